#!/usr/bin/env python3
"""dnmetrics as a user meets it: outputs, exit codes and every bad-input case
(one line on stderr naming the file, non-zero exit, no output file)."""
import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from exr_numpy import write_rgb  # noqa: E402
from cli_checks import check, expect_error, run, summary  # noqa: E402






def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--work-dir", required=True)
    args = ap.parse_args()
    tool, w = args.dnmetrics, args.work_dir
    shutil.rmtree(w, ignore_errors=True)
    os.makedirs(os.path.join(w, "ref"))
    os.makedirs(os.path.join(w, "test"))
    p = lambda *n: os.path.join(w, *n)  # noqa: E731

    rng = np.random.default_rng(3)
    ref = (rng.random((40, 50, 3)) * 2).astype(np.float32)
    noisy = (ref * rng.gamma(4.0, 0.25, ref.shape)).astype(np.float32)
    write_rgb(p("ref.exr"), ref)
    write_rgb(p("noisy.exr"), noisy)
    write_rgb(p("same.exr"), ref)
    write_rgb(p("small.exr"), ref[:20])
    bad = noisy.copy()
    bad[3, 4, 0], bad[5, 6, 1] = np.nan, np.inf
    write_rgb(p("nan.exr"), bad)
    with open(p("text.exr"), "w") as f:
        f.write("this is not an image\n")
    data = open(p("noisy.exr"), "rb").read()
    with open(p("cut.exr"), "wb") as f:
        f.write(data[: len(data) // 2])
    for name, img in (("a.exr", ref), ("b.exr", ref * 1.1)):
        write_rgb(p("ref", name), ref)
        write_rgb(p("test", name), img)

    out = run([tool, "--format", "json", p("ref.exr"), p("noisy.exr"), p("same.exr")])
    check("json: exit 0", out.returncode == 0, out.stderr)
    doc = json.loads(out.stdout)
    keys = {"l1", "mse", "relmse", "psnr", "ssim", "smape", "flip", "hdrflip"}
    check("json: every metric per file and mean", keys <= set(doc["results"][0]) and keys <= set(doc["mean"]))
    check("json: identical image scores 0 error", doc["results"][1]["l1"] == 0 and doc["results"][1]["flip"] == 0)
    check("json: mean is the mean", abs(doc["mean"]["l1"] - doc["results"][0]["l1"] / 2) < 1e-6)

    out = run([tool, "--format", "csv", "--metrics", "l1,psnr", p("ref.exr"), p("noisy.exr")])
    rows = out.stdout.strip().splitlines()
    check("csv: header and one row", rows[0] == "file,l1,psnr" and len(rows) == 2, out.stdout)

    out = run([tool, p("ref"), p("test")])
    check("folder mode: table with mean and std", out.returncode == 0 and "mean" in out.stdout and "std" in out.stdout,
          out.stdout + out.stderr)

    out = run([tool, "--heatmap", p("heat.png"), p("ref.exr"), p("noisy.exr")])
    check("heatmap written", out.returncode == 0 and os.path.getsize(p("heat.png")) > 0, out.stderr)

    out = run([tool, "--maxerror", "psnr=99", p("ref.exr"), p("noisy.exr")])
    check("--maxerror psnr fails with exit 2", out.returncode == 2, out.stderr)
    out = run([tool, "--maxerror", "l1=10", "--maxerror", "psnr=1", p("ref.exr"), p("noisy.exr")])
    check("--maxerror passes with exit 0", out.returncode == 0, out.stderr)

    expect_error("missing file", [tool, p("ref.exr"), p("missing.exr")], p("missing.exr"))
    expect_error("not an image", [tool, p("ref.exr"), p("text.exr")], p("text.exr"))
    expect_error("truncated EXR", [tool, p("ref.exr"), p("cut.exr")], p("cut.exr"))
    expect_error("absent channels", [tool, "--test-channels", "diffuse.R,diffuse.G,diffuse.B",
                                           p("ref.exr"), p("noisy.exr")], "diffuse.R")
    expect_error("mismatched sizes", [tool, p("ref.exr"), p("small.exr")], p("small.exr"))
    expect_error("NaN/Inf pixels", [tool, "--heatmap", p("nanheat.png"), p("ref.exr"), p("nan.exr")],
                 p("nan.exr"), no_file=p("nanheat.png"))
    expect_error("truncated EXR with heatmap", [tool, "--heatmap", p("cutheat.png"), p("ref.exr"), p("cut.exr")],
                 p("cut.exr"), no_file=p("cutheat.png"))
    os.remove(p("test", "b.exr"))
    expect_error("folder with a missing file", [tool, p("ref"), p("test")], "b.exr")

    out = run([tool, "--nonfinite", "zero", "--format", "json", p("ref.exr"), p("nan.exr")])
    check("--nonfinite zero counts and reports", out.returncode == 0 and "2 NaN/Inf" in out.stderr, out.stderr)

    check_fvvdp(tool, p, ref, noisy)
    return summary()


# Stands in for an interpreter with pyfvvdp: reads the frames dnmetrics wrote
# and prints 10 - mean |test - ref| per pair, or over all frames for a video
# (args: the scoring script, the folder, the display, the frame rate).
FAKE_FVVDP = """#!/usr/bin/env python3
import glob, os, sys
import numpy as np
folder, fps = sys.argv[2], float(sys.argv[4])
tests = sorted(glob.glob(os.path.join(folder, "test_*.npy")))
diffs = []
for t in tests:
    test, ref = np.load(t), np.load(t.replace("test_", "ref_"))
    assert test.ndim == 3 and test.shape[2] == 3 and 0 <= test.min() and test.max() <= 1
    diffs.append(np.abs(test - ref).mean())
for d in ([np.mean(diffs)] if fps > 0 else diffs):
    print(10 - d)
"""


def check_fvvdp(tool, p, ref, noisy):
    """--fvvdp: the frames handed over as displayed, a row per pair or one for a
    sequence's video, and a missing interpreter in one line; with
    DN_FVVDP_PYTHON set, pyfvvdp itself."""
    fake = p("fake_python")
    with open(fake, "w") as f:
        f.write(FAKE_FVVDP)
    os.chmod(fake, 0o755)
    out = run([tool, "--fvvdp", "--fvvdp-python", fake, "--format", "json", p("ref.exr"), p("same.exr"),
               p("noisy.exr")])
    doc = json.loads(out.stdout) if out.returncode == 0 else {"results": [{}, {}]}
    check("--fvvdp: a score per pair", out.returncode == 0 and doc["results"][0].get("fvvdp") == 10
          and 9 < doc["results"][1].get("fvvdp", 0) < 10, out.stdout + out.stderr)

    for i, image in enumerate((ref, noisy, ref * 1.2), 1):
        write_rgb(p(f"shot.{i:04d}.exr"), image)
    out = run([tool, "--fvvdp", "--fvvdp-python", fake, "--fps", "12", "--format", "csv", "--metrics", "psnr",
               p("ref.exr"), p("shot.#.exr")])
    rows = out.stdout.strip().splitlines()
    check("--fvvdp on a sequence: one video row at --fps", out.returncode == 0 and len(rows) == 6
          and rows[4].startswith('"' + p("shot.#.exr") + ' (video, 12 fps)",nan,nan,9.'), out.stdout + out.stderr)

    expect_error("--fvvdp without an interpreter",
                 [tool, "--fvvdp", "--fvvdp-python", p("no_python"), p("ref.exr"), p("noisy.exr")], "--fvvdp")
    python = os.environ.get("DN_FVVDP_PYTHON")
    if not python:
        print("skipped: pyfvvdp itself (set DN_FVVDP_PYTHON to an interpreter that has it)")
        return
    out = run([tool, "--fvvdp", "--fvvdp-python", python, "--format", "json", "--metrics", "psnr",
               p("ref.exr"), p("same.exr"), p("noisy.exr")])
    doc = json.loads(out.stdout) if out.returncode == 0 else {"results": [{}, {}]}
    check("pyfvvdp: identical images 10 JOD, noisy ones fewer",
          abs(doc["results"][0].get("fvvdp", 0) - 10) < 1e-3 and doc["results"][1].get("fvvdp", 10) < 9.9,
          out.stdout + out.stderr)


if __name__ == "__main__":
    sys.exit(main())
