#!/usr/bin/env python3
"""OIDN 2.5.1's own timings on the same .npy inputs as denoise_npy_bench, through
its C API with ctypes (numpy alone: the GPU machine has neither pyoidn's cffi nor
network), on its CPU or CUDA device:
  usual      one filter call: colour with albedo and normal (hdr)
  prefilter  OIDN's prefilter recipe: albedo and normal filtered first, then
             the colour with cleanAux (Blender's "Accurate")
Each timed call includes the copies to and from the device, as a host-side
caller of dndenoise sees them; the median of --repeats after one warm-up.

  python3 bench/gpu/oidn_bench.py --lib DIR --input DIR [--device cuda]
      [--modes usual,prefilter] [--repeats 5] [--output DIR]

DIR (--lib) holds libOpenImageDenoise.so.2, libOpenImageDenoise_core.so.2.5.1
and libOpenImageDenoise_device_cuda.so.2.5.1 (or _cpu), e.g. pyoidn's oidn/lib.
"""
import argparse
import ctypes
import os
import statistics
import sys
import time

import numpy as np

DEVICE_TYPES = {"cpu": 1, "cuda": 3}
FORMAT_FLOAT3 = 3
c_size = ctypes.c_size_t
c_ptr = ctypes.c_void_p


def load(lib_dir):
    lib = ctypes.CDLL(os.path.join(lib_dir, "libOpenImageDenoise.so.2"))
    signatures = {
        "oidnNewDevice": (c_ptr, [ctypes.c_int]),
        "oidnCommitDevice": (None, [c_ptr]),
        "oidnGetDeviceError": (ctypes.c_int, [c_ptr, ctypes.POINTER(ctypes.c_char_p)]),
        "oidnNewBuffer": (c_ptr, [c_ptr, c_size]),
        "oidnWriteBuffer": (None, [c_ptr, c_size, c_size, c_ptr]),
        "oidnReadBuffer": (None, [c_ptr, c_size, c_size, c_ptr]),
        "oidnNewFilter": (c_ptr, [c_ptr, ctypes.c_char_p]),
        "oidnSetFilterImage": (None, [c_ptr, ctypes.c_char_p, c_ptr, ctypes.c_int, c_size, c_size,
                                      c_size, c_size, c_size]),
        "oidnSetFilterBool": (None, [c_ptr, ctypes.c_char_p, ctypes.c_bool]),
        "oidnCommitFilter": (None, [c_ptr]),
        "oidnExecuteFilter": (None, [c_ptr]),
        "oidnReleaseFilter": (None, [c_ptr]),
        "oidnReleaseBuffer": (None, [c_ptr]),
        "oidnReleaseDevice": (None, [c_ptr]),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


class Oidn:
    def __init__(self, lib, device_name):
        self.lib = lib
        self.device = lib.oidnNewDevice(DEVICE_TYPES[device_name])
        if not self.device:
            raise RuntimeError(f"OIDN: no {device_name} device (is its device library beside the core?)")
        lib.oidnCommitDevice(self.device)
        self.check(f"creating the {device_name} device")

    def check(self, what):
        message = ctypes.c_char_p()
        if self.lib.oidnGetDeviceError(self.device, ctypes.byref(message)):
            raise RuntimeError(f"OIDN, {what}: {message.value.decode() if message.value else 'error'}")

    def buffer(self, nbytes):
        return self.lib.oidnNewBuffer(self.device, nbytes)

    def write(self, buf, array):
        self.lib.oidnWriteBuffer(buf, 0, array.nbytes, array.ctypes.data)

    def read(self, buf, array):
        self.lib.oidnReadBuffer(buf, 0, array.nbytes, array.ctypes.data)

    def filter(self, images, width, height, hdr=False, clean_aux=False):
        f = self.lib.oidnNewFilter(self.device, b"RT")
        for name, buf in images.items():
            self.lib.oidnSetFilterImage(f, name.encode(), buf, FORMAT_FLOAT3, width, height, 0, 0, 0)
        if hdr:
            self.lib.oidnSetFilterBool(f, b"hdr", True)
        if clean_aux:
            self.lib.oidnSetFilterBool(f, b"cleanAux", True)
        self.lib.oidnCommitFilter(f)
        self.check("committing a filter")
        return f


def run_mode(oidn, mode, inputs, output):
    """One call as a host-side caller makes it: upload, filter(s), download."""
    h, w, _ = inputs["color"].shape
    nbytes = inputs["color"].nbytes
    bufs = {name: oidn.buffer(nbytes) for name in ("color", "albedo", "normal", "output")}
    for name in ("color", "albedo", "normal"):
        oidn.write(bufs[name], inputs[name])
    filters = []
    if mode == "usual":
        filters.append(oidn.filter({"color": bufs["color"], "albedo": bufs["albedo"], "normal": bufs["normal"],
                                    "output": bufs["output"]}, w, h, hdr=True))
    else:  # albedo and normal denoised in place, then the colour with clean aux
        filters.append(oidn.filter({"albedo": bufs["albedo"], "output": bufs["albedo"]}, w, h))
        filters.append(oidn.filter({"normal": bufs["normal"], "output": bufs["normal"]}, w, h))
        filters.append(oidn.filter({"color": bufs["color"], "albedo": bufs["albedo"], "normal": bufs["normal"],
                                    "output": bufs["output"]}, w, h, hdr=True, clean_aux=True))
    for f in filters:
        oidn.lib.oidnExecuteFilter(f)
    oidn.read(bufs["output"], output)
    oidn.check(f"running {mode}")
    for f in filters:
        oidn.lib.oidnReleaseFilter(f)
    for b in bufs.values():
        oidn.lib.oidnReleaseBuffer(b)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lib", required=True)
    ap.add_argument("--input", required=True)
    ap.add_argument("--device", default="cuda", choices=sorted(DEVICE_TYPES))
    ap.add_argument("--modes", default="usual,prefilter")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--output", default="")
    args = ap.parse_args()
    inputs = {}
    for name in ("color", "albedo", "normal"):
        path = os.path.join(args.input, name + ".npy")
        a = np.load(path)
        if a.ndim != 3 or a.shape[2] != 3:
            sys.exit(f"oidn_bench: {path}: expected (height, width, 3), got {a.shape}")
        inputs[name] = np.ascontiguousarray(a, dtype=np.float32)
    h, w, _ = inputs["color"].shape
    oidn = Oidn(load(args.lib), args.device)
    print(f"OIDN {args.device}, {w}x{h}, median of {args.repeats} after 1 warm-up, copies included")
    for mode in args.modes.split(","):
        output = np.zeros_like(inputs["color"])
        run_mode(oidn, mode, inputs, output)  # warm-up: device init, weights, kernels
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            run_mode(oidn, mode, inputs, output)
            times.append(time.perf_counter() - start)
        if not np.isfinite(output).all() or not output.any():
            sys.exit(f"oidn_bench: {mode}: the output is not finite or all zero")
        if args.output:
            os.makedirs(args.output, exist_ok=True)
            np.save(os.path.join(args.output, f"oidn_{mode}_{args.device}.npy"), output)
        print(f"RESULT tool=oidn mode={mode} device={args.device} size={w}x{h} repeats={args.repeats} "
              f"median_s={statistics.median(times):.4f} min_s={min(times):.4f}", flush=True)
    oidn.lib.oidnReleaseDevice(oidn.device)


if __name__ == "__main__":
    main()
