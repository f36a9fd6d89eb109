#!/usr/bin/env python3
"""Denoised light passes (issue 33; docs/RESULTS.md#denoised-light-passes).

Per Cycles light pass and overall, at every sample count the data has, against
the reference's same pass (PSNR on Reinhard-tonemapped values and LDR-FLIP, as
experiments/eval_renders.py computes them):
  noisy      the pass as rendered;
  ours       `dndenoise --passes` (the default model): its "Denoised <pass>" layers;
  oidn       OIDN 2.5.1 (pyoidn, RT filter, HDR) on each pass alone, with the
             render's albedo and normal (noisy, as rendered);
  oidn_pre   the same in OIDN's prefilter mode (albedo and normal denoised
             first, then the pass with cleanAux);
plus the recombination error of each: the passes added by Cycles' rule,
against that method's own denoised beauty (ours: dndenoise's result; OIDN:
OIDN on the Combined pass in the same mode), as mean |sum - beauty| / mean
|beauty|, and for ours the largest per-pixel relative difference. The
passes a file lacks are its residual (beauty minus the rule's sum), denoised
by each method like a pass (positive and negative parts apart for OIDN).
--variants 4 also scores bench/passes_variants' guides and sharing rules at 4 spp.

Data (each set skipped when absent):
  test      Blender 3.4 test frames: testdata/dataset/test (4 and 16 spp: means of
            1 and 4 stacks; reference the mean of gt_a and gt_b) and RENDERS/b34
            (experiments/render_passes_eval.sh: 4, 16, 64 spp; reference gt_a);
  blender5  Blender 5 multi-part files: testdata/renderers/blender5_hdri (4 spp)
            and RENDERS/b5/<scene>/spp{4,16,64}.exr with ref.exr.

  python3 experiments/passes_eval.py [--bin build/bin] [--renders DIR] [--work DIR]
                                     [--variants SPP...] [--results docs/RESULTS.md]

Sequences (--shots): the light passes of animations (issue 54). Each shot
folder has experiments/render_sequences.py's layout: SHOT/spp<N>.<frame>.exr,
and SHOT/ref.<frame>.exr for the frames scored (or one SHOT/ref.exr for a
locked-off shot). Per shot and pass, over the frames with a reference:
  fbf        dndenoise --passes --temporal off (every frame alone)
  seq        dndenoise --passes (the default: the light passes filtered over time
             with the beauty's weights, the residual closing the sum)
  seq_all    --passes-temporal all (the colour passes filtered too)
  seq_off    --passes-temporal off (every pass alone, the beauty temporal: the
             residual takes the difference)
  oidn_pre   OIDN 2.5.1's prefilter mode on each pass alone, per frame
PSNR (Reinhard) against the reference's same pass, flicker of the error
(mean over frames of mean |e_t - e_t-1|, e = R(denoised) - R(reference), R
Reinhard's x / (1 + x)) and its ratio to fbf's, the passes' recombination
error against each method's own denoised beauty, the regrade (glossy x 1.5,
recombined) against the reference regraded the same way, the method's
denoised beauty against the reference's ("beauty"), and each dndenoise
run's wall time (whole process).

  python3 experiments/passes_eval.py --shots SHOT... [--spp 4] [--window 4]
                                     [--threads N] [--work DIR] [--methods fbf seq ...]
                                     [--dndenoise-args=--temporal-trust=learned]
"""

import argparse
import glob
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from eval_renders import flip, psnr  # noqa: E402
from exrutil import read_channels, write_atomic  # noqa: E402
from make_inputs import average_stacks  # noqa: E402
from oidn_denoise import Denoiser as Oidn  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Cycles' light passes (libdenoise/src/passes/light_passes.cpp): key, layer names.
PASSES = [("diffuse_direct", ["DiffDir", "Diffuse Direct"]),
          ("diffuse_indirect", ["DiffInd", "Diffuse Indirect"]),
          ("diffuse_color", ["DiffCol", "Diffuse Color"]),
          ("glossy_direct", ["GlossDir", "Glossy Direct"]),
          ("glossy_indirect", ["GlossInd", "Glossy Indirect"]),
          ("glossy_color", ["GlossCol", "Glossy Color"]),
          ("transmission_direct", ["TransDir", "Transmission Direct"]),
          ("transmission_indirect", ["TransInd", "Transmission Indirect"]),
          ("transmission_color", ["TransCol", "Transmission Color"]),
          ("volume_direct", ["VolumeDir", "Volume Direct"]),
          ("volume_indirect", ["VolumeInd", "Volume Indirect"]),
          ("emission", ["Emit", "Emission"]),
          ("environment", ["Env", "Environment"])]
