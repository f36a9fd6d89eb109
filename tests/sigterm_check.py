#!/usr/bin/env python3
"""SIGTERM at random points of a dndenoise run (model loading, denoising,
writing): afterwards the output folder holds the finished output or nothing,
never a temporary file, and the tool exits 0 (finished first) or 143."""
import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import time

try:
    import numpy as np
    import OpenEXR  # noqa: F401  (make_tiny_dataset.py needs it)
except ImportError as e:  # CTest reports this as skipped
    print(f"skipped: {e}")
    sys.exit(77)

sys.path.insert(0, os.path.dirname(__file__))
from cli_checks import check, run, summary  # noqa: E402
from exr_numpy import read_rgb  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--work-dir", required=True)
    ap.add_argument("--runs", type=int, default=16)
    args = ap.parse_args()
    w = os.path.abspath(args.work_dir)
    shutil.rmtree(w, ignore_errors=True)
    os.makedirs(w)
    p = lambda *n: os.path.join(w, *n)  # noqa: E731
    here = os.path.dirname(os.path.abspath(__file__))
    data = p("data")
    subprocess.run([sys.executable, os.path.join(here, "make_tiny_dataset.py"), data, "--size", "256",
                    "--frames", "1", "--stacks", "1"], check=True)
    dntrain, dndenoise = os.path.join(args.bin, "dntrain"), os.path.join(args.bin, "dndenoise")
    tiny = ["--batch", "1", "--crop", "16", "--threads", "1", "--spp", "4", "--val-every", "0", "--steps", "1"]
    for cmd in ([dntrain, "base", "--data", data, "--out", p("base.dnm"), "--base-channels", "8",
                 "--res-blocks", "1"] + tiny,
                [dntrain, "control", "--data", data, "--base", p("base.dnm"), "--out", p("model.dnm")] + tiny):
        out = run(cmd)
        if out.returncode != 0:
            sys.exit(f"fixture failed: {out.stderr}")
    frame = os.path.join(data, "val", "scene_0", "frame_0", "spp4_00.exr")
    outdir = p("out")
    os.makedirs(outdir)
    output = os.path.join(outdir, "den.exr")
    cmd = [dndenoise, "--model", p("model.dnm"), "--threads", "1", "--steps", "6", "--skip", "1", "--float",
           frame, "-o", output]

    t0 = time.time()
    out = run(cmd)
    full = time.time() - t0
    check("an uninterrupted run finishes", out.returncode == 0 and os.path.exists(output), out.stderr)
    os.remove(output)

    rng = random.Random(1)
    outcomes = {"finished": 0, "stopped": 0}
    for i in range(args.runs):
        # Random points over the whole run, a third of them in its last 20 %, where it writes.
        delay = full * (rng.uniform(0.8, 1.1) if i % 3 == 0 else rng.uniform(0.0, 1.0))
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
        left = sorted(os.listdir(outdir))
        finished = left == ["den.exr"] and np.isfinite(read_rgb(output, "ViewLayer.Denoised")).all()
        if proc.returncode == 0:
            outcomes["finished"] += 1
            ok = finished
        else:
            outcomes["stopped"] += 1
            # 143: the tool's handler; -15: the signal came before main() set it up.
            # A signal after the output was renamed into place leaves it whole.
            ok = (proc.returncode == 143 and "SIGTERM" in err or proc.returncode == -15) and (
                left == [] or finished)
        check(f"SIGTERM after {delay:.2f} s: exit {proc.returncode}, left {left}", ok, err)
        for name in left:
            os.remove(os.path.join(outdir, name))
    print(f"full run {full:.2f} s; outcomes {outcomes}")
    check("some runs were stopped", outcomes["stopped"] > 0, outcomes)
    return summary()


if __name__ == "__main__":
    sys.exit(main())
