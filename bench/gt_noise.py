#!/usr/bin/env python3
"""Noise of a data set's training targets, measured without a reference (Noise2Noise style).

  python3 bench/gt_noise.py DATA [--frames N]

A frame's two ground truths gt_a and gt_b are independent renders with the same
expectation, so per pixel E[(a - b)^2] = 2 var(gt) and the target t = (a + b) / 2
has variance (a - b)^2 / 4 in expectation. The 64-spp input (mean of the 16 stacks)
has variance s^2 / 16 from the stacks' sample variance s^2. And a denoiser D run on
gt_a alone (a stand-in for cleansing: OIDN, colour + albedo + normal, quality high)
has squared error E[(D(a) - b)^2] - var(b) against the unknown truth. All three are
normalised like relMSE, by t^2 + 0.01, and averaged over the pixels of each frame.
The ratios say how far below the input's noise the target is, and whether one
cleansed ground truth is already cleaner than the two raw ones.
"""

import argparse
import glob
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "experiments"))
from exrutil import find_channels, read_channels  # noqa: E402


def buffers(path):
    ch, _ = read_channels(path)
    return [find_channels(ch, layer, chans, path).astype(np.float64)
            for layer, chans in (("Combined", "RGB"), ("Denoising Albedo", "RGB"), ("Denoising Normal", "XYZ"))]


def oidn(color, albedo, normal):
    try:
        from oidn_denoise import Denoiser
    except ImportError:
        return None
    arrays = [np.ascontiguousarray(a, dtype=np.float32) for a in
              (color.clip(min=0), albedo.clip(0, 1), normal.clip(-1, 1))]
    return Denoiser("high", 2).run(*arrays).astype(np.float64)


def frame_noise(fdir):
    a, albedo, normal = buffers(os.path.join(fdir, "gt_a.exr"))
    b = buffers(os.path.join(fdir, "gt_b.exr"))[0]
    stacks = np.stack([buffers(p)[0] for p in sorted(glob.glob(os.path.join(fdir, "spp*_*.exr")))])
    t = (a + b) / 2
    norm = t ** 2 + 0.01
    var_gt = (a - b) ** 2 / 2  # of one ground truth
    out = {"target": float(np.mean(var_gt / 2 / norm)),
           "input": float(np.mean(stacks.var(axis=0, ddof=1) / len(stacks) / norm)),
           "one_gt": float(np.mean(var_gt / norm))}
    d = oidn(a, albedo, normal)
    if d is not None:
        out["cleansed_one_gt"] = float(np.mean(((d - b) ** 2 - var_gt) / norm))
    return out


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data")
    p.add_argument("--frames", type=int, default=0, help="at most this many frames (0: all)")
    args = p.parse_args(argv)
    dirs = sorted(os.path.dirname(m) for m in glob.glob(os.path.join(args.data, "*", "scene_*", "frame_*",
                                                                       "meta.json")))
    dirs = [d for d in dirs if os.path.exists(os.path.join(d, "gt_b.exr"))]
    if args.frames:
        dirs = dirs[:args.frames]
    if not dirs:
        sys.exit("gt_noise.py: %s: no finished frames with gt_a and gt_b" % args.data)
    rows = [(os.path.relpath(d, args.data), frame_noise(d)) for d in dirs]
    keys = [k for k in ("input", "one_gt", "target", "cleansed_one_gt") if k in rows[0][1]]
    names = {"input": "64-spp input", "one_gt": "one ground truth", "target": "target (mean of two)",
             "cleansed_one_gt": "one ground truth, OIDN-cleansed"}
    print("| frame | " + " | ".join(names[k] for k in keys) + " | target / input |")
    print("|---|" + "---|" * (len(keys) + 1))
    for name, r in rows:
        print("| %s | " % name + " | ".join("%.5f" % r[k] for k in keys) + " | %.3f |" % (r["target"] / r["input"]))
    # Medians: a frame whose 4-spp stacks hold fireflies has an input variance orders of magnitude above the rest.
    med = {k: float(np.median([r[k] for _, r in rows])) for k in keys}
    print("| median of %d | " % len(rows) + " | ".join("%.5f" % med[k] for k in keys) +
          " | %.3f |" % float(np.median([r["target"] / r["input"] for _, r in rows])))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
