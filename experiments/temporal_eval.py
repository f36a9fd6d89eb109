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
against fbf; wall time of the dndenoise runs), then a summary per scene
(filter and temporal against prefilter frame by frame, FLIP, flicker against
prefilter's, the worst frame against fbf) and the mean over the scenes, and writes
OUT/results.json (every frame's scores). Existing outputs are reused unless --force.

Scored frames: every frame has a reference (ref.<frame>.exr), or one shared
ref.exr serves all; where only some frames have one (the production set,
experiments/shots/shots_1080.py), those frames are scored, and the flicker of
a frame only where the frame before it is scored too. --per-frame prints each
scored frame's PSNR.

--ref-noise pair takes the references' own noise out of PSNR: each scored frame
has a second reference of another seed (ref2.<frame>.exr, or ref2.exr), and the
squared error of a result T against the clean image C is estimated as
  MSE(T, C) ~ (MSE(T, ref) + MSE(T, ref2)) / 2 - MSE(ref, ref2) / 2
(each reference is C plus its own zero-mean noise n, independent of T and of
the other's: E MSE(T, ref) = MSE(T, C) + E|n|^2 and E MSE(ref, ref2) = 2 E|n|^2),
all in the Reinhard space of dnmetrics' PSNR (MSE = 10^(-PSNR/10)); PSNR is then
-10 log10 of that estimate. FLIP and flicker are the means of the scores
against the two references, not corrected (noise in the reference raises both
for every method alike); the summary gives the flicker the references' noise
alone adds, the pair's flicker / sqrt 2 as a share of prefilter's (about what a
perfect result scores on consecutive scored frames; 0 with a shared reference,
whose noise cancels).
"""

import argparse
import glob
import json
import math
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


def number(path):
    return int(path[-8:-4])


def reference(folder, name="ref"):
    """One shared NAME.exr, or the pattern NAME.#.exr."""
    shared = os.path.join(folder, name + ".exr")
    return shared if os.path.exists(shared) else os.path.join(folder, name + ".#.exr")


def scored_frames(folder, spp):
    """The frames with a reference: all of them with a shared ref.exr."""
    frames = [number(p) for p in frames_of(folder, spp)]
    if os.path.exists(os.path.join(folder, "ref.exr")):
        return frames
    return [f for f in frames if os.path.exists(os.path.join(folder, f"ref.{f:04d}.exr"))]


def mse_of(psnr):
    return 10 ** (-psnr / 10)


def psnr_of(mse):
    return -10 * math.log10(mse) if mse > 0 else math.inf


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
        if args.trust:
            cmd += ["--trust", args.trust]
        return run(cmd, log=os.path.join(out, method + ".log"))[0]
    if done and not args.force and len(done) == len(frames):
        return None
    if method in ("oidn", "prefilter"):
        cmd = [sys.executable, os.path.join(HERE, "oidn_denoise.py"), *frames, "-o", target + "/"] + threads
        return run(cmd + (["--prefilter"] if method == "prefilter" else []))[0]
    mode = "off" if method == "fbf" else "on"
    cmd = [args.dndenoise, "--model", args.model, pattern, "-o", os.path.join(target, f"spp{spp}.#.exr"),
           "--rgb-only", "--float", "--temporal", mode, "--window", str(args.window), "-v",
           "--frames", f"1-{last}"] + threads + (args.dndenoise_args if method == "temporal" else [])
    return run(cmd, log=os.path.join(out, method + ".log"))[0]


def runs(frames):
    """The frames in stretches of consecutive numbers: [3, 4, 7, 8] -> [[3, 4], [7, 8]]."""
    stretches = []
    for f in frames:
        if stretches and f == stretches[-1][-1] + 1:
            stretches[-1].append(f)
        else:
            stretches.append([f])
    return stretches


def linked(folder, name, frames, links):
    """Patterns for folder/name.<frame>.exr on the given frames: the folder's own when
    it holds just those and they follow each other, else one folder of links per
    stretch of consecutive frames (a dnmetrics sequence has no gaps)."""
    present = sorted(number(p) for p in glob.glob(os.path.join(folder, f"{name}.[0-9][0-9][0-9][0-9].exr")))
    if present == frames and len(runs(frames)) == 1:
        return [os.path.join(folder, f"{name}.#.exr")]
    patterns = []
    for stretch in runs(frames):
        target = os.path.join(links, f"{stretch[0]:04d}")
        os.makedirs(target, exist_ok=True)
        for f in stretch:
            link = os.path.join(target, f"{name}.{f:04d}.exr")
            if not os.path.lexists(link):
                os.symlink(os.path.abspath(os.path.join(folder, f"{name}.{f:04d}.exr")), link)
        patterns.append(os.path.join(target, f"{name}.#.exr"))
    return patterns


def compare(args, ref, tests, video=False):
    """dnmetrics over sequences (patterns, each without gaps): {frame: row}; the
    flicker of a frame only where the frame before it was compared too. With video
    (one pattern), also the FovVideoVDP JOD."""
    by_frame, jod = {}, None
    for test in tests:
        cmd = [args.dnmetrics, ref, test, "--metrics", "psnr,flip", "--format", "json"]
        if video:
            cmd += ["--fvvdp", "--fvvdp-python", args.fvvdp_python, "--fps", "24"]
        rows = json.loads(run(cmd)[1])["results"]
        jod = rows.pop()["fvvdp"] if video else None  # the sequence's own row, last
        by_frame.update({number(r["file"]): r for r in rows})
    for f, r in by_frame.items():
        for key in ("psnr", "flip", "flicker"):  # JSON has "inf" and "nan" as strings
            if isinstance(r.get(key), str):
                r[key] = float(r[key])
        if f - 1 not in by_frame or r.get("flicker") is None or math.isnan(r["flicker"]):
            r["flicker"] = None
    return by_frame, jod


def reference_noise(args, scene, frames):
    """Per scored frame: the Reinhard MSE between ref and ref2 (another seed) and
    the flicker of that difference (None without a previous scored frame; 0 for a
    shared reference, whose noise is the same in every frame and cancels)."""
    folder = os.path.join(args.data, scene)
    first, second = reference(folder), reference(folder, "ref2")
    if not os.path.exists(second if "#" not in second else second.replace("#", f"{frames[0]:04d}")):
        sys.exit(f"temporal_eval: --ref-noise pair: {scene} has no ref2 (a second reference of another seed)")
    if "#" not in first:  # one shared pair
        row = json.loads(run([args.dnmetrics, first, second, "--metrics", "psnr", "--format", "json"])[1])["results"][0]
        return {f: {"mse": mse_of(row["psnr"]), "flicker": 0.0 if f - 1 in frames else None} for f in frames}
    rows, _ = compare(args, first, linked(folder, "ref2", frames, os.path.join(args.out, scene, "ref2")))
    missing = [f for f in frames if f not in rows]
    if missing:
        sys.exit(f"temporal_eval: --ref-noise pair: {scene} has no ref2 for frames {missing}")
    return {f: {"mse": mse_of(rows[f]["psnr"]), "flicker": rows[f]["flicker"]} for f in frames}


def score(args, scene, spp, method, out, frames, noise):
    """Per scored frame PSNR, FLIP and flicker ({frame: value}), and with --fvvdp-python
    the frames' FovVideoVDP as one 24 fps video (None without). With noise (per
    frame, reference_noise) PSNR has the references' noise taken out (docstring)."""
    folder = os.path.join(args.data, scene)
    tests = linked(os.path.join(out, method), f"spp{spp}", frames, os.path.join(out, "scored", method))
    video = bool(args.fvvdp_python) and len(tests) == 1
    rows, jod = compare(args, reference(folder), tests, video)
    result = {"frames": frames, "fvvdp": jod,
              "psnr": {f: rows[f]["psnr"] for f in frames}, "flip": {f: rows[f]["flip"] for f in frames},
              "flicker": {f: rows[f]["flicker"] for f in frames if rows[f]["flicker"] is not None}}
    if noise:
        second, _ = compare(args, reference(folder, "ref2"), tests)
        result["psnr_against_ref"] = result["psnr"]
        result["psnr"] = {}
        for f in frames:
            corrected = (mse_of(rows[f]["psnr"]) + mse_of(second[f]["psnr"])) / 2 - noise[f]["mse"] / 2
            if corrected <= 0:  # within the references' noise: not measurable with them
                print(f"temporal_eval: {scene} spp{spp} {method} frame {f}: the error is below the references' "
                      "noise; PSNR not measured (nan)", file=sys.stderr)
            result["psnr"][f] = psnr_of(corrected) if corrected > 0 else math.nan
        result["flip"] = {f: (rows[f]["flip"] + second[f]["flip"]) / 2 for f in frames}
        result["flicker"] = {f: (v + second[f]["flicker"]) / 2 for f, v in result["flicker"].items()}
    return result


def history_shares(log):
    with open(log) as f:
        return [float(m) for m in re.findall(r"(\d+)% from history", f.read())]


def mean(values):
    values = list(values.values()) if isinstance(values, dict) else list(values)
    return sum(values) / len(values) if values else math.nan


def summary_row(scores, noise):
    """temporal (and filter) against prefilter and fbf, frame by frame, on one scene at one spp."""
    t, p, fbf = scores["temporal"], scores["prefilter"], scores["fbf"]
    frames = t["frames"]
    pair = [noise[f]["flicker"] for f in frames if noise and noise[f]["flicker"] is not None]
    return {"prefilter_psnr": mean(p["psnr"]),
            "gain_db": mean([t["psnr"][f] - p["psnr"][f] for f in frames]),
            "filter_gain_db": mean([scores["filter"]["psnr"][f] - p["psnr"][f] for f in frames]),
            "flip": mean(t["flip"]), "flip_prefilter": mean(p["flip"]),
            "flicker_ratio": mean(t["flicker"]) / mean(p["flicker"]) if t["flicker"] else math.nan,
            "worst_vs_fbf_db": min(t["psnr"][f] - fbf["psnr"][f] for f in frames),
            "worst_frame": min(frames, key=lambda f: t["psnr"][f] - fbf["psnr"][f]),
            "ref_pair_psnr": psnr_of(mean([noise[f]["mse"] for f in frames])) if noise else None,
            "flicker_floor_ratio": (mean(pair) / math.sqrt(2) if pair else 0.0) / mean(p["flicker"])
                                   if noise and p["flicker"] else None}


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
    ap.add_argument("--trust", default="",
                    help="the filter alone with this learned trust (dntrain trust's output); the "
                         "temporal default takes the one --model carries, if any")
    ap.add_argument("--dndenoise-args", nargs="*", default=[],
                    help="more dndenoise arguments for the temporal default, e.g. --temporal-trust=learned")
    ap.add_argument("--scenes", nargs="+", default=["still", "object", "pan", "light"])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--window", type=int, default=4)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--force", action="store_true")
    ap.add_argument("--ref-noise", choices=("none", "pair"), default="none",
                    help="pair: take the references' own noise out of PSNR, from ref2 (docstring)")
    ap.add_argument("--per-frame", action="store_true", help="also print each scored frame's PSNR")
    args = ap.parse_args()

    results = {}
    summary = {}
    video = " FovVideoVDP JOD |" if args.fvvdp_python else ""
    print("| scene | spp | method | PSNR dB | FLIP | flicker |" + video + " note |")
    print("|---|---|---|---|---|---|---|" + ("---|" if video else ""))
    per_frame = []
    for scene in args.scenes:
        folder = os.path.join(args.data, scene)
        for spp in args.spp:
            out = os.path.join(args.out, scene, f"spp{spp}")
            os.makedirs(out, exist_ok=True)
            frames = scored_frames(folder, spp)
            if not frames:
                sys.exit(f"temporal_eval: {scene}: no frame of spp{spp} has a reference")
            noise = reference_noise(args, scene, frames) if args.ref_noise == "pair" else None
            methods = list(METHODS)
            times = {m: denoise(args, scene, spp, m, out) for m in methods}
            scores = {m: score(args, scene, spp, m, out, frames, noise) for m in methods}
            worst = {m: min(scores[m]["psnr"][f] - scores["fbf"]["psnr"][f] for f in frames) for m in methods}
            shares = {m: history_shares(os.path.join(out, m + ".log")) for m in methods
                      if m not in ("fbf", "oidn", "prefilter")}
            summary[f"{scene}/spp{spp}"] = summary_row(scores, noise)
            results[f"{scene}/spp{spp}"] = {"scores": scores, "seconds": times, "reference_noise": noise,
                                           "worst_frame_delta_db": worst, "history_percent": shares,
                                           "summary": summary[f"{scene}/spp{spp}"]}
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
            for f in frames:
                per_frame.append(f"| {scene} | {spp} | {f} | " + " | ".join(f"{scores[m]['psnr'][f]:.2f}" for m in methods)
                                 + (f" | {psnr_of(noise[f]['mse']):.2f}" if noise else "") + " |")
    if args.per_frame:
        pair = args.ref_noise == "pair"
        print("\nPSNR per scored frame, dB" + (" (references' noise taken out)" if pair else "") + ":\n")
        print("| scene | spp | frame | " + " | ".join(METHODS) + (" | ref vs ref2 |" if pair else " |"))
        print("|---|---|---|" + "---|" * (len(METHODS) + pair))
        print("\n".join(per_frame))
    print("\nAgainst OIDN's prefilter mode frame by frame (gains: mean over the scored frames of the "
          "PSNR difference, dB); the worst frame: temporal against fbf; flicker as a share of OIDN-pre's:\n")
    print("| shot | spp | frames | OIDN-pre PSNR | filter | temporal (default) | worst frame vs fbf | "
          "FLIP pre / temporal | flicker vs OIDN-pre | ref vs ref2 dB | of which the references' noise |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for spp in args.spp:
        rows = [summary[f"{scene}/spp{spp}"] for scene in args.scenes]
        for scene, r in zip(args.scenes, rows):
            frames = results[f"{scene}/spp{spp}"]["scores"]["temporal"]["frames"]
            span = f"{frames[0]}-{frames[-1]}" if frames == list(range(frames[0], frames[-1] + 1)) else \
                ",".join(map(str, frames))
            pair = f"{r['ref_pair_psnr']:.2f}" if r["ref_pair_psnr"] is not None else "-"
            floor = f"{100 * r['flicker_floor_ratio']:.0f} %" if r["flicker_floor_ratio"] is not None else "-"
            print(f"| {scene} | {spp} | {span} | {r['prefilter_psnr']:.2f} | {r['filter_gain_db']:+.2f} | "
                  f"{r['gain_db']:+.2f} | {r['worst_vs_fbf_db']:+.2f} (frame {r['worst_frame']}) | "
                  f"{r['flip_prefilter']:.4f} / {r['flip']:.4f} | {100 * r['flicker_ratio']:.0f} % | {pair} | {floor} |")
        print(f"| **mean** | {spp} | | | {mean([r['filter_gain_db'] for r in rows]):+.2f} | "
              f"**{mean([r['gain_db'] for r in rows]):+.2f}** | {min(r['worst_vs_fbf_db'] for r in rows):+.2f} (worst) | "
              f"{mean([r['flip_prefilter'] for r in rows]):.4f} / {mean([r['flip'] for r in rows]):.4f} | "
              f"{100 * mean([r['flicker_ratio'] for r in rows]):.0f} % | | |", flush=True)
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
