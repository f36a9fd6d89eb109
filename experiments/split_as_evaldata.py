#!/usr/bin/env python3
"""A data set's split laid out as evaluation renders, grouped by pixel filter.

  python3 experiments/split_as_evaldata.py /work/data/mitsuba256/test /work/evalm --prefix mtest_
  python3 experiments/eval_sets.py --test-split /nonexistent --user --evaldata /work/evalm --work W --name NAME

Every finished frame of SPLIT becomes OUT/<prefix><filter>/<scene>_<frame>/ with spp4.exr
(its first 4-spp stack), spp16.exr (the mean of four, every channel, as make_inputs.py
makes them) and ref.exr (the mean of gt_a and gt_b). The filter is meta.json's
`filter` (Mitsuba's frames), "cycles" where there is none.
"""

import argparse
import glob
import json
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SPPS = (4, 16)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("split", help="a split folder of scene_*/frame_* (e.g. DATA/test)")
    p.add_argument("out", help="the evaluation folder to write (must not exist)")
    p.add_argument("--prefix", default="", help="put before each group's name")
    args = p.parse_args(argv)
    if os.path.exists(args.out):
        sys.exit("split_as_evaldata.py: %s exists; give a new folder" % args.out)
    tmp = os.path.join(args.out, ".inputs")
    count = 0
    for scene in sorted(glob.glob(os.path.join(args.split, "scene_*"))):
        metas = glob.glob(os.path.join(scene, "frame_*", "meta.json"))
        frames = sorted(os.path.basename(os.path.dirname(m)) for m in metas)
        if not frames:
            continue
        subprocess.run([sys.executable, os.path.join(HERE, "make_inputs.py"), "scene", scene, "--frames", *frames,
                        "--spps", *map(str, SPPS), "--inputs", tmp, "--refs", tmp],
                       check=True, stdout=subprocess.DEVNULL)
        for frame in frames:
            with open(os.path.join(scene, frame, "meta.json")) as f:
                group = args.prefix + json.load(f).get("filter", "cycles")
            target = os.path.join(args.out, group, "%s_%s" % (os.path.basename(scene), frame))
            os.makedirs(target)
            for spp in SPPS:
                os.replace(os.path.join(tmp, "%s_spp%d.exr" % (frame, spp)), os.path.join(target, "spp%d.exr" % spp))
            os.replace(os.path.join(tmp, frame + ".exr"), os.path.join(target, "ref.exr"))
            count += 1
    shutil.rmtree(tmp, ignore_errors=True)
    print("split_as_evaldata.py: %d frames -> %s" % (count, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
