#!/usr/bin/env python3
"""What relighting each kept neighbour by a wide box's light would do: a probe
on the filter's own view of its neighbours, before any change to the filter.

  temporal_refilter SHOT/spp4.#.exr ALONE/spp4.#.exr -o OUT/o.#.exr --frames 1-8 \\
      --dump-trust DUMP --target SHOT/spp16.#.exr
  drift_probe.py SHOT:DUMP [SHOT:DUMP ...] [--threshold 0.05] [--boxes 15 31]

For each scored frame (a reference SHOT/ref.####.exr, or one ref.exr for the
whole shot, and ref2 of another seed): the frame's result and its kept
neighbours as the filter weighed them (DUMP/####.{own,moved,weights}.npy)
combined as a weighted mean, as they are, and with each neighbour's pixel
scaled by the ratio of the frame's and the neighbour's means over the
(2r+1)^2 box of its trusted pixels wherever that ratio (mean over channels)
is more than --threshold from 1: a light that drifted slowly over a wide area
(too faint for the per-pixel tests at a few samples) is brought to the
frame's. Prints the PSNR gain over the frame alone (Reinhard, the references'
own noise taken out) per frame, and each shot's mean. The weighted mean
leaves out the accumulated render's second denoising, so the figures compare
the variants with each other, not with dndenoise's.
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from exrutil import read_color  # noqa: E402


def rgb(path):
    return read_color(path).astype(np.float64)


def reinhard(x):
    x = np.maximum(x, 0.0)
    return x / (1.0 + x)


def psnr(image, ref, ref2):
    """Against two references of other seeds, their own noise taken out."""
    def mse(a, b):
        return np.mean((reinhard(a) - reinhard(b)) ** 2)
    return -10 * np.log10((mse(image, ref) + mse(image, ref2)) / 2 - mse(ref, ref2) / 2)


def box_mean(x, r):
    """Per pixel, the mean of x (H, W, C) over the (2r+1)^2 box, clipped to the image."""
    s = np.cumsum(np.cumsum(np.pad(x, ((1, 0), (1, 0), (0, 0))), 0), 1)
    h, w = x.shape[:2]
    y0, y1 = np.clip(np.arange(h) - r, 0, h), np.clip(np.arange(h) + r + 1, 0, h)
    x0, x1 = np.clip(np.arange(w) - r, 0, w), np.clip(np.arange(w) + r + 1, 0, w)
    total = s[y1][:, x1] - s[y0][:, x1] - s[y1][:, x0] + s[y0][:, x0]
    return total / ((y1 - y0)[:, None] * (x1 - x0)[None, :])[..., None]


def combined(own, moved, weights, box, threshold):
    total, weight = own.copy(), np.ones(own.shape[:2])
    for image, w in zip(moved, weights):
        if box > 0:
            trusted = (w > 0).astype(np.float64)[..., None]
            count = box_mean(trusted, box) + 1e-9
            ratio = (box_mean(own * trusted, box) / count + 1e-6) / (box_mean(image * trusted, box) / count + 1e-6)
            ratio = np.clip(ratio, 0.5, 2.0)
            drifted = np.abs(ratio.mean(-1, keepdims=True) - 1.0) > threshold
            image = np.where(drifted, image * ratio, image)
        total += w[..., None] * image
        weight += w
    return total / weight[..., None]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("shots", nargs="+", help="SHOT:DUMP")
    ap.add_argument("--threshold", type=float, default=0.05)
    ap.add_argument("--boxes", type=int, nargs="+", default=[15, 31])
    args = ap.parse_args()
    variants = [0] + args.boxes
    print("shot frame alone  " + "  ".join("as weighed" if b == 0 else f"box {2 * b + 1}" for b in variants))
    for spec in args.shots:
        shot, dump = spec.split(":")
        gains = []
        for frame in range(1, 100):
            own_path = os.path.join(dump, f"{frame:04d}.own.npy")
            if not os.path.exists(own_path):
                break
            shared = os.path.join(shot, "ref.exr")
            ref = shared if os.path.exists(shared) else os.path.join(shot, f"ref.{frame:04d}.exr")
            if not os.path.exists(ref):
                continue
            ref, ref2 = rgb(ref), rgb(ref.replace("ref.", "ref2."))
            own = np.load(own_path).astype(np.float64)
            moved = np.load(os.path.join(dump, f"{frame:04d}.moved.npy")).astype(np.float64)
            weights = np.load(os.path.join(dump, f"{frame:04d}.weights.npy")).astype(np.float64)
            alone = psnr(own, ref, ref2)
            gains.append([psnr(combined(own, moved, weights, b, args.threshold), ref, ref2) - alone for b in variants])
            print(f"{os.path.basename(shot.rstrip('/'))} {frame} {alone:6.2f} " + "  ".join(f"{g:+9.2f}" for g in gains[-1]))
        if gains:
            print(f"{os.path.basename(shot.rstrip('/'))} mean        " + "  ".join(f"{g:+9.2f}" for g in np.mean(gains, 0)))


if __name__ == "__main__":
    main()
