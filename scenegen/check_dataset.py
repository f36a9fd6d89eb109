#!/usr/bin/env python3
"""Compares a rebuilt data set with the committed manifest of the one the model was trained on.

  python3 scenegen/check_dataset.py DATA scenegen/dataset128.json [--shard i/n]

For every frame the manifest lists (only this shard's scenes with --shard), the rebuilt
frame is 'identical' (every file's pixel digest matches), 'close' (colour statistics of
the ground truth and of the stacks within tolerance: Cycles does not reproduce bits
across CPUs or builds), 'missing', or differs (the statistics that are off are printed).
Exits 1 unless every frame is identical or close.
"""

import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from dataset_checks import CheckError, cached, compare  # noqa: E402
from make_dataset import frame_done, parse_shard, scene_dir  # noqa: E402


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="the rebuilt data set folder")
    p.add_argument("manifest", help="the committed manifest (make_dataset.py --export, export_manifest.py)")
    p.add_argument("--shard", type=parse_shard, default=(0, 1), help="i/n: only this shard's scenes")
    p.add_argument("--rel-mean", type=float, default=0.03, help="relative tolerance of channel means")
    p.add_argument("--rel-std", type=float, default=0.10, help="relative tolerance of channel deviations")
    args = p.parse_args(argv)
    try:
        with open(args.manifest) as f:
            manifest = json.load(f)
        fields = manifest["frame_fields"]
        settings = manifest["settings"]
    except (OSError, ValueError, KeyError) as err:
        sys.exit("check_dataset.py: %s: not a data set manifest (%s)" % (args.manifest, err))
    # The generators shard by position in the seed range they were given, so a
    # seed whose frames were all rejected still takes its turn.
    seeds = manifest.get("seeds")
    if not isinstance(seeds, list):
        seeds = list(range(seeds["first"], seeds["first"] + seeds["count"]))
    mine = {s for j, s in enumerate(seeds) if j % args.shard[1] == args.shard[0]}
    tally = {"identical": 0, "close": 0, "missing": 0, "differs": 0}
    for row in manifest["frames"]:
        frame = dict(zip(fields, row))
        if frame["seed"] not in mine:
            continue
        sdir = scene_dir(args.data, frame["seed"])
        fdir = os.path.join(sdir, "frame_%d" % frame["frame"])
        if not os.path.exists(os.path.join(fdir, "meta.json")) or not frame_done(sdir, frame["frame"], settings):
            tally["missing"] += 1
            print("missing: %s" % fdir)
            continue
        try:
            files = json.load(open(os.path.join(fdir, "meta.json")))["files"]
            verdict = compare(frame["checks"], cached(fdir, files), args.rel_mean, args.rel_std)
        except (CheckError, OSError, ValueError) as err:
            verdict = str(err)
        if verdict in ("identical", "close"):
            tally[verdict] += 1
        else:
            tally["differs"] += 1
            print("differs: %s: %s" % (fdir, verdict))
    total = sum(tally.values())
    print("check_dataset.py: %d frames: %d identical, %d close, %d missing, %d differ"
          % (total, tally["identical"], tally["close"], tally["missing"], tally["differs"]))
    return 0 if total and tally["missing"] == tally["differs"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
