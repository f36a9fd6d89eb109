#!/usr/bin/env python3
"""Does cleansing help? For every frame of DATA/<split> that has gt_clean.exr,
compares the raw ground truth (gt_a.exr, the render the cleanser read), the
mean of the pair (gt_a + gt_b) / 2 (the loader's target without gt_clean, twice
the spp) and gt_clean.exr with a reference render of the same frame in REF/<split> (its
gt_b.exr: at least 8x the spp, and a Cycles seed independent of gt_a's), using
dnmetrics (relMSE and LDR-FLIP). Prints one line per frame and the means.

  evaluate.py --dnmetrics build/bin/dnmetrics --data DATA --ref REF [--split val]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests"))
from exr_numpy import read_rgb, write_rgb  # noqa: E402


def metrics(dnmetrics, ref, tests):
    out = subprocess.run([dnmetrics, "--format", "json", "--metrics", "relmse,flip", ref] + tests,
                         capture_output=True, text=True, check=True)
    return {os.path.basename(r["file"]): r for r in json.loads(out.stdout)["results"]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--ref", required=True)
    ap.add_argument("--split", default="val")
    args = ap.parse_args()
    rows = []
    tmp = tempfile.mkdtemp()
    root = os.path.join(args.data, args.split)
    for scene in sorted(os.listdir(root)):
        for frame in sorted(os.listdir(os.path.join(root, scene))):
            d = os.path.join(root, scene, frame)
            ref = os.path.join(args.ref, args.split, scene, frame, "gt_b.exr")
            if not (os.path.exists(os.path.join(d, "gt_clean.exr")) and os.path.exists(ref)):
                continue
            pair = os.path.join(tmp, f"{scene}_{frame}_pair.exr")
            write_rgb(pair, (read_rgb(os.path.join(d, "gt_a.exr")) + read_rgb(os.path.join(d, "gt_b.exr"))) / 2)
            m = metrics(args.dnmetrics, ref, [os.path.join(d, "gt_a.exr"), pair, os.path.join(d, "gt_clean.exr")])
            rows.append((f"{scene}/{frame}", m["gt_a.exr"], m[os.path.basename(pair)], m["gt_clean.exr"]))
    if not rows:
        sys.exit("evaluate.py: no frame has both gt_clean.exr and a reference")
    print(f"{'frame':24s} {'relMSE: raw':>11s} {'pair':>8s} {'clean':>8s}   {'FLIP: raw':>9s} {'pair':>7s} {'clean':>7s}")
    for name, raw, pair, clean in rows:
        print(f"{name:24s} {raw['relmse']:11.5f} {pair['relmse']:8.5f} {clean['relmse']:8.5f}   "
              f"{raw['flip']:9.4f} {pair['flip']:7.4f} {clean['flip']:7.4f}")
    mean = lambda key, i: sum(r[i][key] for r in rows) / len(rows)  # noqa: E731
    print(f"{'mean of ' + str(len(rows)) + ' frames':24s} {mean('relmse', 1):11.5f} {mean('relmse', 2):8.5f} "
          f"{mean('relmse', 3):8.5f}   {mean('flip', 1):9.4f} {mean('flip', 2):7.4f} {mean('flip', 3):7.4f}")

if __name__ == "__main__":
    main()
