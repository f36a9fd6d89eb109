#!/usr/bin/env python3
"""Benchmark frames for denoise_npy_bench and oidn_bench: the shipped example's
buffers (bench/gpu/carry/example.npz, made by bench/gpu/prepare_carry.sh) tiled to
each size, so the noise stays independent per pixel (an upscale would correlate
it). Writes OUT/WxH/<buffer>.npy, float32. Needs numpy only.

  python3 bench/gpu/make_inputs.py --example bench/gpu/carry/example.npz --out DIR \
      [--sizes 1920x1080,3840x2160]
"""
import argparse
import os
import sys

import numpy as np


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--example", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--sizes", default="1920x1080,3840x2160")
    args = ap.parse_args()
    if not os.path.exists(args.example):
        sys.exit(f"make_inputs: {args.example}: missing (run bench/gpu/prepare_carry.sh where OpenImageIO is)")
    buffers = dict(np.load(args.example))
    if "color" not in buffers:
        sys.exit(f"make_inputs: {args.example}: no colour buffer")
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.split("x"))
        folder = os.path.join(args.out, f"{width}x{height}")
        os.makedirs(folder, exist_ok=True)
        for name, image in buffers.items():
            h, w = image.shape[:2]
            reps = (-(-height // h), -(-width // w)) + (1,) * (image.ndim - 2)
            tiled = np.tile(image, reps)[:height, :width]
            np.save(os.path.join(folder, name + ".npy"), np.ascontiguousarray(tiled, dtype="<f4"))
        print(f"{folder}: {', '.join(sorted(buffers))}")


if __name__ == "__main__":
    main()
