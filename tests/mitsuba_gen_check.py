#!/usr/bin/env python3
"""scenegen/mitsuba_gen.py end to end on one tiny scene: layout, channels, resume, settings
guard, and that its Gaussian filter correlates the noise where its box filter does not.

  PYTHON tests/mitsuba_gen_check.py --work-dir DIR      (PYTHON: one with mitsuba, numpy, OpenEXR)

Exits 77 (skipped) when the interpreter has no mitsuba (experiments/setup_renderers.sh).
"""

import argparse
import glob
import importlib.util
import json
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GEN = os.path.join(ROOT, "scenegen", "mitsuba_gen.py")
SEED = 100001  # objects on a ground plane under an HDRI: quick and well lit
FAILURES = []
PASSED = []


def check(condition, what):
    print(("ok:   " if condition else "FAIL: ") + what)
    (PASSED if condition else FAILURES).append(what)


def generate(out, *extra):
    cmd = [sys.executable, GEN, "--out", out, "--seeds", str(SEED), "--frames", "1", "--res", "32",
           "--stacks", "4", "--gt-spp", "64", "--all-train", "--max-gt-relmse", "1e9", *extra]
    return subprocess.run(cmd, capture_output=True, text=True)


def lag1(fdir):
    import numpy as np
    sys.path.insert(0, os.path.join(ROOT, "experiments"))
    from eval_renders import lag1_autocorrelation
    from exrutil import read_color
    ref = 0.5 * (read_color(os.path.join(fdir, "gt_a.exr")) + read_color(os.path.join(fdir, "gt_b.exr")))
    return float(np.mean([lag1_autocorrelation(read_color(f), ref, False)
                          for f in sorted(glob.glob(os.path.join(fdir, "spp4_*.exr")))]))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--work-dir", required=True)
    args = p.parse_args()
    if importlib.util.find_spec("mitsuba") is None:
        print("skipped: %s has no mitsuba (experiments/setup_renderers.sh)" % sys.executable)
        return 77
    import OpenEXR
    shutil.rmtree(args.work_dir, ignore_errors=True)
    gauss, box = os.path.join(args.work_dir, "gauss"), os.path.join(args.work_dir, "box")
    fdir = os.path.join(gauss, "train", "scene_%06d" % SEED, "frame_0")

    r = generate(gauss, "--filters", "gaussian")
    check(r.returncode == 0, "renders a frame (%s)" % r.stderr.strip().splitlines()[-1:])
    with open(os.path.join(fdir, "meta.json")) as f:
        meta = json.load(f)
    files = ["spp4_%02d.exr" % i for i in range(4)] + ["gt_a.exr", "gt_b.exr"]
    check(meta["files"] == files and all(os.path.exists(os.path.join(fdir, n)) for n in files),
          "meta.json lists the 4 stacks and 2 ground truths, all present")
    check(meta["filter"] == "gaussian" and meta["pixel_filter"] == {"type": "gaussian", "stddev": 0.5},
          "meta.json records the pixel filter")
    check(not glob.glob(os.path.join(fdir, "*.tmp*")), "no temporary files left")
    header_channels = set(OpenEXR.File(os.path.join(fdir, "gt_a.exr"), separate_channels=True).channels())
    want = {"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "Denoising Normal.X", "Denoising Normal.Y",
            "Denoising Normal.Z", "normals.X", "normals.Y", "normals.Z", "depth.T"}
    check(header_channels == want, "channels: %s" % sorted(header_channels))

    stamp = os.path.getmtime(os.path.join(fdir, "spp4_01.exr"))
    r = generate(gauss, "--filters", "gaussian")
    check(r.returncode == 0 and "1 frames to render" not in r.stderr and "0 frames to render" in r.stderr,
          "a finished frame is skipped")
    os.remove(os.path.join(fdir, "meta.json"))
    os.remove(os.path.join(fdir, "spp4_02.exr"))
    r = generate(gauss, "--filters", "gaussian")
    check(r.returncode == 0 and os.path.exists(os.path.join(fdir, "spp4_02.exr"))
          and os.path.getmtime(os.path.join(fdir, "spp4_01.exr")) == stamp
          and os.path.exists(os.path.join(fdir, "meta.json")),
          "an unfinished frame renders only its missing files")
    r = generate(gauss, "--filters", "gaussian", "--gt-spp", "32")
    check(r.returncode != 0 and "other settings" in r.stderr, "other settings into the same folder: an error")

    r = generate(box, "--filters", "box")
    check(r.returncode == 0, "renders the same scene with a box filter")
    rho_gauss, rho_box = lag1(fdir), lag1(os.path.join(box, "train", "scene_%06d" % SEED, "frame_0"))
    check(rho_gauss > 0.2, "Gaussian filter: lag-1 autocorrelation of the noise %.3f > 0.2" % rho_gauss)
    check(abs(rho_box) < 0.1, "box filter: lag-1 autocorrelation of the noise %.3f within 0.1 of 0" % rho_box)

    strict = os.path.join(args.work_dir, "strict")
    rdir = os.path.join(strict, "train", "scene_%06d" % SEED, "frame_0")
    r = generate(strict, "--max-gt-relmse", "0")
    check(r.returncode == 0 and "rejected" in r.stderr and os.path.exists(os.path.join(rdir, "rejected.json"))
          and not glob.glob(os.path.join(rdir, "*.exr")) and not os.path.exists(os.path.join(rdir, "meta.json")),
          "a frame whose ground truths disagree is dropped, rejected.json says why")
    r = generate(strict, "--max-gt-relmse", "0")
    check(r.returncode == 0 and "0 frames to render" in r.stderr, "a rejected frame is not rendered again")

    print("%d passed, %d failed" % (len(PASSED), len(FAILURES)))
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
