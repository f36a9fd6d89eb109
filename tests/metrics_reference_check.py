#!/usr/bin/env python3
"""dnmetrics against an independent computation: numpy for L1/MSE/relMSE/PSNR/
SMAPE and scikit-image for SSIM, on the real render pairs in testdata/pairs and
on a synthetic HDR pair with fireflies and negative values.
Exit 0 when everything agrees, 1 otherwise, 77 when a reference is missing."""
import argparse
import glob
import json
import os
import subprocess
import sys

try:
    import numpy as np
    from skimage.metrics import structural_similarity
    from exr_numpy import read_rgb, write_rgb
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e}")
    sys.exit(77)


def reference_metrics(ref, test):
    r, t = np.clip(ref, 0, 6).astype(np.float64), np.clip(test, 0, 6).astype(np.float64)
    rl, tl = np.maximum(ref, 0).astype(np.float64), np.maximum(test, 0).astype(np.float64)
    rt, tt = rl / (1 + rl), tl / (1 + tl)
    return {
        "l1": np.mean(np.abs(r - t)),
        "mse": np.mean((r - t) ** 2),
        "relmse": np.mean((rl - tl) ** 2 / (rl ** 2 + 1e-2)),
        "psnr": 10 * np.log10(1 / np.mean((rt - tt) ** 2)),
        "ssim": structural_similarity(rt, tt, data_range=1.0, channel_axis=2, gaussian_weights=True,
                                      sigma=1.5, use_sample_covariance=False),
        "smape": np.mean(np.abs(r - t)) / (np.mean(r) + np.mean(t) + 1e-2),
    }


def synthetic_pair(work):
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:48, 0:64] / 48.0
    ref = np.dstack([x * 2, y, 0.5 + 0.4 * np.sin(6 * x)]).astype(np.float32)
    test = ref * rng.gamma(4.0, 0.25, ref.shape).astype(np.float32)
    test[5, 7] = 250.0  # a firefly
    test[9, 9] = -0.3   # negative lobe
    paths = [os.path.join(work, n) for n in ("synthetic_ref.exr", "synthetic_test.exr")]
    write_rgb(paths[0], ref)
    write_rgb(paths[1], test)
    return paths


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--testdata", required=True)
    ap.add_argument("--work-dir", required=True)
    args = ap.parse_args()
    os.makedirs(args.work_dir, exist_ok=True)

    pairs = [synthetic_pair(args.work_dir)]
    for test in sorted(glob.glob(os.path.join(args.testdata, "pairs", "*_4spp.exr"))):
        pairs.append([test.replace("_4spp.exr", "_ref.exr"), test])

    names = ["l1", "mse", "relmse", "psnr", "ssim", "smape"]
    failures = 0
    for ref_path, test_path in pairs:
        out = subprocess.run([args.dnmetrics, "--format", "json", "--metrics", ",".join(names),
                              ref_path, test_path], capture_output=True, text=True)
        if out.returncode != 0:
            print(f"FAIL {test_path}: dnmetrics exited {out.returncode}: {out.stderr.strip()}")
            failures += 1
            continue
        ours = json.loads(out.stdout)["results"][0]
        theirs = reference_metrics(read_rgb(ref_path), read_rgb(test_path))
        for name in names:
            a, b = ours[name], theirs[name]
            ok = abs(a - b) <= (1e-3 if name == "psnr" else 1e-4 * max(abs(b), 1e-6) + 1e-7)
            failures += not ok
            print(f"{'ok  ' if ok else 'FAIL'} {os.path.basename(test_path):28s} {name:7s} "
                  f"dnmetrics {a:.7g}  reference {b:.7g}")
    print(f"{len(pairs) * len(names) - failures} passed, {failures} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
