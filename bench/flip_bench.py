#!/usr/bin/env python3
"""Speed of our FLIP (tests/flip_cli) against NVIDIA's flip-evaluator on one
pair, in the same run, best of --repeats. Without a pair it makes a
deterministic 1920x1080 HDR pair (smooth radiance, multiplicative noise).

  flip_bench.py --cli build/bin/flip_cli [--repeats 3] [REFERENCE.exr:TEST.exr]

Our time is flip_cli's own measurement of the metric (image reading and
writing excluded); the reference's is the flip_evaluator.evaluate call on the
same float data.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import flip_evaluator


def write_pfm(path, rgb):
    height, width, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{width} {height}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())  # PFM rows run bottom-up


def synthetic_pair(folder):
    y, x = np.mgrid[0:1080, 0:1920].astype(np.float32)
    radiance = np.dstack([2.0 + 1.5 * np.sin(x / 97.0) * np.cos(y / 61.0),
                          1.0 + 0.8 * np.cos(x / 53.0 + y / 71.0),
                          0.5 + 0.4 * np.sin((x + y) / 41.0)]) ** 2
    radiance[400:460, 900:1000] = 40.0  # a light source
    noise = np.random.default_rng(1).gamma(4.0, 0.25, radiance.shape)
    paths = [os.path.join(folder, "reference.pfm"), os.path.join(folder, "test.pfm")]
    write_pfm(paths[0], radiance.astype(np.float32))
    write_pfm(paths[1], (radiance * noise).astype(np.float32))
    return paths


def reinhard_srgb(linear):
    v = np.maximum(linear, 0).astype(np.float32)
    v = v / (np.float32(1) + v)
    return np.where(v <= 0.0031308, v * np.float32(12.92),
                    np.float32(1.055) * np.power(v, np.float32(1 / 2.4)) - np.float32(0.055))


def timed_reference(reference, test, mode):
    start = time.perf_counter()
    _, mean, _ = flip_evaluator.evaluate(reference.copy(), test.copy(), mode, applyMagma=False)
    return time.perf_counter() - start, mean


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cli", required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("pair", nargs="?", help="REFERENCE.exr:TEST.exr")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        reference_path, test_path = (args.pair.split(":", 1) if args.pair
                                     else synthetic_pair(folder))
        prefix = os.path.join(folder, "dump")
        best = {}
        for _ in range(args.repeats):
            ours = json.loads(subprocess.run([args.cli, reference_path, test_path, "--dump", prefix],
                                             check=True, capture_output=True, text=True).stdout)
            reference = np.load(prefix + ".reference.npy")
            test = np.load(prefix + ".test.npy")
            ldr = timed_reference(reinhard_srgb(reference), reinhard_srgb(test), "LDR")
            hdr = timed_reference(np.maximum(reference, 0), np.maximum(test, 0), "HDR")
            for key, seconds, mean in (("ours LDR", ours["flip_seconds"], ours["flip"]),
                                       ("ours HDR", ours["hdrflip_seconds"], ours["hdrflip"]),
                                       ("flip-evaluator LDR", *ldr), ("flip-evaluator HDR", *hdr)):
                best[key] = min(best.get(key, (float("inf"), mean)), (seconds, mean))
    print(f"{ours['width']}x{ours['height']}, {ours['num_exposures']} HDR exposures, "
          f"{os.cpu_count()} cores, best of {args.repeats}")
    for key, (seconds, mean) in best.items():
        print(f"  {key:20s} {seconds:7.3f} s   mean {mean:.6f}")
    for mode in ("LDR", "HDR"):
        print(f"  speed-up {mode}: {best[f'flip-evaluator {mode}'][0] / best[f'ours {mode}'][0]:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
