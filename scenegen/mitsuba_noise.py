#!/usr/bin/env python3
"""How correlated and how clean the frames of a data set are, per pixel filter (docs/dataset.md).

  python3 scenegen/mitsuba_noise.py DATA [--frames N] [--per-frame]

For every finished frame (meta.json present; at most N, in path order), with
ref = (gt_a + gt_b) / 2:
- lag-1 autocorrelation of the noise d = input - ref between horizontal and vertical
  neighbours (experiments/eval_renders.py's measure), for one 4-spp stack and for
  the mean of all stacks (linear radiance);
- relMSE of gt_a against gt_b and of one stack against ref: mean((x - y)^2 / (y^2 + 0.01))
  over pixels and channels, also without the 16 largest per-pixel errors (fireflies
  dominate the plain mean).
Frames are grouped by meta.json's `filter` ("cycles" for frames without one: the
Blender set, whose filter Cycles importance-samples instead of splatting).
Prints a Markdown table of the means per filter, and for the frames that record it
(mitsuba_gen.py's meta.json) the CPU seconds per frame per archetype: the throughput of
one render thread on a free core.
"""

import argparse
import glob
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "experiments"))
from eval_renders import lag1_autocorrelation  # noqa: E402
from exrutil import read_color  # noqa: E402


def rel_mse(x, y, trim=0):
    """Mean over pixels of the channels' mean (x - y)^2 / (y^2 + 0.01), without the `trim` largest."""
    per_pixel = np.sort(np.mean((x - y) ** 2 / (y * y + 0.01), axis=-1).ravel())
    return float(np.mean(per_pixel[:per_pixel.size - trim]))


def measure(fdir, meta):
    stacks = [read_color(os.path.join(fdir, f)).astype(np.float64) for f in meta["files"] if f.startswith("spp")]
    gt_a = read_color(os.path.join(fdir, "gt_a.exr")).astype(np.float64)
    gt_b = read_color(os.path.join(fdir, "gt_b.exr")).astype(np.float64)
    ref = 0.5 * (gt_a + gt_b)
    mean = np.mean(stacks, axis=0)
    return {"lag1_stack": lag1_autocorrelation(stacks[0], ref, False),
            "lag1_mean": lag1_autocorrelation(mean, ref, False),
            "lag1_gt": lag1_autocorrelation(gt_a, gt_b, False),
            "relmse_gt": rel_mse(gt_a, gt_b), "relmse_stack": rel_mse(stacks[0], ref),
            "relmse_gt_trim16": rel_mse(gt_a, gt_b, 16), "relmse_stack_trim16": rel_mse(stacks[0], ref, 16)}


def print_cost(metas):
    """CPU seconds per frame (all files rendered in one run) per archetype, from meta.json."""
    rows = {}
    for meta in metas:
        cpu = meta.get("render_cpu_seconds", {})
        if "frame_cpu_seconds" not in meta or any(v is None for v in cpu.values()):
            continue  # not a mitsuba_gen.py frame, or resumed from an interrupted run
        gt = sum(v for k, v in cpu.items() if k.startswith("gt"))
        rows.setdefault(meta["archetype"], []).append((meta["frame_cpu_seconds"], gt, sum(cpu.values()) - gt))
    if not rows:
        return
    every = [r for v in rows.values() for r in v]
    rows["all"] = every
    print("\n| archetype | frames | CPU s per frame | ground truth | stacks | frames/h on one free core |")
    print("|---|---|---|---|---|---|")
    for name, v in rows.items():
        total, gt, stacks = (float(np.mean([r[i] for r in v])) for i in range(3))
        print("| %s | %d | %.1f | %.1f | %.1f | %.0f |" % (name, len(v), total, gt, stacks, 3600 / total))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data")
    p.add_argument("--frames", type=int, default=0, help="at most this many frames (0: all)")
    p.add_argument("--per-frame", action="store_true")
    args = p.parse_args()
    metas = sorted(glob.glob(os.path.join(args.data, "*", "scene_*", "frame_*", "meta.json")))
    if not metas:
        sys.exit("mitsuba_noise.py: %s: no finished frames" % args.data)
    if args.frames:
        metas = metas[:args.frames]
    groups, all_meta = {}, []
    for path in metas:
        with open(path) as f:
            meta = json.load(f)
        all_meta.append(meta)
        fdir = os.path.dirname(path)
        m = measure(fdir, meta)
        groups.setdefault(meta.get("filter", "cycles"), []).append(m)
        if args.per_frame:
            print("%s %s %s" % (os.path.relpath(fdir, args.data), meta.get("filter", "cycles"),
                                " ".join("%s=%.4f" % kv for kv in m.items())))
    keys = ("lag1_stack", "lag1_mean", "lag1_gt", "relmse_stack", "relmse_gt", "relmse_stack_trim16",
            "relmse_gt_trim16")
    print("\n| filter | frames | lag-1 autocorr. (4 spp - ref) | (%d-spp mean - ref) | (gt_a - gt_b) "
          "| relMSE 4 spp | relMSE gt_a vs gt_b | the same without the 16 largest per-pixel errors: 4 spp "
          "| gt_a vs gt_b |" % (meta["spp"] * meta["stacks"]))
    print("|---|---|---|---|---|---|---|---|---|")
    for name, rows in sorted(groups.items()):
        print("| %s | %d | %s |" % (name, len(rows), " | ".join(
            ("%.3f" if k.startswith("lag") else "%.4f") % np.mean([r[k] for r in rows]) for k in keys)))
    print_cost(all_meta)
    return 0


if __name__ == "__main__":
    sys.exit(main())
