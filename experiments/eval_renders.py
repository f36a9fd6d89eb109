#!/usr/bin/env python3
"""Baseline scores on the evaluation renders of render_evaldata.sh: the noisy input and
OIDN 2 (pyoidn, RT filter, HDR, quality default) given colour, colour + albedo, and
colour + albedo + normal; and the lag-1 autocorrelation of each input's noise.

  eval_renders.py --data /work/evaldata [--sets blender5 mitsuba_box mitsuba_gauss] [--threads 2]

DATA/<set>/<scene>/spp<N>.exr are scored against DATA/<set>/<scene>/ref.exr. OIDN's
results go to DATA/out/oidn_<buffers>/<set>/<scene>/spp<N>.exr (plain float RGB; kept and
reused). Buffers are found by name: Blender's `<layer>.Combined`, `.Denoising Albedo`,
`.Denoising Normal` (single- or multi-part), or Mitsuba's `R,G,B`, `albedo.*`, `normals.*`
(the AOV names of render_mitsuba.py).

Metrics, as dnmetrics defines them: PSNR on Reinhard v / (1 + v) clipped to [0, 1], peak 1;
FLIP (LDR, flip_evaluator at 67 pixels per degree) on Reinhard then sRGB. The noise
autocorrelation is that of d = render - reference between horizontal and vertical
neighbours, averaged over both directions and the 3 channels, on linear radiance and on
Reinhard-tonemapped values (less driven by fireflies, but at 4 spp the tonemap's bias
adds a smooth, positively correlated part).
Prints one line per render and a Markdown table of means per set and spp.
"""

import argparse
import glob
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from exrutil import ExrError, color_names, fail, read_channels, write_rgb  # noqa: E402

BUFFER_SETS = ("c", "ca", "can")
ALBEDO = (("Denoising Albedo", "RGB"), ("albedo", "RGB"))
NORMAL = (("Denoising Normal", "XYZ"), ("normals", "XYZ"))


def layer(channels, names, path):
    """The first (layer, suffixes) of names present, as float32 (H, W, 3)."""
    for name, suffixes in names:
        found = []
        for suffix in suffixes:
            matches = sorted(n for n in channels if n == f"{name}.{suffix}" or n.endswith(f".{name}.{suffix}"))
            found.append(channels[matches[0]] if matches else None)
        if all(f is not None for f in found):
            return np.stack([f.astype(np.float32) for f in found], axis=-1)
    raise ExrError(f"{path}: none of the layers {[n for n, _ in names]}")


def load(path):
    """Colour (finite, >= 0), albedo in [0, 1], normal in [-1, 1]."""
    channels, _ = read_channels(path)
    color = np.stack([channels[n].astype(np.float32) for n in color_names(channels, path)], axis=-1)
    color = np.nan_to_num(color, nan=0.0, posinf=0.0, neginf=0.0).clip(min=0.0)
    albedo = layer(channels, ALBEDO, path).clip(0.0, 1.0)
    normal = np.nan_to_num(layer(channels, NORMAL, path)).clip(-1.0, 1.0)
    return [np.ascontiguousarray(a) for a in (color, albedo, normal)]


def reinhard(v):
    return np.clip(v / (1.0 + v), 0.0, 1.0)


def psnr(ref, test):
    mse = float(np.mean((reinhard(ref) - reinhard(test)) ** 2))
    return 10.0 * np.log10(1.0 / max(mse, 1e-12))


def flip(ref, test):
    import flip_evaluator

    def srgb(v):
        t = reinhard(v)
        return np.where(t <= 0.0031308, 12.92 * t, 1.055 * np.power(t, 1 / 2.4) - 0.055).astype(np.float32)

    return float(flip_evaluator.evaluate(srgb(ref), srgb(test), "LDR")[1])


def lag1_autocorrelation(render, ref, tonemap):
    """Correlation of the noise d = render - ref between horizontal and vertical neighbours,
    averaged over both directions and the 3 channels; of Reinhard-tonemapped values if tonemap."""
    d = reinhard(render) - reinhard(ref) if tonemap else (render - ref).astype(np.float64)
    d = d - d.mean(axis=(0, 1))
    var = float(np.sum(d * d))
    if var == 0.0:
        return 0.0
    horizontal = float(np.sum(d[:, 1:] * d[:, :-1])) / var
    vertical = float(np.sum(d[1:] * d[:-1])) / var
    return 0.5 * (horizontal + vertical)


