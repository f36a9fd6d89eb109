#!/usr/bin/env python3
"""Frames per hour of the data set generator, and where its time goes.

  python3 bench/scenegen_profile.py --out /tmp/prof --seeds 1000-1029 [make_dataset.py options]

Renders the seeds with scenegen/make_dataset.py --profile (options after the known
ones go to it; defaults are the training set's: 128x128, 16 x 4 spp, 2 x 256-spp
ground truth, 2 frames, 2 threads), then prints wall and CPU time, frames per hour as
measured and as if the cores were free (CPU seconds / threads: the machine may be
shared), and a table of the phases per frame in CPU seconds (robust to a busy machine)
and wall seconds: Blender start-up (process start to the
script running), scene build (Python: geometry, materials, camera search), exposure
probe (a 32x32 render: kernel load, scene sync and BVH build happen here), sampling
of the stacks and of the ground truths, EXR writes (one multilayer file timed again
per frame, times the files per frame) and the rest (driver, manifest, checks).
--procs processes (shards) run side by side with --threads each (default 2 x 1 thread:
the serial parts of one process, start-up, scene build, EXR writes, do not leave a core idle).
"""

import argparse
import glob
import json
import os
import re
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def seed_list(text):
    if "-" in text:
        lo, hi = (int(x) for x in text.split("-"))
        return ",".join(str(s) for s in range(lo, hi + 1))
    return text


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="a fresh folder")
    p.add_argument("--seeds", default="1000-1029", help="A-B or a comma list")
    p.add_argument("--procs", type=int, default=2, help="make_dataset.py processes (shards) side by side")
    args, extra = p.parse_known_args(argv)
    defaults = {"--res": "128", "--spp": "4", "--stacks": "16", "--gt-spp": "256", "--frames": "2",
                "--threads": "1", "--batch": "20"}
    for key, value in defaults.items():
        if key not in extra:
            extra += [key, value]
    threads = int(extra[extra.index("--threads") + 1]) * args.procs
    cmd = [sys.executable, os.path.join(ROOT, "scenegen", "make_dataset.py"), "--out", args.out,
           "--seeds", seed_list(args.seeds), "--profile"] + extra
    print("$ " + " ".join(cmd) + " --shard i/%d for i < %d" % (args.procs, args.procs), file=sys.stderr)
    load0 = os.getloadavg()[0]
    t0 = time.time()
    procs = [subprocess.Popen(cmd + ["--shard", "%d/%d" % (i, args.procs)]) for i in range(args.procs)]
    if any(proc.wait() != 0 for proc in procs):
        sys.exit("scenegen_profile.py: make_dataset.py failed")
    wall = time.time() - t0
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = usage.ru_utime + usage.ru_stime

    metas = [json.load(open(m)) for m in glob.glob(os.path.join(args.out, "*", "scene_*", "frame_*", "meta.json"))]
    metas = [m for m in metas if "render_cpu_seconds" in m and None not in m["render_cpu_seconds"].values()]
    if not metas:
        sys.exit("scenegen_profile.py: no frames were rendered")
    n = len(metas)
    scenes = {m["seed"]: m for m in metas}
    logs = "".join(open(log).read() for log in glob.glob(os.path.join(args.out, "logs", "batch_*.log")))
    starts = [(float(w), float(c)) for w, c in re.findall(r"start-up ([0-9.]+) s, ([0-9.]+) s CPU", logs)]
    files = len(metas[0]["files"])
    n_stacks = metas[0]["stacks"]

    def total(key, kind, pick):
        return sum(v for m in metas for name, v in m[key].items() if name.startswith(pick) and v) if kind else 0

    phases = []
    for label, wall_s, cpu_s in [
            ("Blender start-up", sum(w for w, _ in starts), sum(c for _, c in starts)),
            ("scene build (Python: geometry, materials, camera search)",
             sum(m["scene_build_seconds"] for m in scenes.values()),
             sum(m["scene_build_cpu_seconds"] for m in scenes.values())),
            ("exposure probe (kernel load, scene sync, BVH build)",
             sum(m["probe_seconds"] for m in scenes.values()), sum(m["probe_cpu_seconds"] for m in scenes.values())),
            ("stacks: sampling (%d x %d spp)" % (n_stacks, metas[0]["spp"]),
             total("render_seconds", 1, "spp") - sum(m["exr_write_seconds"] for m in metas) * n_stacks,
             total("render_cpu_seconds", 1, "spp") - sum(m["exr_write_cpu_seconds"] for m in metas) * n_stacks),
            ("ground truth: sampling (%d x %d spp)" % (files - n_stacks, metas[0]["gt_spp"]),
             total("render_seconds", 1, "gt") - sum(m["exr_write_seconds"] for m in metas) * (files - n_stacks),
             total("render_cpu_seconds", 1, "gt") - sum(m["exr_write_cpu_seconds"] for m in metas) * (files - n_stacks)),
            ("EXR writes (%d multilayer files)" % files, sum(m["exr_write_seconds"] for m in metas) * files,
             sum(m["exr_write_cpu_seconds"] for m in metas) * files)]:
        phases.append((label, wall_s, cpu_s))
    wall_all = wall * args.procs  # phase wall times are summed over the side-by-side processes
    phases.append(("rest (driver, checks, manifest)", wall_all - sum(p[1] for p in phases),
                   cpu - sum(p[2] for p in phases)))
    print("%d frames of %d scenes in %.0f s wall, %.0f s CPU; load average %.1f at the start, %.1f at the end"
          % (n, len(scenes), wall, cpu, load0, os.getloadavg()[0]))
    print("frames per hour: %.0f measured; %.0f with %d free cores (CPU seconds / %d)"
          % (3600 * n / wall, 3600 * n / (cpu / threads), threads, threads))
    print("| phase | CPU s per frame | share of CPU | wall s per frame (one process) |")
    print("|---|---|---|---|")
    for name, wall_s, cpu_s in phases:
        print("| %s | %.2f | %.0f%% | %.2f |" % (name, cpu_s / n, 100 * cpu_s / cpu, wall_s / n))
    print("| total | %.2f | 100%% | %.2f |" % (cpu / n, wall_all / n))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
