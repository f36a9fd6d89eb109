#!/usr/bin/env python3
"""dnmetrics (every metric, whole process) against NVIDIA's `flip` tool (LDR-FLIP
on PNGs plus HDR-FLIP on EXRs, whole processes) on the same 1920x1080 pair, in
the same run; prints median wall times over --repeats and their ratio.

  dnmetrics_bench.py --dnmetrics build/bin/dnmetrics [--repeats 5] [--size 1920x1080]
"""
import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from exr_numpy import write_rgb  # noqa: E402


def make_pair(folder, width, height):
    """A smooth HDR reference and a noisy test with fireflies, deterministic."""
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    ref = np.dstack([1.5 + np.sin(x / 97) * np.cos(y / 53), 0.8 + 0.6 * np.sin((x + y) / 71),
                     np.exp(-((x - width / 2) ** 2 + (y - height / 2) ** 2) / (2 * 300.0 ** 2)) * 8])
    ref = np.maximum(ref, 0).astype(np.float32)
    test = (ref * rng.gamma(2.0, 0.5, ref.shape)).astype(np.float32)
    test[rng.random(ref.shape[:2]) < 1e-3] *= 40
    paths = {}
    for name, img in (("ref", ref), ("test", test)):
        paths[name + ".exr"] = os.path.join(folder, name + ".exr")
        write_rgb(paths[name + ".exr"], img)
        ldr = (np.clip(img / (1 + img), 0, 1))
        srgb = np.where(ldr <= 0.0031308, 12.92 * ldr, 1.055 * ldr ** (1 / 2.4) - 0.055)
        paths[name + ".png"] = os.path.join(folder, name + ".png")
        from PIL import Image  # noqa: E402 (Pillow ships with scikit-image)
        Image.fromarray((srgb * 255 + 0.5).astype(np.uint8)).save(paths[name + ".png"])
    return paths


def timed(cmds, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for cmd in cmds:
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--size", default="1920x1080")
    args = ap.parse_args()
    if not shutil.which("flip"):
        sys.exit("dnmetrics_bench: NVIDIA's `flip` tool is missing (pip install flip-evaluator)")
    width, height = map(int, args.size.split("x"))
    with tempfile.TemporaryDirectory() as folder:
        p = make_pair(folder, width, height)
        ours = timed([[args.dnmetrics, p["ref.exr"], p["test.exr"]]], args.repeats)
        flip_only = timed([[args.dnmetrics, "--metrics", "flip,hdrflip", p["ref.exr"], p["test.exr"]]], args.repeats)
        reference = timed([["flip", "-nerm", "-nexm", "-r", p["ref.png"], "-t", p["test.png"]],
                           ["flip", "-nerm", "-nexm", "-r", p["ref.exr"], "-t", p["test.exr"]]], args.repeats)
    print(f"pair {width}x{height}, median of {args.repeats} runs, whole processes")
    print(f"dnmetrics, all 8 metrics        {ours:7.3f} s")
    print(f"dnmetrics, flip + hdrflip only  {flip_only:7.3f} s")
    print(f"flip (LDR png + HDR exr)        {reference:7.3f} s")
    print(f"ratio all metrics / flip        {ours / reference:7.3f}")
    print(f"ratio flip+hdrflip / flip       {flip_only / reference:7.3f}")


if __name__ == "__main__":
    main()