TERMS = [(["diffuse_direct", "diffuse_indirect"], "diffuse_color"),
         (["glossy_direct", "glossy_indirect"], "glossy_color"),
         (["transmission_direct", "transmission_indirect"], "transmission_color"),
         (["volume_direct", "volume_indirect"], None), (["emission"], None), (["environment"], None)]
COLORS = {c for _, c in TERMS if c}
VIEW = "ViewLayer."


def rgb(channels, layer):
    names = [f"{layer}.{c}" for c in "RGB"]
    if not all(n in channels for n in names):
        return None
    return np.nan_to_num(np.stack([channels[n].astype(np.float32) for n in names], axis=-1))


def passes_of(channels):
    """{key: (H, W, 3)} of the light passes present, by Cycles' names, and their layer names."""
    found, layers = {}, {}
    for key, names in PASSES:
        for name in names:
            image = rgb(channels, VIEW + name)
            if image is not None:
                found[key], layers[key] = image, name
                break
    return found, layers


def usable_terms(found):
    terms = []
    for lights, color in TERMS:
        present = [k for k in lights if k in found]
        if present and (color is None or color in found):
            terms.append((present, color))
    return terms


def recombine(terms, passes, residual=None):
    total = 0.0
    for lights, color in terms:
        term = sum(passes[k] for k in lights)
        total = total + (term * passes[color] if color else term)
    return total + (residual if residual is not None else 0.0)


def regraded(passes, gain=1.5):
    return {k: v * gain if k.startswith("glossy_") and k != "glossy_color" else v for k, v in passes.items()}


def load(path):
    channels, _ = read_channels(path)
    beauty = rgb(channels, VIEW + "Combined")
    albedo = rgb(channels, VIEW + "Denoising Albedo").clip(0, 1)
    normal = np.stack([channels[f"{VIEW}Denoising Normal.{c}"].astype(np.float32) for c in "XYZ"],
                      -1).clip(-1, 1)
    found, layers = passes_of(channels)
    return channels, beauty, albedo, normal, found, layers


def cases(renders, work):
    """(set, name, spp, input path, reference path or (gt paths))."""
    out = []
    stacks = sorted(glob.glob(os.path.join(ROOT, "testdata/dataset/test/scene_*/frame_*")))
    stacks += sorted(glob.glob(os.path.join(renders, "b34/scene_*/frame_*")))
    for frame_dir in stacks:
        if not os.path.exists(os.path.join(frame_dir, "meta.json")):
            continue
        meta = json.load(open(os.path.join(frame_dir, "meta.json")))
        gts = [p for p in (os.path.join(frame_dir, f"gt_{t}.exr") for t in "ab") if os.path.exists(p)]
        name = "/".join(frame_dir.split("/")[-2:])
        for spp in (4, 16, 64):
            if spp // int(meta["spp"]) > int(meta["stacks"]):
                continue
            path = os.path.join(work, "inputs", name.replace("/", "_") + f"_spp{spp}.exr")
            if not os.path.exists(path):
                channels, header = average_stacks(frame_dir, spp)
                write_atomic(path, channels, header)
            out.append(("test", name, spp, path, gts))
    fixture = os.path.join(ROOT, "testdata/renderers/blender5_hdri_4spp.exr")
    out.append(("blender5", "hdri_fixture", 4, fixture, [fixture.replace("_4spp", "_ref")]))
    for scene_dir in sorted(glob.glob(os.path.join(renders, "b5/*"))):
        ref = os.path.join(scene_dir, "ref.exr")
        for spp in (4, 16, 64):
            path = os.path.join(scene_dir, f"spp{spp}.exr")
            if os.path.exists(path) and os.path.exists(ref):
                out.append(("blender5", os.path.basename(scene_dir), spp, path, [ref]))
    # Every set's 4 spp first, then 16, then 64: a run cut short still covers each set.
    return sorted(out, key=lambda case: (case[2], case[0] != "test"))


def oidn_signed(oidn, image, albedo, normal, prefilter):
    pos = oidn.run(np.ascontiguousarray(image.clip(min=0)), albedo, normal, prefilter=prefilter)
    neg = oidn.run(np.ascontiguousarray((-image).clip(min=0)), albedo, normal, prefilter=prefilter)
    return pos - neg


