#!/usr/bin/env python3
"""Temporal denoising against frame-by-frame denoising, on rendered sequences.

  python3 experiments/temporal_eval.py --data /work/data/temporal --out /work/data/temporal/eval \
      --dndenoise build/bin/dndenoise --dnmetrics build/bin/dnmetrics \
      --refilter build/bin/temporal_refilter --model models/default.dnm \
      --scenes still object pan light --spp 4 16 [--window 4] [--threads 2]

For each scene folder (experiments/render_sequences.py: spp<N>.<frame>.exr, and
ref.<frame>.exr or one ref.exr for a locked-off shot; at most 8 frames) and
each --spp, denoises the sequence these ways:
  fbf        dndenoise --temporal off --float (the default model, every frame alone)
  filter     the temporal filter alone (dndenoise --temporal filter) over the fbf
             frames (bench/temporal_refilter: the same code, without denoising again)
  temporal   dndenoise --float, the default (--temporal on): the filter, and
             the noisy renders accumulated the same way and denoised again
  oidn       OIDN 2.x per frame, its usual call (experiments/oidn_denoise.py)
  prefilter  OIDN's prefilter mode per frame (oidn_denoise.py --prefilter)
and scores each with dnmetrics (PSNR, FLIP per frame, flicker of the error),
and with FovVideoVDP as a 24 fps video where --fvvdp-python names an
interpreter that has pyfvvdp (dnmetrics --fvvdp; JOD, higher is better).
Prints a Markdown table (means over frames; the worst per-frame PSNR change
against fbf; wall time of the dndenoise runs) and writes OUT/results.json.
Existing outputs are reused unless --force.
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
METHODS = ("fbf", "filter", "temporal", "oidn", "prefilter")


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
    return sorted(glob.glob(os.path.join(folder, f"spp{spp}.[0-9][0-9][0-9][0-9].exr")))[:8]


def denoise(args, scene, spp, method, out):
    folder = os.path.join(args.data, scene)
    pattern = os.path.join(folder, f"spp{spp}.#.exr")
    frames = frames_of(folder, spp)
    last = int(frames[-1][-8:-4])
    target = os.path.join(out, method)
    os.makedirs(target, exist_ok=True)
    done = glob.glob(os.path.join(target, "*.exr"))
    threads = ["--threads", str(args.threads)] if args.threads else []
    if method == "filter":  # always: it is quick, and its settings are what is measured
        cmd = [args.refilter, pattern, os.path.join(out, "fbf", f"spp{spp}.#.exr"), "-o",
               os.path.join(target, f"spp{spp}.#.exr"), "--window", str(args.window),
               "--frames", f"1-{last}"]
        if args.colour:
            cmd += ["--colour", args.colour]
        if args.light_spread:
            cmd += ["--light-spread", args.light_spread]
        return run(cmd, log=os.path.join(out, method + ".log"))[0]
    if done and not args.force and len(done) == len(frames):
        return None
    if method in ("oidn", "prefilter"):
        cmd = [sys.executable, os.path.join(HERE, "oidn_denoise.py"), *frames, "-o", target + "/"] + threads
        return run(cmd + (["--prefilter"] if method == "prefilter" else []))[0]
    mode = "off" if method == "fbf" else "on"
    cmd = [args.dndenoise, "--model", args.model, pattern, "-o", os.path.join(target, f"spp{spp}.#.exr"),
           "--rgb-only", "--float", "--temporal", mode, "--window", str(args.window), "-v",
           "--frames", f"1-{last}"] + threads
    return run(cmd, log=os.path.join(out, method + ".log"))[0]


def score(args, scene, spp, method, out):
    """Per-frame PSNR, FLIP and flicker, and with --fvvdp-python the frames'
    FovVideoVDP as one 24 fps video (None without)."""
    folder = os.path.join(args.data, scene)
    shared = os.path.join(folder, "ref.exr")
    ref = shared if os.path.exists(shared) else os.path.join(folder, "ref.#.exr")
    test = os.path.join(out, method, f"spp{spp}.#.exr")
    cmd = [args.dnmetrics, ref, test, "--metrics", "psnr,flip", "--format", "json"]
    if args.fvvdp_python:
        cmd += ["--fvvdp", "--fvvdp-python", args.fvvdp_python, "--fps", "24"]
    rows = json.loads(run(cmd)[1])["results"]
    video = rows.pop()["fvvdp"] if args.fvvdp_python else None  # the sequence's own row, last
    return {"psnr": [r["psnr"] for r in rows], "flip": [r["flip"] for r in rows],
            "flicker": [r["flicker"] for r in rows[1:]], "fvvdp": video}


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
    ap.add_argument("--refilter", required=True, help="bench/temporal_refilter")
    ap.add_argument("--model", required=True)
    ap.add_argument("--colour", default="", help="LOW,HIGH: the colour test's thresholds")
    ap.add_argument("--fvvdp-python", default="", help="an interpreter with pyfvvdp: also FovVideoVDP")
    ap.add_argument("--light-spread", default="", help="the spread above which a neighbour is left out")
    ap.add_argument("--scenes", nargs="+", default=["still", "object", "pan", "light"])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--window", type=int, default=4)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--force", action="store_true")
    args = ap.parse_args()

    results = {}
    video = " FovVideoVDP JOD |" if args.fvvdp_python else ""
    print("| scene | spp | method | PSNR dB | FLIP | flicker |" + video + " note |")
    print("|---|---|---|---|---|---|---|" + ("---|" if video else ""))
    for scene in args.scenes:
        for spp in args.spp:
            out = os.path.join(args.out, scene, f"spp{spp}")
            os.makedirs(out, exist_ok=True)
            methods = list(METHODS)
            times = {m: denoise(args, scene, spp, m, out) for m in methods}
            scores = {m: score(args, scene, spp, m, out) for m in methods}
            worst = {m: min(t - f for t, f in zip(scores[m]["psnr"], scores["fbf"]["psnr"])) for m in methods}
            shares = {m: history_shares(os.path.join(out, m + ".log")) for m in methods
                      if m not in ("fbf", "oidn", "prefilter")}
            results[f"{scene}/spp{spp}"] = {"scores": scores, "seconds": times,
                                           "worst_frame_delta_db": worst, "history_percent": shares}
            for m in methods:
                s = scores[m]
                note = ""
                if m in shares:
                    note = f"worst frame {worst[m]:+.2f} dB vs fbf; {mean(shares[m]):.0f}% from history"
                    if times.get("fbf") and times.get(m) and m != "filter":
                        note += f"; time x{times[m] / times['fbf']:.2f} of fbf"
                jod = f" {s['fvvdp']:.3f} |" if s["fvvdp"] is not None else ""
                print(f"| {scene} | {spp} | {m} | {mean(s['psnr']):.2f} | {mean(s['flip']):.4f} | "
                      f"{mean(s['flicker']):.5f} |{jod} {note} |", flush=True)
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
