#!/usr/bin/env python3
"""How exactly dndenoise's pretrained base reproduces OIDN: each input is
denoised by `dndenoise --model MODEL` and by OIDN itself (oidn_denoise.py,
pyoidn), with the same buffers, and the two results are compared: PSNR after
the Reinhard tonemap v / (1 + v) (as dnmetrics computes it) and the largest
absolute difference in HDR.

  oidn_agreement.py --bin build/bin --model models/oidn.dnm [--aux albedo,normal|albedo|none]
                    IN.exr ... [--min-psnr 45]

Prints one line per input and the lowest PSNR and largest difference over all;
exits 1 when any PSNR is below --min-psnr.
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

from exrutil import read_color

HERE = os.path.dirname(os.path.abspath(__file__))


def reinhard_psnr(a, b):
    mse = np.mean((a / (1 + a) - b / (1 + b)) ** 2, dtype=np.float64)
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--bin", required=True)
    ap.add_argument("--model", required=True)
    ap.add_argument("--aux", choices=["albedo,normal", "albedo", "none"], default="albedo,normal")
    ap.add_argument("--min-psnr", type=float, default=45.0)
    args = ap.parse_args()
    buffers = {"albedo,normal": "color,albedo,normal", "albedo": "color,albedo", "none": "color"}[args.aux]
    lowest, largest = float("inf"), 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for i, path in enumerate(args.inputs):
            ours, theirs = os.path.join(tmp, f"ours{i}.exr"), os.path.join(tmp, f"oidn{i}.exr")
            subprocess.run([os.path.join(args.bin, "dndenoise"), "--model", args.model, "--rgb-only", "--float",
                            "--buffers", buffers, path, "-o", ours], check=True)
            subprocess.run([sys.executable, os.path.join(HERE, "oidn_denoise.py"), "--aux", args.aux, path,
                            "-o", theirs], check=True)
            a, b = read_color(ours), read_color(theirs)
            psnr, diff = reinhard_psnr(a, b), float(np.abs(a - b).max())
            lowest, largest = min(lowest, psnr), max(largest, diff)
            print(f"{path}: {psnr:.2f} dB, largest difference {diff:.3g}", flush=True)
    print(f"lowest {lowest:.2f} dB, largest difference {largest:.3g} over {len(args.inputs)} inputs")
    return 1 if lowest < args.min_psnr else 0


if __name__ == "__main__":
    sys.exit(main())