def oidn_passes(oidn, found, residual, beauty, albedo, normal, prefilter):
    out = {k: oidn.run(np.ascontiguousarray(v.clip(min=0)), albedo, normal, prefilter=prefilter)
           for k, v in found.items()}
    out["residual"] = oidn_signed(oidn, residual, albedo, normal, prefilter)
    whole = oidn.run(np.ascontiguousarray(beauty.clip(min=0)), albedo, normal, prefilter=prefilter)
    return out, whole


def run_ours(args, path, out):
    os.makedirs(os.path.dirname(out), exist_ok=True)
    if not os.path.exists(out):
        cmd = [os.path.join(args.bin, "dndenoise"), "--passes", "-v", path, "-o", out]
        start = time.time()
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            sys.exit(f"passes_eval: {' '.join(cmd)} failed: {done.stderr.strip()}")
        print(f"  dndenoise --passes {os.path.basename(path)}: {time.time() - start:.1f} s", flush=True)
    channels, _ = read_channels(out)
    beauty = rgb(channels, VIEW + "Denoised")
    passes = {}
    for key, names in PASSES + [("residual", ["Residual"])]:
        for name in names:
            image = rgb(channels, f"{VIEW}Denoised {name}")
            if image is not None:
                passes[key] = image
    return passes, beauty


def run_variants(args, path, folder):
    os.makedirs(folder, exist_ok=True)
    if len(glob.glob(os.path.join(folder, "*.exr"))) < 12:  # 3 guides x 4 sharing rules
        subprocess.run([os.path.join(args.bin, "passes_variants"), "--model",
                        os.path.join(ROOT, "models/default.dnm"), path, folder], check=True,
                       capture_output=True)
    variants = {}
    for file in sorted(glob.glob(os.path.join(folder, "*.exr"))):
        channels, _ = read_channels(file)
        keys = {n.rsplit(".", 1)[0] for n in channels}
        variants["v:" + os.path.basename(file)[:-4]] = (
            {k: rgb(channels, k) for k in keys if k != "beauty"}, rgb(channels, "beauty"))
    return variants


def rel_l1(a, b):
    return float(np.abs(a - b).mean() / max(np.abs(b).mean(), 1e-12))


def max_rel(a, b, floor=1e-3):
    return float((np.abs(a - b) / np.maximum(np.abs(b), floor)).max())


def evaluate(args, rows_path):
    oidn = Oidn("default", 0)
    rows = []
    for set_name, name, spp, path, refs in cases(args.renders, args.work):
        print(f"{set_name} {name} {spp} spp", flush=True)
        _, beauty, albedo, normal, found, layers = load(path)
        ref_found = [passes_of(read_channels(r)[0])[0] for r in refs]
        ref_beauty = np.mean([load(r)[1] for r in refs], axis=0)
        reference = {k: np.mean([rf[k] for rf in ref_found], axis=0) for k in found}
        terms = usable_terms(found)
        used = [k for lights, color in terms for k in lights + ([color] if color else [])]
        residual = beauty - recombine(terms, found)
        reference["residual"] = ref_beauty - recombine(terms, reference)
        methods = {"noisy": ({**found, "residual": residual}, beauty)}
        tag = f"{set_name}_{name.replace('/', '_')}_spp{spp}"
        methods["ours"] = run_ours(args, path, os.path.join(args.work, "ours", tag + ".exr"))
        methods["oidn"] = oidn_passes(oidn, found, residual, beauty, albedo, normal, False)
        methods["oidn_pre"] = oidn_passes(oidn, found, residual, beauty, albedo, normal, True)
        if args.variants and spp in args.variants:
            methods.update(run_variants(args, path, os.path.join(args.work, "variants", tag)))
        for method, (passes, whole) in methods.items():
            recombined = recombine(terms, passes, passes.get("residual"))
            row = {"set": set_name, "frame": name, "spp": spp, "method": method,
                   "rel_l1": rel_l1(recombined, whole), "max_rel": max_rel(recombined, whole),
                   "passes": {}}
            for key in used + ["residual"]:
                if not np.any(reference[key]) and not np.any(found.get(key, residual)):
                    continue  # black in the render and the reference: nothing to score
                row["passes"][key] = [psnr(reference[key], passes[key]), flip(reference[key], passes[key])]
            row["passes"]["recombined"] = [psnr(ref_beauty, recombined), flip(ref_beauty, recombined)]
            # The compositing round trip: glossy light 50 % brighter, passes added back up.
            graded = recombine(terms, regraded(passes), passes.get("residual"))
            graded_ref = recombine(terms, regraded(reference), reference["residual"])
            row["passes"]["regraded"] = [psnr(graded_ref, graded), flip(graded_ref, graded)]
            row["layers"] = layers
            rows.append(row)
        with open(rows_path + ".tmp", "w") as f:  # after every frame: a run cut short keeps its rows
            json.dump(rows, f, indent=1)
        os.replace(rows_path + ".tmp", rows_path)
    return rows


