#!/usr/bin/env python3
"""Frames per hour of the data set generator, and where its CPU time goes.

  python3 bench/scenegen_profile.py --out /tmp/prof --seeds 1000-1029 [make_dataset.py options]
  python3 bench/scenegen_profile.py --out DATA --summary     # only the table, from what DATA holds

Renders the seeds with scenegen/make_dataset.py --profile (options after the known
ones go to it; defaults are the training set's: 128x128, 8 x 4 spp, 2 x 64-spp
ground truth, 2 frames), --procs processes (shards) side by side with one Cycles
thread each, so that the serial parts of one (start-up, scene build, EXR writes)
do not leave a core idle. Then, from the frames' meta.json and the batch logs
(so also for a run that was stopped: --summary), prints a table of CPU seconds per
frame by phase: Blender start-up (process start to the script running, paid once
per batch of --batch scenes), scene build (Python: geometry, materials, camera
search), exposure probe (the first render, 32x32: image textures, shaders, BVH build),
sampling of the stacks and of the ground truths, and EXR writes (one multilayer file
written again per frame, times the files per frame). CPU seconds do not grow much
when other jobs share the machine, wall seconds do: frames per hour on free cores
is 3600 x cores / (CPU seconds per frame). The driver's own work (planning, the
checks in the manifest) is not in the table; --summary prints it when the run
was made here (rusage of the children).
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


def run(args, extra):
    """make_dataset.py shards side by side; returns (wall seconds, CPU seconds of the children)."""
    defaults = {"--res": "128", "--spp": "4", "--stacks": "8", "--gt-spp": "64", "--frames": "2",
                "--threads": "1", "--batch": "20"}
    for key, value in defaults.items():
        if key not in extra:
            extra += [key, value]
    cmd = [sys.executable, os.path.join(ROOT, "scenegen", "make_dataset.py"), "--out", args.out,
           "--seeds", seed_list(args.seeds), "--profile"] + extra
    print("$ " + " ".join(cmd) + " --shard i/%d for i < %d" % (args.procs, args.procs), file=sys.stderr)
    t0 = time.time()
    procs = [subprocess.Popen(cmd + ["--shard", "%d/%d" % (i, args.procs)]) for i in range(args.procs)]
    if any(proc.wait() != 0 for proc in procs):
        sys.exit("scenegen_profile.py: make_dataset.py failed")
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.time() - t0, usage.ru_utime + usage.ru_stime


def finished_frames(out):
    metas = [json.load(open(m)) for m in glob.glob(os.path.join(out, "*", "scene_*", "frame_*", "meta.json"))]
    return [m for m in metas if "exr_write_cpu_seconds" in m and None not in m["render_cpu_seconds"].values()]


def phases(out, metas, batch):
    """[(phase, CPU seconds per frame)] over the finished frames."""
    n = len(metas)
    scenes = {m["seed"]: m for m in metas}
    logs = "".join(open(log).read() for log in glob.glob(os.path.join(out, "logs", "batch_*.log")))
    starts = [float(c) for c in re.findall(r"start-up [0-9.]+ s, ([0-9.]+) s CPU", logs)]
    startup = sum(starts) / len(starts) if starts else 0.0
    frames_per_scene = n / len(scenes)
    files = len(metas[0]["files"])
    stacks = metas[0]["stacks"]
    write = sum(m["exr_write_cpu_seconds"] for m in metas) / n

    def render(prefix):
        return sum(v for m in metas for k, v in m["render_cpu_seconds"].items() if k.startswith(prefix)) / n

    return [("Blender start-up (once per %d scenes)" % batch, startup / (batch * frames_per_scene)),
            ("scene build (Python: geometry, materials, camera search)",
             sum(m["scene_build_cpu_seconds"] for m in scenes.values()) / n),
            ("exposure probe (first render: textures, shaders, BVH build)",
             sum(m["probe_cpu_seconds"] for m in scenes.values()) / n),
            ("stacks: sampling (%d x %d spp)" % (stacks, metas[0]["spp"]), render("spp") - write * stacks),
            ("ground truth: sampling (%d x %d spp)" % (files - stacks, metas[0]["gt_spp"]),
             render("gt") - write * (files - stacks)),
            ("EXR writes (%d multilayer files)" % files, write * files)]


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="a fresh folder (or a data set, with --summary)")
    p.add_argument("--seeds", default="1000-1029", help="A-B or a comma list")
    p.add_argument("--procs", type=int, default=2, help="make_dataset.py processes (shards) side by side")
    p.add_argument("--cores", type=int, default=2, help="cores of the machine the estimate is for")
    p.add_argument("--batch", type=int, default=20, help="scenes per Blender process (start-up share)")
    p.add_argument("--summary", action="store_true", help="render nothing; summarise what --out holds")
    args, extra = p.parse_known_args(argv)
    measured = None
    load0 = os.getloadavg()[0]
    if not args.summary:
        measured = run(args, extra + ["--batch", str(args.batch)])
    metas = finished_frames(args.out)
    if not metas:
        sys.exit("scenegen_profile.py: %s: no frames rendered with --profile" % args.out)
    table = phases(args.out, metas, args.batch)
    cpu = sum(s for _, s in table)
    archetypes = sorted({m.get("archetype", "?") for m in metas})
    print("%d frames of %d scenes (%s) in %s" % (len(metas), len({m["seed"] for m in metas}),
                                                 ", ".join(archetypes), args.out))
    print("frames per hour on %d free cores: %.0f (%.1f CPU s per frame)" % (args.cores, 3600 * args.cores / cpu, cpu))
    if measured:
        wall, cpu_all = measured
        print("this run: %.0f s wall (%.0f frames per hour; load average %.1f at the start, %.1f at the end), "
              "%.0f s CPU in all, of which %.1f s per frame outside the table (driver, checks)"
              % (wall, 3600 * len(metas) / wall, load0, os.getloadavg()[0], cpu_all, cpu_all / len(metas) - cpu))
    print("| phase | CPU s per frame | share |")
    print("|---|---|---|")
    for name, seconds in table:
        print("| %s | %.2f | %.0f%% |" % (name, seconds, 100 * seconds / cpu))
    print("| total | %.2f | 100%% |" % cpu)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
