#!/usr/bin/env python3
"""scenegen/export_manifest.py and check_dataset.py on a made-up set with Mitsuba's layout:
the manifest round trip, a shard whose range holds a seed with every frame rejected, a
changed file and a missing frame.

  python3 tests/manifest_check.py --work-dir DIR
"""

import argparse
import json
import os
import shutil
import sys

try:
    import numpy as np
    sys.path.insert(0, os.path.dirname(__file__))
    from exr_numpy import write_rgb
    from cli_checks import check, run, summary
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e}")
    sys.exit(77)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scenegen"))
from make_dataset import scene_dir  # noqa: E402

EXPORT = os.path.join(ROOT, "scenegen", "export_manifest.py")
CHECK = os.path.join(ROOT, "scenegen", "check_dataset.py")
FIRST, COUNT, REJECTED = 500, 4, 501  # every frame of seed 501 rejected, as mitsuba_gen.py does
FILES = ["spp4_00.exr", "spp4_01.exr", "gt_a.exr", "gt_b.exr"]


def make_frame(data, seed, k):
    fdir = os.path.join(scene_dir(data, seed), "frame_%d" % k)
    os.makedirs(fdir)
    if seed == REJECTED:
        with open(os.path.join(fdir, "rejected.json"), "w") as f:
            json.dump({"reason": "gt_a and gt_b disagree"}, f)
        return
    rng = np.random.default_rng(seed * 10 + k)
    for name in FILES:
        write_rgb(os.path.join(fdir, name), rng.random((8, 8, 3)))
    meta = {"generator_version": "mitsuba-1.0.0", "seed": seed, "frame": k, "res": 8, "spp": 4, "stacks": 2,
            "gt_spp": 256, "gt_count": 2, "gt_depth": "16", "files": FILES, "archetype": "room",
            "lighting": "room"}
    with open(os.path.join(fdir, "meta.json"), "w") as f:
        json.dump(meta, f)


def verdict(data, manifest, *extra):
    out = run([sys.executable, CHECK, data, manifest, *extra])
    return out.returncode, (out.stdout.strip().splitlines() or [""])[-1]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--work-dir", required=True)
    work = p.parse_args().work_dir
    shutil.rmtree(work, ignore_errors=True)
    data, manifest = os.path.join(work, "data"), os.path.join(work, "manifest.json")
    for seed in range(FIRST, FIRST + COUNT):
        for k in range(2):
            make_frame(data, seed, k)

    out = run([sys.executable, EXPORT, data, manifest, "--first-seed", str(FIRST), "--scenes", str(COUNT)])
    check("export_manifest.py: exit 0", out.returncode == 0, out.stderr)
    with open(manifest) as f:
        m = json.load(f)
    check("the manifest lists the 6 frames that were not rejected",
          m["frame_count"] == 6 and len(m["frames"]) == 6 and m["seeds"] == {"first": FIRST, "count": COUNT}, m)
    code, line = verdict(data, manifest)
    check("the set itself: every frame identical", code == 0 and "6 identical" in line, line)
    # Shard 2/4 is seed 502, the third of the range, though only three seeds have frames.
    code, line = verdict(data, manifest, "--shard", "2/4")
    check("--shard 2/4: seed 502's 2 frames", code == 0 and line.endswith("2 frames: 2 identical, 0 close, "
                                                                          "0 missing, 0 differ"), line)
    code, line = verdict(data, manifest, "--shard", "1/4")
    check("--shard 1/4: the rejected seed, nothing to check", line.startswith("check_dataset.py: 0 frames"), line)

    gt = os.path.join(scene_dir(data, 503), "frame_1", "gt_a.exr")
    write_rgb(gt, np.full((8, 8, 3), 5.0))
    code, line = verdict(data, manifest)
    check("a changed ground truth: exit 1, one frame differs", code == 1 and "1 differ" in line, line)
    shutil.rmtree(os.path.join(scene_dir(data, 500), "frame_0"))
    code, line = verdict(data, manifest)
    check("a frame gone: exit 1, one missing", code == 1 and "1 missing" in line, line)

    bad = os.path.join(scene_dir(data, 502), "frame_0", "meta.json")
    with open(bad) as f:
        meta = json.load(f)
    meta["gt_spp"] = 64
    with open(bad, "w") as f:
        json.dump(meta, f)
    out = run([sys.executable, EXPORT, data, manifest, "--first-seed", str(FIRST), "--scenes", str(COUNT)])
    check("export_manifest.py: frames of other settings refused, naming the frame",
          out.returncode == 1 and "scene_000502/frame_0/meta.json" in out.stderr, out.stderr)
    return summary()


if __name__ == "__main__":
    sys.exit(main())