def table(rows, methods):
    """Markdown: per set and spp, each pass's mean PSNR / FLIP per method."""
    lines = []
    groups = sorted({(r["set"], r["spp"]) for r in rows})
    for set_name, spp in groups:
        group = [r for r in rows if r["set"] == set_name and r["spp"] == spp]
        frames = sorted({r["frame"] for r in group})
        lines += [f"#### {set_name}, {spp} spp ({len(frames)} frames)", "",
                  "| pass | frames | " + " | ".join(f"{m} PSNR / FLIP" for m in methods) +
                  " | ours - oidn_pre dB |", "|---" * (len(methods) + 3) + "|"]
        keys = []
        for r in group:
            keys += [k for k in r["passes"] if k not in keys]
        last = ["residual", "recombined", "regraded"]
        keys = [k for k in keys if k not in last] + last
        for key in keys:
            cells, means = [], {}
            count = 0
            for m in methods:
                vals = [r["passes"][key] for r in group if r["method"] == m and key in r["passes"]]
                count = max(count, len(vals))
                if vals:
                    means[m] = np.mean(vals, axis=0)
                    cells.append(f"{means[m][0]:.2f} / {means[m][1]:.4f}")
                else:
                    cells.append("-")
            gain = "-"
            if "ours" in means and "oidn_pre" in means:
                d = means["ours"][0] - means["oidn_pre"][0]
                gain = "0.00" if abs(d) < 0.005 else f"{d:+.2f}"
            label = {"recombined": "**recombined** (vs. the reference's Combined)",
                     "regraded": "**regraded** (glossy x1.5, recombined, vs. the reference's same)"
                     }.get(key, key)
            lines.append(f"| {label} | {count} | " + " | ".join(cells) + f" | {gain} |")
        lines.append("")
        rec = []
        for m in methods:
            vals = [r for r in group if r["method"] == m]
            if vals and m != "noisy":
                rec.append(f"{m} {np.mean([r['rel_l1'] for r in vals]):.2e} mean / "
                           f"{max(r['max_rel'] for r in vals):.2e} max")
        lines += ["Recombination error (the rule's sum against the method's own denoised beauty, "
                  "relative): " + "; ".join(rec) + ".", ""]
    return lines


SEQUENCE_METHODS = {"fbf": ["--temporal", "off"], "seq": [], "seq_all": ["--passes-temporal", "all"],
                    "seq_off": ["--passes-temporal", "off"]}


def reinhard(image):
    image = np.clip(image, 0, None)
    return image / (1 + image)


def shot_frames(shot, spp):
    """(every frame number rendered at spp, {scored frame: its reference path})."""
    frames = sorted(int(f.split(".")[-2]) for f in glob.glob(os.path.join(shot, f"spp{spp}.*.exr")))
    shared = os.path.join(shot, "ref.exr")
    refs = {n: shared if os.path.exists(shared) else os.path.join(shot, f"ref.{n:04d}.exr") for n in frames}
    return frames, {n: r for n, r in refs.items() if os.path.exists(r)}


def run_sequence(args, shot, spp, method, out_dir):
    """dndenoise --passes over the shot's frames in one process; its wall time (None: reused)."""
    os.makedirs(out_dir, exist_ok=True)
    frames, _ = shot_frames(shot, spp)
    if all(os.path.exists(os.path.join(out_dir, f"out.{n:04d}.exr")) for n in frames):
        return None
    cmd = [os.path.join(args.bin, "dndenoise"), "--passes", os.path.join(shot, f"spp{spp}.#.exr"),
           "-o", os.path.join(out_dir, "out.#.exr"), "--window", str(args.window),
           "--frames", f"{frames[0]}-{frames[-1]}"] + SEQUENCE_METHODS[method] + args.dndenoise_args
    if args.threads:
        cmd += ["--threads", str(args.threads)]
    start = time.time()
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"passes_eval: {' '.join(cmd)} failed: {done.stderr.strip()}")
    return time.time() - start