class Oidn:
    """One OIDN device and RT filter per buffer set, reused for every image."""

    def __init__(self, threads):
        import pyoidn
        from pyoidn.filter import OIDN_QUALITY_DEFAULT
        self.pyoidn = pyoidn
        self.device = pyoidn.Device()
        if threads > 0:
            self.device.set_int("numThreads", threads)
        self.device.commit()
        self.filters = {}
        for buffers in BUFFER_SETS:
            f = pyoidn.Filter(self.device, "RT")
            f.set_bool("hdr", True)
            f.set_quality(OIDN_QUALITY_DEFAULT)
            self.filters[buffers] = f

    def run(self, buffers, color, albedo, normal):
        from pyoidn.filter import OIDN_FORMAT_FLOAT3
        f = self.filters[buffers]
        output = np.empty_like(color)
        images = {"color": color, "albedo": albedo, "normal": normal, "output": output}
        for name in ("color", "output") + (("albedo",) if "a" in buffers else ()) + (
                ("normal",) if "n" in buffers else ()):
            f.set_image(name, images[name], OIDN_FORMAT_FLOAT3)
        f.commit()
        f.execute()
        error = self.device.get_error()
        if error:
            raise RuntimeError(f"OIDN failed: {error}")
        return output


def renders(data, sets):
    found = []
    for set_name in sets:
        for path in glob.glob(os.path.join(data, set_name, "*", "spp*.exr")):
            m = re.fullmatch(r"spp(\d+)\.exr", os.path.basename(path))
            if m:
                found.append((set_name, os.path.basename(os.path.dirname(path)), int(m.group(1)), path))
    return sorted(found)


def denoised(oidn, data, buffers, set_name, scene, spp, inputs):
    """OIDN's result with these buffers, read back when an earlier run wrote it."""
    path = os.path.join(data, "out", f"oidn_{buffers}", set_name, scene, f"spp{spp}.exr")
    if not os.path.exists(path):
        write_rgb(path, oidn.run(buffers, *inputs))
    channels, _ = read_channels(path)
    return np.stack([channels[c] for c in "RGB"], axis=-1).astype(np.float32)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True)
    parser.add_argument("--sets", nargs="+", default=["blender5", "mitsuba_box", "mitsuba_gauss"])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-flip", action="store_true", help="PSNR only")
    args = parser.parse_args()
    oidn = Oidn(args.threads)
    rows = {}
    methods = ["noisy"] + [f"oidn_{b}" for b in BUFFER_SETS]
    print("%-32s %6s %6s " % ("render", "rho", "rho_tm") + " ".join("%14s" % m for m in methods))
    for set_name, scene, spp, path in renders(args.data, args.sets):
        ref_path = os.path.join(os.path.dirname(path), "ref.exr")
        if not os.path.exists(ref_path):
            print(f"eval_renders: {ref_path}: no reference yet, {path} skipped", file=sys.stderr)
            continue
        try:
            inputs = load(path)
            ref = load(ref_path)[0]
        except ExrError as error:
            fail(f"eval_renders: {error}")
        results = {"noisy": inputs[0]}
        for buffers in BUFFER_SETS:
            results[f"oidn_{buffers}"] = denoised(oidn, args.data, buffers, set_name, scene, spp, inputs)
        scores = {m: (psnr(ref, img), None if args.no_flip else flip(ref, img)) for m, img in results.items()}
        rho = (lag1_autocorrelation(inputs[0], ref, False), lag1_autocorrelation(inputs[0], ref, True))
        rows.setdefault((set_name, spp), []).append((rho, scores))
        print("%-32s %6.3f %6.3f " % ((f"{set_name}/{scene}/spp{spp}",) + rho) + " ".join(
            "%6.2f %7s" % (scores[m][0], "" if scores[m][1] is None else "%.4f" % scores[m][1]) for m in methods),
            flush=True)
    print_table(rows, methods, args.no_flip)


def print_table(rows, methods, no_flip):
    print("\n| set | spp | scenes | noise lag-1 autocorr. (linear / Reinhard) | " + " | ".join(
        f"{m} PSNR" + ("" if no_flip else f" / FLIP") for m in methods) + " |")
    print("|---|---|---|---|" + "---|" * len(methods))
    for (set_name, spp), entries in sorted(rows.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        cells = []
        for m in methods:
            p = np.mean([e[1][m][0] for e in entries])
            cells.append("%.2f" % p if no_flip else "%.2f / %.4f" % (p, np.mean([e[1][m][1] for e in entries])))
        rho = np.mean([e[0][0] for e in entries]), np.mean([e[0][1] for e in entries])
        print(f"| {set_name} | {spp} | {len(entries)} | {rho[0]:.3f} / {rho[1]:.3f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    sys.exit(main())
