#!/usr/bin/env python3
"""The references' own noise: PSNR of ref against ref2 (another seed, same spp).

  python3 experiments/shots/check_refs.py /work/data/shots

For every shot folder with DIR/ref2.<frame>.exr (or ref2.exr), the PSNR of the
Combined pass of ref against ref2, Reinhard-tonemapped (x / (1 + x), peak 1),
as experiments/temporal_eval.py scores. Each reference's error against the
converged image is about 3 dB below this figure (two independent noises).
Needs numpy and the OpenEXR module (the system Python, not the bpy venv).
"""

import glob
import math
import os
import sys

import numpy as np
import OpenEXR


def combined(path):
    exr = OpenEXR.File(path, separate_channels=True)
    channels = {n: c.pixels for part in exr.parts for n, c in part.channels.items()}
    names = [next(n for n in channels if n.endswith("Combined." + c)) for c in "RGB"]
    return np.stack([channels[n].astype(np.float64) for n in names], axis=-1)


def psnr(a, b):
    a, b = a / (1 + np.maximum(a, 0)), b / (1 + np.maximum(b, 0))
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else -10 * math.log10(mse)


def pairs(folder):
    for second in sorted(glob.glob(os.path.join(folder, "ref2*.exr"))):
        first = os.path.join(folder, os.path.basename(second).replace("ref2", "ref", 1))
        if os.path.exists(first):
            yield first, second


def main():
    root = sys.argv[1]
    print("| shot | frame | ref vs ref2 PSNR dB |")
    print("|---|---|---|")
    for folder in sorted(glob.glob(os.path.join(root, "*", ""))):
        for first, second in pairs(folder):
            print("| %s | %s | %.2f |" % (os.path.basename(folder.rstrip("/")), os.path.basename(second)[5:-4] or "-",
                                           psnr(combined(first), combined(second))))


if __name__ == "__main__":
    main()
