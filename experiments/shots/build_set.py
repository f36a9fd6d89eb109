#!/usr/bin/env python3
"""Render the whole evaluation set (shots.py), resuming where a run stopped.

  python3 experiments/shots/build_set.py --out /work/data/shots            # in the foreground
  python3 experiments/shots/build_set.py --out /work/data/shots --detach   # in the background
  tail -f /work/data/shots/build.log

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
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# The venv scripts/install.sh makes (bpy 5.0.1, numpy<2), or the one DN_BPY_VENV names.
BPY_PYTHON = os.path.join(os.environ.get("DN_BPY_VENV") or os.path.normpath(os.path.join(HERE, "..", "..", "build-venv-bpy")),
                          "bin", "python")
SHOTS = ["room_dolly", "room_pan", "room_still", "fox_walk", "helmet_orbit", "vase_handheld", "toycar_pass",
         "truck_track", "lamp_swing", "sun_sweep", "glass_turntable", "texture_dolly", "fox_yard",
         "attic_still", "porch_still"]


def expected(folder, moving, checks, extra):
    if extra:  # other settings: let shots.py decide what is missing
        return [None]
    names = ["spp%d.%04d.exr" % (spp, f) for f in range(1, 9) for spp in (4, 16)]
    names += ["ref.%04d.exr" % f for f in range(1, 9)] if moving else ["ref.exr"]
    names += ["ref2.%04d.exr" % f for f in checks] if moving else ["ref2.exr"]
    return [n for n in names if not os.path.exists(os.path.join(folder, n))]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--shots", nargs="+", default=SHOTS, choices=SHOTS)
    ap.add_argument("--python", default=BPY_PYTHON, help="a Python with bpy 5 (default: %(default)s)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--check-frames", default="4", help="frames that also get ref2 ('' for none)")
    ap.add_argument("--detach", action="store_true", help="run in the background (log: OUT/build.log)")
    args, extra = ap.parse_known_args()
    os.makedirs(args.out, exist_ok=True)
    log_path = os.path.join(args.out, "build.log")
    if args.detach:
        argv = [a for a in sys.argv if a != "--detach"]
        with open(log_path, "a") as log:
            child = subprocess.Popen([sys.executable] + argv, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        print("build_set: running in the background, pid %d, log %s" % (child.pid, log_path))
        return
    listing = subprocess.run([args.python, os.path.join(HERE, "shots.py"), "--list"], capture_output=True,
                             text=True, check=True).stdout
    moving = {line.split()[0]: line.split()[3] == "moving" for line in listing.splitlines() if line.strip()}
    checks = [int(f) for f in args.check_frames.split(",") if f]
    threads = max(1, args.threads // args.jobs)

    def one(shot):
        folder = os.path.join(args.out, shot)
        missing = expected(folder, moving[shot], checks, extra)
        if not missing:
            return "%s: complete" % shot
        start = time.time()
        cmd = [args.python, os.path.join(HERE, "shots.py"), "--shot", shot, "--out", folder, "--threads",
               str(threads), "--check-frames", args.check_frames] + extra
        with open(os.path.join(args.out, shot + ".log"), "a") as log:
            code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        state = "done" if code == 0 else "FAILED (exit %d, see %s.log)" % (code, shot)
        return "%s: %s in %.0f s" % (shot, state, time.time() - start)

    start = time.time()
    print("build_set: %d shots into %s, %s" % (len(args.shots), args.out, time.strftime("%Y-%m-%d %H:%M:%S")),
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
