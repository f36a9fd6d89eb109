#!/usr/bin/env python3
"""Render the whole evaluation set (shots.py), resuming where a run stopped.

  python3 experiments/shots/build_set.py --out /work/data/shots            # in the foreground
  python3 experiments/shots/build_set.py --out /work/data/shots --detach   # in the background
  tail -f /work/data/shots/build.log
  python3 experiments/shots/build_set.py --set production --out /work/data/shots_1080 --detach
                                      # the 1080p-scale set (shots_1080.py), the same way

One bpy process per shot, one after another (--jobs N: N at once, the threads
shared among them). Every file is written under a temporary name and renamed, and
existing files are kept, so running the same command again finishes what is
missing; a shot whose files are all there is not started. Frames 1-8, 4 and 16
spp, the shot's reference spp, and ref2 (another seed) for the --check-frames.
Options after the known ones go to shots.py as they are (e.g. --res 128x96 to
render a smaller set into another folder).
"""

import argparse
import concurrent.futures
import os
import resource
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# The venv scripts/install.sh makes (bpy 5.0.1, numpy<2), or the one DN_BPY_VENV names.
BPY_PYTHON = os.path.join(os.environ.get("DN_BPY_VENV") or os.path.normpath(os.path.join(HERE, "..", "..", "build-venv-bpy")),
                          "bin", "python")
# The two sets: the 128x96 shots (shots.py) and the crops of 1080p frames (shots_1080.py).
SCRIPTS = {"evaluation": "shots.py", "production": "shots_1080.py"}


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def listing(python, script):
    """The set's shots in order: name -> (moving, the frames with references: a list, or
    None for every frame), from the script's --list."""
    out = subprocess.run([python, os.path.join(HERE, script), "--list"], capture_output=True, text=True,
                         check=True).stdout
    shots = {}
    for line in out.splitlines():
        if line.strip():
            fields = line.split()
            frames = fields[4] if script == "shots_1080.py" else "all"
            shots[fields[0]] = (fields[3] == "moving", None if frames == "all" else [int(f) for f in frames.split(",")])
    return shots


def expected(folder, moving, ref_frames, checks, extra):
    if extra:  # other settings: let the script decide what is missing
        return [None]
    names = ["spp%d.%04d.exr" % (spp, f) for f in range(1, 9) for spp in (4, 16)]
    if ref_frames is not None:  # the production set: two references for each scored frame
        names += ["%s.%04d.exr" % (r, f) for f in ref_frames for r in ("ref", "ref2")] if moving else ["ref.exr", "ref2.exr"]
    else:
        names += ["ref.%04d.exr" % f for f in range(1, 9)] if moving else ["ref.exr"]
        names += ["ref2.%04d.exr" % f for f in checks] if moving else ["ref2.exr"]
    return [n for n in names if not os.path.exists(os.path.join(folder, n))]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--set", choices=sorted(SCRIPTS), default="evaluation",
                    help="evaluation: the 128x96 shots; production: crops of 1080p frames")
    ap.add_argument("--shots", nargs="+", help="default: all of the set's")
    ap.add_argument("--python", default=BPY_PYTHON, help="a Python with bpy 5 (default: %(default)s)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--check-frames", default="4", help="frames that also get ref2 ('' for none; "
                    "the evaluation set only: the production set has ref2 on every scored frame)")
    ap.add_argument("--detach", action="store_true", help="run in the background (log: OUT/build.log)")
    args, extra = ap.parse_known_args()
    os.makedirs(args.out, exist_ok=True)
    log_path = os.path.join(args.out, "build.log")
    if args.detach:
        argv = [a for a in sys.argv if a != "--detach"]
        with open(log_path, "a") as log:
            child = subprocess.Popen([sys.executable] + argv, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        # The lowest priority: a new session is its own autogroup (Linux), where nice
        # alone changes nothing against other sessions; the group's own nice does.
        try:
            with open("/proc/%d/autogroup" % child.pid, "w") as group:
                group.write("19")
        except OSError:
            pass
        print("build_set: running in the background at the lowest priority, pid %d, log %s" % (child.pid, log_path))
        return
    script = SCRIPTS[args.set]
    shots = listing(args.python, script)
    unknown = set(args.shots or []) - set(shots)
    if unknown:
        ap.error("not in the %s set: %s" % (args.set, " ".join(sorted(unknown))))
    args.shots = args.shots or list(shots)
    checks = [int(f) for f in args.check_frames.split(",") if f]
    threads = max(1, args.threads // args.jobs)

    def one(shot):
        folder = os.path.join(args.out, shot)
        missing = expected(folder, *shots[shot], checks, extra)
        if not missing:
            return "%s: complete" % shot
        start, cpu = time.time(), children_cpu()
        cmd = [args.python, os.path.join(HERE, script), "--shot", shot, "--out", folder, "--threads", str(threads)]
        if args.set == "evaluation":
            cmd += ["--check-frames", args.check_frames]
        cmd += extra
        with open(os.path.join(args.out, shot + ".log"), "a") as log:
            code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        state = "done" if code == 0 else "FAILED (exit %d, see %s.log)" % (code, shot)
        # CPU time over the threads: the wall time on cores no one else uses (with --jobs 1)
        return "%s: %s in %.0f s (%.0f s of CPU / %d threads)" % (shot, state, time.time() - start,
                                                                 (children_cpu() - cpu) / threads, threads)

    start = time.time()
    print("build_set: %d %s shots into %s, %s" % (len(args.shots), args.set, args.out, time.strftime("%Y-%m-%d %H:%M:%S")),
          flush=True)
    failed = 0
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        for line in pool.map(one, args.shots):
            failed += "FAILED" in line
            print("build_set: " + line, flush=True)
    print("build_set: finished in %.0f s, %d failed" % (time.time() - start, failed), flush=True)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
