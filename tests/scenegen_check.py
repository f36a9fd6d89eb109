#!/usr/bin/env python3
"""The data set generator's driver without Blender: splits, shards, resume, manifest, checks.

  python3 tests/scenegen_check.py --work-dir DIR [--blender blender]

Builds a fake data set (small EXRs written with the OpenEXR module, meta.json as
generate.py writes it) and runs scenegen/make_dataset.py's planning, manifest and
export and scenegen/check_dataset.py on it. With --blender (an executable that exists),
also renders one tiny real frame through make_dataset.py and checks it against itself.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenEXR

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENEGEN = os.path.join(ROOT, "scenegen")
sys.path.insert(0, SCENEGEN)
import make_dataset as md  # noqa: E402
from dataset_checks import compare  # noqa: E402

FAILURES = []


def check(condition, what):
    print(("ok:   " if condition else "FAIL: ") + what)
    if not condition:
        FAILURES.append(what)


def write_exr(path, value, rng):
    """A 16x16 half-float file with Blender's Combined and albedo channel names."""
    channels = {}
    for c in "RGB":
        channels["ViewLayer.Combined." + c] = (value + 0.01 * rng.standard_normal((16, 16))).astype(np.float16)
        channels["ViewLayer.Denoising Albedo." + c] = np.full((16, 16), 0.5, np.float16)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels).write(path)


def fake_frame(args, seed, k, archetype, lighting, rng):
    fdir = os.path.join(md.scene_dir(args.out, seed), "frame_%d" % k)
    os.makedirs(fdir, exist_ok=True)
    files = ["spp%d_%02d.exr" % (args.spp, i) for i in range(args.stacks)] + ["gt_a.exr", "gt_b.exr"]
    for name in files:
        write_exr(os.path.join(fdir, name), 0.2 + 0.01 * seed, rng)
    meta = {"generator_version": "test", "blender_version": "none", "seed": seed, "frame": k,
            "res": args.res, "spp": args.spp, "stacks": args.stacks, "gt_spp": args.gt_spp, "gt_count": 2,
            "gt_depth": args.gt_depth, "seed_tag": "", "archetype": archetype, "lighting": lighting,
            "render_seeds": {f: 1 for f in files}, "render_seconds": {f: 0.5 for f in files},
            "frame_seconds": 9.0, "exposure_scale": 1.0, "files": files}
    with open(os.path.join(fdir, "meta.json"), "w") as f:
        json.dump(meta, f)
    return fdir


def test_splits_and_shards():
    splits = [md.split_of(s) for s in range(20000)]
    check(splits == [md.split_of(s) for s in range(20000)], "split_of is deterministic")
    test, val = splits.count("test") / 20000, splits.count("val") / 20000
    check(0.04 < test < 0.06 and 0.02 < val < 0.04, "split fractions %.3f test, %.3f val" % (test, val))
    args = md.parse_args(["--out", "/nonexistent", "--scenes", "23", "--first-seed", "5"])
    covered = []
    for i in range(4):
        args.shard = (i, 4)
        seeds, _ = md.plan_work(args)
        covered += seeds
    check(sorted(covered) == list(range(5, 28)), "4 shards cover every seed exactly once")
    check([len(b) for b in md.batches(list(range(45)), 20)] == [20, 20, 5], "batches of 20")
    for bad in ("4/4", "1", "a/b", "-1/3"):
        try:
            md.parse_shard(bad)
            check(False, "--shard %s refused" % bad)
        except Exception:
            check(True, "--shard %s refused" % bad)


def test_commands():
    args = md.parse_args(["--out", "/d", "--blender", "/venv/bin/python"])
    cmd = md.generator_command(args, "/d/jobs.json")
    check(cmd[:2] == ["/venv/bin/python", md.GENERATE] and "--jobs" in cmd, "bpy module command")
    args = md.parse_args(["--out", "/d", "--blender", "blender", "--profile"])
    cmd = md.generator_command(args, "/d/jobs.json")
    check(cmd[:5] == ["blender", "-b", "--factory-startup", "--python", md.GENERATE] and cmd[5] == "--"
          and "--profile" in cmd, "Blender executable command")