def sequence_frame(args, shot, spp, method, n, oidn):
    """(passes by key with the residual, the method's denoised beauty) of frame n."""
    path = os.path.join(shot, f"spp{spp}.{n:04d}.exr")
    if method != "oidn_pre":
        return run_ours(args, path, os.path.join(args.work, os.path.basename(shot), method, f"out.{n:04d}.exr"))
    _, beauty, albedo, normal, found, _ = load(path)
    residual = beauty - recombine(usable_terms(found), found)
    return oidn_passes(oidn, found, residual, beauty, albedo, normal, True)


def sequence_scores(frames_out, frames_ref, terms):
    """Per pass key (and "regrade", "beauty"): PSNR per frame, flicker of the error; the recombination error."""
    keys = [k for k in frames_ref[0][0] if k in frames_out[0][0]]
    scores = {}
    for key in keys + ["regrade", "beauty"]:
        outs, refs = [], []
        for (passes, beauty), (ref_passes, ref_beauty) in zip(frames_out, frames_ref):
            if key == "beauty":
                outs.append(beauty)
                refs.append(ref_beauty)
            elif key == "regrade":
                outs.append(recombine(terms, regraded(passes), passes["residual"]))
                refs.append(recombine(terms, regraded(ref_passes), ref_passes["residual"]))
            else:
                outs.append(passes[key])
                refs.append(ref_passes[key])
        errors = [reinhard(o) - reinhard(r) for o, r in zip(outs, refs)]
        flick = np.mean([np.abs(b - a).mean() for a, b in zip(errors, errors[1:])]) if len(errors) > 1 else np.nan
        scores[key] = {"psnr": [psnr(r, o) for o, r in zip(outs, refs)], "flicker": float(flick)}
    scores["recombination"] = max(rel_l1(recombine(terms, p, p["residual"]), b) for p, b in frames_out)
    return scores


def evaluate_shots(args):
    oidn = Oidn("default", args.threads)
    results = {}
    for shot in args.shots:
        name = os.path.basename(os.path.normpath(shot))
        frames, refs = shot_frames(shot, args.spp)
        if not refs:
            sys.exit(f"passes_eval: {shot}: no ref.exr or ref.<frame>.exr for the frames of spp{args.spp}")
        scored = sorted(refs)
        frames_ref = []
        for n in scored:
            _, beauty, _, _, found, _ = load(refs[n])
            found["residual"] = beauty - recombine(usable_terms(found), found)
            frames_ref.append((found, beauty))
        terms = usable_terms(frames_ref[0][0])
        results[name] = {}
        for method in args.methods:
            seconds = None
            if method in SEQUENCE_METHODS:
                seconds = run_sequence(args, shot, args.spp, method, os.path.join(args.work, name, method))
            outs = [sequence_frame(args, shot, args.spp, method, n, oidn) for n in scored]
            results[name][method] = sequence_scores(outs, frames_ref, terms)
            results[name][method]["seconds"] = seconds
            print(f"  {name} {method} done", flush=True)
    with open(os.path.join(args.work, "sequence_results.json"), "w") as f:
        json.dump(results, f, indent=1)
    return results


