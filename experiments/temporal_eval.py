#!/usr/bin/env python3
"""Temporal denoising against frame-by-frame denoising, on rendered sequences.

  python3 experiments/temporal_eval.py --data /work/data/temporal --out /work/data/temporal/eval \
      --dndenoise build/bin/dndenoise --dnmetrics build/bin/dnmetrics \
      --scenes still object pan light --spp 4 16 [--window 2] [--threads 2]

For each scene folder (experiments/render_sequences.py: spp<N>.<frame>.exr, and
ref.<frame>.exr or one ref.exr for a locked-off shot) and each --spp, denoises
the sequence four ways:
  fbf       dndenoise --temporal off (the default model, every frame alone)
  temporal  dndenoise --temporal on --window W
  oidn      OIDN 2.x per frame, its usual call (experiments/oidn_denoise.py)
  prefilter OIDN's prefilter mode per frame (oidn_denoise.py --prefilter)
and scores each with dnmetrics (PSNR, FLIP per frame, flicker of the error).
Prints a Markdown table (means over frames; the worst per-frame PSNR change of
temporal against fbf; wall time of the two dndenoise runs, measured back to
back in this process) and writes OUT/results.json. Existing outputs are reused
unless --force.
"""

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
METHODS = ("fbf", "temporal", "oidn", "prefilter")


def run(cmd, log=None):
    start = time.time()
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f"temporal_eval: {' '.join(cmd)} failed:\n{result.stderr}")
    if log:
        with open(log, "w") as f:
            f.write(result.stderr)
    return time.time() - start, result.stdout


def frames_of(folder, spp):
    return sorted(glob.glob(os.path.join(folder, f"spp{spp}.[0-9][0-9][0-9][0-9].exr")))


def denoise(args, scene, spp, method, out):
    folder = os.path.join(args.data, scene)
    pattern = os.path.join(folder, f"spp{spp}.#.exr")
    target = os.path.join(out, method)
    os.makedirs(target, exist_ok=True)
    done = glob.glob(os.path.join(target, "*.exr"))
    if done and not args.force and len(done) == len(frames_of(folder, spp)):
        return None
    if method in ("fbf", "temporal"):
        cmd = [args.dndenoise, pattern, "-o", os.path.join(target, f"spp{spp}.#.exr"),
               "--rgb-only", "--temporal", "off" if method == "fbf" else "on", "-v"]
        if method == "temporal":
            cmd += ["--window", str(args.window)]
        if args.threads:
            cmd += ["--threads", str(args.threads)]
        seconds, _ = run(cmd, log=os.path.join(out, method + ".log"))
        return seconds
    cmd = [sys.executable, os.path.join(HERE, "oidn_denoise.py"), *frames_of(folder, spp), "-o", target + "/"]
    if args.threads:
        cmd += ["--threads", str(args.threads)]
    if method == "prefilter":
        cmd.append("--prefilter")
    return run(cmd)[0]


def score(args, scene, spp, method, out):
    folder = os.path.join(args.data, scene)
    shared = os.path.join(folder, "ref.exr")
    ref = shared if os.path.exists(shared) else os.path.join(folder, "ref.#.exr")
    test = os.path.join(out, method, f"spp{spp}.#.exr")
    _, stdout = run([args.dnmetrics, ref, test, "--metrics", "psnr,flip", "--format", "json"])
    data = json.loads(stdout)
    return {"psnr": [r["psnr"] for r in data["results"]], "flip": [r["flip"] for r in data["results"]],
            "flicker": [r["flicker"] for r in data["results"][1:]]}


def history_shares(log):
    with open(log) as f:
        return [float(m) for m in re.findall(r"(\d+)% from history", f.read())]


def mean(values):
    return sum(values) / len(values)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--dndenoise", required=True)
    ap.add_argument("--dnmetrics", required=True)
    ap.add_argument("--scenes", nargs="+", default=["still", "object", "pan", "light"])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--window", type=int, default=2)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args()

    results = {}
    print("| scene | spp | method | PSNR dB | FLIP | flicker | note |")
    print("|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        for spp in args.spp:
            out = os.path.join(args.out, scene, f"spp{spp}")
            os.makedirs(out, exist_ok=True)
            times = {m: denoise(args, scene, spp, m, out) for m in METHODS}
            scores = {m: score(args, scene, spp, m, out) for m in METHODS}
            worst = min(t - f for t, f in zip(scores["temporal"]["psnr"], scores["fbf"]["psnr"]))
            shares = history_shares(os.path.join(out, "temporal.log"))
            results[f"{scene}/spp{spp}"] = {"scores": scores, "seconds": times,
                                           "worst_frame_delta_db": worst, "history_percent": shares}
            for m in METHODS:
                s = scores[m]
                note = ""
                if m == "temporal":
                    note = f"worst frame {worst:+.2f} dB vs fbf; {mean(shares):.0f}% from history"
                    if times["fbf"] and times["temporal"]:
                        note += f"; time x{times['temporal'] / times['fbf']:.2f} of fbf"
                print(f"| {scene} | {spp} | {m} | {mean(s['psnr']):.2f} | {mean(s['flip']):.4f} | "
                      f"{mean(s['flicker']):.5f} | {note} |", flush=True)
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
