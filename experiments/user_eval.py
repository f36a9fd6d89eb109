#!/usr/bin/env python3
"""Score dndenoise on user-style renders (user_scenes.py): L1, PSNR, SSIM, FLIP.

  user_eval.py --dir DIR --name default                  (dndenoise at its defaults)
  user_eval.py --dir DIR --name skip22 -- --skip 22      (extra dndenoise arguments)
  user_eval.py --dir DIR --name noisy                    (the input itself)
  user_eval.py --dir DIR --name oidn                     (OIDN 2, through oidn_denoise.py)

DIR holds SCENE_<N>spp.exr renders and one SCENE_ref.exr per scene. Results go to
DIR/out/<name>/; each line is one render, then the mean per spp.
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
METRICS = ("l1", "psnr", "ssim", "flip")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dir", required=True)
    parser.add_argument("--name", required=True)
    parser.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    args, extra = parser.parse_known_args()
    extra = extra[1:] if extra[:1] == ["--"] else extra
    out = os.path.join(args.dir, "out", args.name)
    os.makedirs(out, exist_ok=True)

    renders = sorted(glob.glob(os.path.join(args.dir, "*_*spp.exr")))
    if not renders:
        sys.exit("user_eval.py: %s: no SCENE_<N>spp.exr renders" % args.dir)
    by_spp = {}
    print("%-22s %8s %8s %8s %8s" % (("render",) + METRICS))
    for render in renders:
        scene, spp = re.match(r"(.+)_(\d+)spp\.exr$", os.path.basename(render)).groups()
        reference = os.path.join(args.dir, scene + "_ref.exr")
        result = os.path.join(out, os.path.basename(render))
        if args.name == "noisy":
            result = render
        elif not os.path.exists(result):
            if args.name == "oidn":
                cmd = [sys.executable, os.path.join(HERE, "oidn_denoise.py"), render, "-o", result]
            else:
                cmd = [os.path.join(args.bin, "dndenoise"), render, "-o", result, "--rgb-only"] + extra
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        scores = json.loads(subprocess.run(
            [os.path.join(args.bin, "dnmetrics"), "--format", "json", "--metrics", ",".join(METRICS),
             reference, result], check=True, capture_output=True, text=True).stdout)
        row = [scores["results"][0][m] for m in METRICS]
        by_spp.setdefault(int(spp), []).append(row)
        print("%-22s %8.4f %8.2f %8.4f %8.4f" % ((os.path.basename(render),) + tuple(row)))
    for spp, rows in sorted(by_spp.items()):
        mean = [sum(r[i] for r in rows) / len(rows) for i in range(len(METRICS))]
        print("%-22s %8.4f %8.2f %8.4f %8.4f" % (("mean %d spp" % spp,) + tuple(mean)))


if __name__ == "__main__":
    main()