def test_manifest_and_checks(work):
    out = os.path.join(work, "data")
    shutil.rmtree(out, ignore_errors=True)
    args = md.parse_args(["--out", out, "--scenes", "6", "--first-seed", "100", "--res", "16", "--stacks", "2",
                          "--gt-spp", "8", "--frames", "2"])
    rng = np.random.default_rng(0)
    layout = {100: ("night", "night"), 101: ("thin", "hdri"), 102: ("night", "night"), 103: ("photo", "hdri")}
    for seed, (arch, light) in layout.items():
        for k in range(2):
            fake_frame(args, seed, k, arch, light, rng)
    # Seed 104: frame 0 done, frame 1 started (a file but no meta.json); 105 not started.
    fake_frame(args, 104, 0, "thin", "window", rng)
    os.makedirs(os.path.join(md.scene_dir(out, 104), "frame_1"))
    write_exr(os.path.join(md.scene_dir(out, 104), "frame_1", "spp4_00.exr"), 0.1, rng)
    _, work_left = md.plan_work(args)
    check(work_left == [(104, [1]), (105, [0, 1])], "resume: only unfinished frames are planned (%s)" % work_left)
    os.remove(os.path.join(md.scene_dir(out, 100), "frame_1", "gt_b.exr"))
    check(not md.frame_done(md.scene_dir(out, 100), 1, md.render_settings(args)),
          "a frame with a listed file missing is not done")
    fake_frame(args, 100, 1, "night", "night", rng)

    manifest = md.write_manifest(args, "none")
    check(manifest["frame_count"] == 9, "manifest lists the 9 finished frames (%d)" % manifest["frame_count"])
    counts = manifest["frame_counts"]
    check(counts["archetype"] == {"night": 4, "photo": 2, "thin": 3}, "frames per archetype %s" % counts["archetype"])
    check(counts["archetype_lighting"]["thin"] == {"hdri": 2, "window": 1}, "frames per archetype and lighting")
    export = os.path.join(work, "export.json")
    md.export_checks(manifest, export)
    data = json.load(open(export))
    check(len(data["frames"]) == 9 and len(data["frames"][0][5]["digests"]) == 4, "export: 9 frames, 4 digests each")

    checker = [sys.executable, os.path.join(SCENEGEN, "check_dataset.py")]
    run = subprocess.run(checker + [out, export], capture_output=True, text=True)
    check(run.returncode == 0 and "9 identical" in run.stdout, "a data set matches its own manifest")
    run = subprocess.run(checker + [out, export, "--shard", "1/2"], capture_output=True, text=True)
    check(run.returncode == 0 and "4 frames" in run.stdout, "--shard 1/2 checks that shard's frames only")

    # Slightly different pixels (another CPU): close; far off: differs; deleted: missing.
    fdir = os.path.join(md.scene_dir(out, 101), "frame_0")
    write_exr(os.path.join(fdir, "gt_a.exr"), 0.2 + 0.01 * 101, np.random.default_rng(7))
    write_exr(os.path.join(md.scene_dir(out, 102), "frame_0", "gt_b.exr"), 5.0, rng)
    shutil.rmtree(os.path.join(md.scene_dir(out, 103), "frame_1"))
    run = subprocess.run(checker + [out, export], capture_output=True, text=True)
    check(run.returncode == 1 and "6 identical, 1 close, 1 missing, 1 differ" in run.stdout,
          "close, differs and missing are told apart: " + run.stdout.strip().splitlines()[-1])
    expected = {"digests": ["a"], "gt": [0.1, 0.1, 0.1, 0.05, 0.05, 0.05]}
    check(compare(expected, {"digests": ["b"], "gt": [0.101, 0.1, 0.1, 0.05, 0.05, 0.051]}) == "close",
          "1% off the mean is close")
    check("gt mean R" in compare(expected, {"digests": ["b"], "gt": [0.2, 0.1, 0.1, 0.05, 0.05, 0.05]}),
          "double the mean differs, naming the channel")


def test_tiny_render(work, blender):
    out = os.path.join(work, "render")
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, os.path.join(SCENEGEN, "make_dataset.py"), "--out", out, "--seeds", "3",
           "--res", "16", "--stacks", "1", "--gt-spp", "4", "--frames", "1", "--gt-count", "1",
           "--blender", blender, "--export", os.path.join(work, "render.json")]
    run = subprocess.run(cmd, capture_output=True, text=True)
    check(run.returncode == 0 and "1 finished frames" in run.stderr, "one tiny frame rendered by " + blender)
    run = subprocess.run(cmd[:2] + ["--out", out, "--seeds", "3", "--res", "16", "--stacks", "1", "--gt-spp", "4",
                                    "--frames", "1", "--gt-count", "1", "--blender", blender],
                         capture_output=True, text=True)
    check(run.returncode == 0 and "0 frames to render, 1 already done" in run.stderr, "a second run renders nothing")
    plan = os.path.join(work, "plan.json")
    run = subprocess.run(cmd[:2] + ["--out", os.path.join(work, "plan"), "--seeds", "3,9", "--frames", "2",
                                    "--blender", blender, "--describe-only", plan], capture_output=True, text=True)
    counts = json.load(open(plan))["frame_counts"]["archetype"] if run.returncode == 0 else {}
    check(counts == {"exterior": 2, "metal_hdri": 2}, "--describe-only: seeds 3 and 9 are an exterior and "
          "metals under an HDRI, 2 frames each (%s)" % counts)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--work-dir", required=True)
    p.add_argument("--blender", default="")
    args = p.parse_args()
    os.makedirs(args.work_dir, exist_ok=True)
    test_splits_and_shards()
    test_commands()
    test_manifest_and_checks(args.work_dir)
    if args.blender and shutil.which(args.blender):
        test_tiny_render(args.work_dir, args.blender)
    print("%d failed" % len(FAILURES) if FAILURES else "all scenegen checks passed")
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
