#!/usr/bin/env python3
"""Two dndenoise settings, A and B, on every frame with a reference under
testdata (pairs, renderers, the data set's test split): the PSNR of each
against the reference, and of B against A (how far B's output moved), with
dnmetrics' PSNR (Reinhard v / (1 + v), clipped to [0, 1], peak 1). For
checking that a speed change keeps the quality: B - A per frame and the mean.

  quality_ab.py --bin build/bin --a "--model models/default.dnm" --b "--model ... -q fast"
                [--b-env NAME=VALUE] [--threads 2] [--keep DIR] [--match 000104,cornell]
"""
import argparse
import glob
import os
import shlex
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, os.path.join(ROOT, "tests"))
from exr_numpy import read_rgb  # noqa: E402


def frames():
    """(name, noisy, reference as an array) for every frame with a reference."""
    data = os.path.join(ROOT, "testdata")
    for folder in ("pairs", "renderers"):
        for ref in sorted(glob.glob(os.path.join(data, folder, "*_ref.exr"))):
            for noisy in sorted(glob.glob(ref[: -len("ref.exr")] + "*spp.exr")):
                yield f"{folder}/{os.path.basename(noisy)}", noisy, read_rgb(ref)
    for frame in sorted(glob.glob(os.path.join(data, "dataset", "test", "scene_*", "frame_*"))):
        refs = [read_rgb(p) for p in sorted(glob.glob(os.path.join(frame, "gt_*.exr")))]
        noisy = os.path.join(frame, "spp4_00.exr")
        if refs and os.path.exists(noisy):
            yield os.path.relpath(noisy, data), noisy, np.mean(refs, axis=0)


def psnr(a, b):
    def tone(v):
        v = np.nan_to_num(np.maximum(v, 0.0))
        return np.clip(v / (1.0 + v), 0.0, 1.0)
    mse = float(np.mean((tone(a) - tone(b)) ** 2))
    return float("inf") if mse == 0 else -10.0 * np.log10(mse)


def denoise(binary, flags, env, noisy, out, threads):
    cmd = [os.path.join(binary, "dndenoise"), "--threads", str(threads), "--rgb-only", *shlex.split(flags),
           noisy, "-o", out]
    res = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, **env))
    if res.returncode != 0:
        sys.exit(f"quality_ab: {' '.join(cmd)} failed:\n{res.stderr}")
    return read_rgb(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True)
    ap.add_argument("--a", default="", help="dndenoise flags of A")
    ap.add_argument("--b", default="", help="dndenoise flags of B")
    ap.add_argument("--a-env", action="append", default=[], help="NAME=VALUE in A's environment")
    ap.add_argument("--b-env", action="append", default=[], help="NAME=VALUE in B's environment")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--keep", help="folder for the outputs (default: a temporary one)")
    ap.add_argument("--match", default="", help="only frames whose name holds one of these (comma-separated)")
    args = ap.parse_args()
    envs = [dict(e.split("=", 1) for e in args.a_env), dict(e.split("=", 1) for e in args.b_env)]
    tmp = tempfile.TemporaryDirectory()
    work = args.keep or tmp.name
    os.makedirs(work, exist_ok=True)
    print(f"A: {args.a} {' '.join(args.a_env)}\nB: {args.b} {' '.join(args.b_env)}")
    print(f"{'frame':<44} {'A dB':>7} {'B dB':>7} {'B-A dB':>7} {'B vs A dB':>9}")
    rows = []
    for name, noisy, ref in frames():
        if args.match and not any(m in name for m in args.match.split(",")):
            continue
        slug = name.replace("/", "_")
        a = denoise(args.bin, args.a, envs[0], noisy, os.path.join(work, "a_" + slug), args.threads)
        b = denoise(args.bin, args.b, envs[1], noisy, os.path.join(work, "b_" + slug), args.threads)
        row = (psnr(a, ref), psnr(b, ref), psnr(b, a))
        rows.append(row)
        print(f"{name:<44} {row[0]:7.3f} {row[1]:7.3f} {row[1] - row[0]:+7.3f} {row[2]:9.2f}", flush=True)
    a_mean, b_mean = np.mean([r[0] for r in rows]), np.mean([r[1] for r in rows])
    worst = min(r[1] - r[0] for r in rows)
    print(f"{'mean of ' + str(len(rows)) + ' frames':<44} {a_mean:7.3f} {b_mean:7.3f} {b_mean - a_mean:+7.3f} "
          f"{np.mean([r[2] for r in rows]):9.2f}   (worst B-A {worst:+.3f} dB, lowest B vs A "
          f"{min(r[2] for r in rows):.2f} dB)")


if __name__ == "__main__":
    main()