def sequence_table(results):
    lines = []
    for name, methods in results.items():
        keys = [k for k in methods["fbf"] if isinstance(methods["fbf"][k], dict)]
        lines += [f"### {name}", "",
                  "| pass | " + " | ".join(f"PSNR {m}" for m in methods) + " | " +
                  " | ".join(f"flicker {m}/fbf" for m in methods if m != "fbf") + " |",
                  "|---" * (2 * len(methods)) + "|"]
        for key in keys:
            base = methods["fbf"][key]["flicker"]
            psnrs = " | ".join(f"{np.mean(methods[m][key]['psnr']):.2f}" for m in methods)
            ratios = " | ".join(f"{methods[m][key]['flicker'] / base:.2f}" if base > 0 else "-"
                                for m in methods if m != "fbf")
            lines.append(f"| {key} | {psnrs} | {ratios} |")
        lines += ["", "recombination (mean |sum - beauty| / mean |beauty|, worst frame): " +
                  ", ".join(f"{m} {methods[m]['recombination']:.1e}" for m in methods),
                  "dndenoise wall time, whole process: " +
                  ", ".join(f"{m} {methods[m]['seconds']:.1f} s" for m in methods
                            if methods[m].get("seconds")), ""]
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shots", nargs="+", help="sequence folders: the per-pass sequence mode")
    ap.add_argument("--spp", type=int, default=4, help="--shots: the sample count scored")
    ap.add_argument("--window", type=int, default=4, help="--shots: dndenoise --window")
    ap.add_argument("--threads", type=int, default=0, help="--shots: dndenoise and OIDN threads (0: all)")
    ap.add_argument("--methods", nargs="+", default=list(SEQUENCE_METHODS) + ["oidn_pre"],
                    help="--shots: the methods run (fbf first)")
    ap.add_argument("--dndenoise-args", nargs="*", default=[],
                    help="--shots: more dndenoise arguments for every run, e.g. --temporal-trust learned")
    ap.add_argument("--bin", default=os.path.join(ROOT, "build/bin"))
    ap.add_argument("--renders", default="/work/data/passes/renders")
    ap.add_argument("--work", default="/work/data/passes/eval")
    ap.add_argument("--variants", type=int, nargs="*", default=[],
                    help="also bench/passes_variants' variants at these spp (e.g. 4)")
    ap.add_argument("--results", help="write the tables into this file's passes_eval section")
    ap.add_argument("--table-only", action="store_true", help="the tables from WORK/rows.json of a run")
    args = ap.parse_args()
    if args.shots:
        os.makedirs(args.work, exist_ok=True)
        print("\n".join(sequence_table(evaluate_shots(args))))
        return
    rows_path = os.path.join(args.work, "rows.json")
    if args.table_only:
        rows = json.load(open(rows_path))
    else:
        os.makedirs(args.work, exist_ok=True)
        rows = evaluate(args, rows_path)
    methods = ["noisy", "ours", "oidn", "oidn_pre"]
    methods += sorted({r["method"] for r in rows if r["method"].startswith("v:")})
    lines = table(rows, methods)
    print("\n".join(lines))
    if args.results:
        argv = [a for a in sys.argv[1:] if a != "--table-only"]
        write_section(args.results, lines, " ".join(argv))


BEGIN, END = "<!-- passes_eval.py: begin -->", "<!-- passes_eval.py: end -->"


def write_section(path, lines, argv):
    text = open(path).read() if os.path.exists(path) else ""
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    body = [BEGIN, "## Denoised light passes", "",
            f"Generated by `python3 experiments/passes_eval.py {argv}` on "
            f"{time.strftime('%Y-%m-%d', time.gmtime())} at commit `{commit}` "
            "(renders: `experiments/render_passes_eval.sh`); `experiments/results.py` keeps this section. "
            "Sets: `test`, Blender 3.4 Cycles frames with every light pass: the committed test "
            "frames (`testdata/dataset/test`, 64x64, 4 and 16 spp, reference 2x512 spp) and the "
            "test-split seeds 2, 3 and 9 of scenegen at 128x128 (4/16/64 spp as means of 4-spp "
            "stacks, reference 512 spp); `blender5`, Blender 5.0.1 multi-part files: the committed "
            "`blender5_hdri` crop (64x64, 4 spp) and the `hdri`, `cornell` and `product` scenes of "
            "`render_blender5.py --all-light-passes` at 128x128 (reference 512 spp); the `hdri` "
            "crop lacks Emission, Environment and Volume, so its residual holds them. "
            "Methods: `noisy`, the pass as rendered; `ours`, `dndenoise --passes` (the default "
            "model); `oidn`, OIDN 2.5.1 (pyoidn) on each pass alone with the render's albedo and "
            "normal; `oidn_pre`, the same in OIDN's prefilter mode. PSNR (Reinhard) and LDR-FLIP "
            "against the reference's same pass, means over the frames where the pass is not black "
            "in both. Our light passes are OIDN's prefilter mode on the pass alone (this library's "
            "port of its networks), our colour passes OIDN's albedo network; the residual (the "
            "beauty minus the rule's sum of the passes) is scored against the reference's, which is "
            "about 0: ours holds, by design, the denoised beauty's difference from the sum of the "
            "passes denoised apart, so that the passes recombine to the denoised beauty (rows "
            "`recombined`: the rule's sum against the reference's Combined; `regraded`: the glossy "
            "light passes x1.5, then recombined, against the reference regraded the same way; the "
            "recombination error: the rule's sum against the method's own denoised beauty, ours "
            "`dndenoise`'s, OIDN's OIDN on the Combined pass in the same mode).", ""]
    body += lines + [END]
    if BEGIN in text:
        text = text[:text.index(BEGIN)] + "\n".join(body) + text[text.index(END) + len(END):]
    else:
        text = text.rstrip("\n") + "\n\n" + "\n".join(body) + "\n"
    with open(path + ".tmp", "w") as f:
        f.write(text)
    os.replace(path + ".tmp", path)


if __name__ == "__main__":
    sys.exit(main())
