#!/usr/bin/env python3
"""The small committed manifest of a data set already on disk, in the format check_dataset.py reads.

  python3 scenegen/export_manifest.py /work/data/mitsuba256 scenegen/mitsuba128.json --first-seed 100000 --scenes 200

make_dataset.py writes the Blender set's manifest itself (make data-manifest); this one is
for sets made by other generators (scenegen/mitsuba_gen.py), read from the frames' meta.json.
Every frame must share the settings that check_dataset.py compares; frames rejected by the
generator (rejected.json, no meta.json) are not part of the set.
"""

import argparse
import glob
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from dataset_checks import cached  # noqa: E402
from make_dataset import count_frames, export_checks, read_json, split_of  # noqa: E402

SETTING_KEYS = ("res", "spp", "stacks", "gt_spp", "gt_depth", "gt_count")


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="the data set folder (train/, val/, test/)")
    p.add_argument("out", help="the manifest to write")
    p.add_argument("--first-seed", type=int, required=True, help="the generator's seed range, as it was given")
    p.add_argument("--scenes", type=int, required=True)
    args = p.parse_args(argv)
    scenes, settings, versions = {}, None, set()
    for path in sorted(glob.glob(os.path.join(args.data, "*", "scene_*", "frame_*", "meta.json"))):
        meta = read_json(path)
        if meta is None:
            sys.exit("export_manifest.py: %s: not readable JSON" % path)
        mine = {k: meta.get(k) for k in SETTING_KEYS}
        if settings is None:
            settings = mine
        elif mine != settings:
            sys.exit("export_manifest.py: %s: settings %s differ from the set's %s" % (path, mine, settings))
        if not args.first_seed <= meta["seed"] < args.first_seed + args.scenes:
            sys.exit("export_manifest.py: %s: seed %d is outside the range given" % (path, meta["seed"]))
        versions.add(meta.get("generator_version", "?"))
        fdir = os.path.dirname(path)
        frame = {"frame": meta["frame"], "archetype": meta.get("archetype", "?"),
                 "lighting": meta.get("lighting", "?"), "checks": cached(fdir, meta["files"])}
        scenes.setdefault(meta["seed"], []).append(frame)
    if not scenes:
        sys.exit("export_manifest.py: %s holds no finished frames" % args.data)
    settings["seed_tag"] = ""  # what check_dataset.py's frame_done() expects of frames without one
    listed = [{"seed": seed, "split": split_of(seed), "frames": frames} for seed, frames in sorted(scenes.items())]
    counts = {"train": 0, "val": 0, "test": 0}
    for s in listed:
        counts[s["split"]] += 1
    manifest = {"generator_versions": sorted(versions), "blender_version": None, "settings": settings,
                "seeds": {"first": args.first_seed, "count": args.scenes}, "scene_counts": counts,
                "frame_count": sum(len(s["frames"]) for s in listed), "frame_counts": count_frames(listed),
                "scenes": listed}
    export_checks(manifest, args.out)
    print("export_manifest.py: %d frames of %d scenes -> %s" % (manifest["frame_count"], len(listed), args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
