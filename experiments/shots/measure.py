#!/usr/bin/env python3
"""Time and reference noise per shot, from tiny renders; the set's time extrapolated.

  python3 experiments/shots/measure.py [--res 64x48] [--spp 128] [--threads 2] [shot ...]
  python3 experiments/shots/measure.py --set production [--res 96x96] ...   (the 1080p-scale set:
      a 96x96 crop of the 1080p frame, on the same point; the shot is extrapolated at its
      crop with two references on each scored frame)

For each shot renders frame 4 at --res: 4 spp (to warm the scene up), --spp with
the noisy seed (timed), and two references of different seeds at --spp. Prints
the seconds per million samples x pixels (CPU seconds / threads: the wall time on
cores no one else uses; the wall time is longer while other work shares them), the PSNR of the two references (check_refs.py)
and that PSNR carried to 1024 and 4096 spp (noise variance falls as 1/spp: +10
log10(N/spp) dB), and the full shot's time at its resolution (8 frames of 4 + 16
spp and the reference, one ref2 frame), extrapolated linearly in samples x pixels.
"""

import argparse
import math
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from build_set import BPY_PYTHON, SCRIPTS, listing  # noqa: E402
from check_refs import combined, psnr  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("shots", nargs="*")
    ap.add_argument("--set", choices=sorted(SCRIPTS), default="evaluation")
    ap.add_argument("--res", default="", help="default: 64x48 (evaluation), 96x96 (production)")
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--python", default=BPY_PYTHON, help="a Python with bpy 5 (default: %(default)s)")
    args = ap.parse_args()
    production = args.set == "production"
    script = SCRIPTS[args.set]
    args.res = args.res or ("96x96" if production else "64x48")
    width, height = (int(v) for v in args.res.split("x"))
    lines = subprocess.run([args.python, os.path.join(HERE, script), "--list"], capture_output=True,
                           text=True, check=True).stdout
    table = {line.split()[0]: line.split()[1:4] for line in lines.splitlines() if line.strip()}
    ref_frames = {shot: frames for shot, (_, frames) in listing(args.python, script).items()}
    args.shots = args.shots or list(table)
    total = 0.0
    print("| shot | s per Mspp-px | ref vs ref2 at %d spp | at 1024 | at 4096 | ref spp | shot res | shot time s | mean radiance |" % args.spp)
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for shot in args.shots:
            out = os.path.join(tmp, shot)
            size = ["--crop", str(width)] if production else ["--res", args.res]
            refs = ["--ref-frames", "4"] if production else ["--check-frames", "4"]
            log = subprocess.run([args.python, os.path.join(HERE, script), "--shot", shot, "--out", out] + size +
                                 ["--frames", "4-4", "--spp", "4", str(args.spp), "--ref-spp", str(args.spp),
                                  "--threads", str(args.threads)] + refs, capture_output=True, text=True)
            # CPU seconds over the threads: the wall time on cores no one else uses
            seconds = re.findall(r"spp%d\.0004\.exr \(\d+ spp\) [\d.]+ s, ([\d.]+) s of CPU" % args.spp, log.stdout)
            if log.returncode or not seconds:
                print("| %s | failed: %s |" % (shot, log.stderr.strip().splitlines()[-1:]))
                continue
            per = float(seconds[0]) / args.threads / (args.spp * width * height) * 1e6
            moving = table[shot][2] == "moving"
            name = "ref%s.0004.exr" if moving else "ref%s.exr"
            first = combined(os.path.join(out, name % ""))
            noise = psnr(first, combined(os.path.join(out, name % "2")))
            level = float(first.mean())  # linear: the Reinhard scores compress what is far above 1
            res, ref_spp = table[shot][0], int(table[shot][1])
            pixels = math.prod(int(v) for v in res.split("x"))
            if production:  # ref and ref2 on each scored frame
                samples = 8 * (4 + 16) + 2 * (len(ref_frames[shot]) if moving else 1) * ref_spp
            else:
                samples = 8 * (4 + 16) + (8 if moving else 1) * ref_spp + ref_spp  # + one ref2 frame
            shot_time = per * 1e-6 * samples * pixels
            total += shot_time
            print("| %s | %.2f | %.2f | %.2f | %.2f | %d | %s | %.0f | %.3f |" % (
                shot, per, noise, noise + 10 * math.log10(1024 / args.spp), noise + 10 * math.log10(4096 / args.spp),
                ref_spp, res, shot_time, level), flush=True)
    print("set: %.0f s (%.1f h) at %d threads, extrapolated" % (total, total / 3600, args.threads))


if __name__ == "__main__":
    main()
