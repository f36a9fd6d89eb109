#!/usr/bin/env python3
"""Writes docs/RESULTS.md and its figures from one run of the experiment Makefile.

  report.py --plan OUT/plan.json --results docs/RESULTS.md --figures docs/results
            --bin BIN --command 'make -C experiments ...'

Everything in the report comes from the run's files: the plan (methods, models,
frames), dnmetrics' per-frame JSON, the choice files of the tuned methods, the speed
measurements and the images themselves. Sentences about wins and losses are
generated from those numbers.
"""

import argparse
import datetime
import glob
import hashlib
import json
import math
import os
import platform
import subprocess
import sys

import numpy as np
from PIL import Image

from page_sections import SECTION_BEGIN, SECTION_END, figure_tonemap
from exrutil import read_color
from metrics_io import HIGHER_IS_BETTER, case_path, load_case_metrics

METRICS = [("l1", "L1", 4), ("psnr", "PSNR (dB)", 2), ("ssim", "SSIM", 4), ("flip", "FLIP", 4),
           ("hdrflip", "HDR-FLIP", 4)]
SHORT = {"noisy": "Noisy", "oidn": "OIDN", "oidn_high": "OIDN high", "isik": "Isik",
         "regression": "Regression", "base": "Base prior", "ours": "Ours",
         "ours_nomatch": "Ours (no mean matching)", "ours_fixed": "Ours (4-spp defaults)", "ours_best": "Ours (tuned)",
         "ours_samples": "Ours (K samples)"}
OURS = ("ours", "ours_nomatch", "ours_fixed", "ours_best", "ours_samples")
FIGURE_CROP = 128
FIGURE_MIN_WIDTH = 192
# Luminance bands of the reference (linear, exposure-scaled radiance) for "where" analysis.
BANDS = [("dark", 0.0, 0.05), ("mid", 0.05, 0.5), ("bright", 0.5, math.inf)]
EDGE_QUANTILE = 0.9  # pixels above this quantile of the reference's gradient are "edges"


# ---------------------------------------------------------------- helpers

def shell_output(command, cwd=None):
    try:
        return subprocess.run(command, cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def sha256(path):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def fmt(value, digits):
    return f"{value:.{digits}f}"


def better(metric, a, b):
    """True when value a is strictly better than b for this metric."""
    return a > b if metric in HIGHER_IS_BETTER else a < b


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def clamp6(rgb):
    return np.clip(np.nan_to_num(rgb, nan=0.0, posinf=6.0, neginf=0.0), 0.0, 6.0)


# ---------------------------------------------------------------- the run's data

class Run:
    def __init__(self, plan_path):
        with open(plan_path) as f:
            self.plan = json.load(f)
        self.out = self.plan["out"]
        self.methods = self.plan["methods"]
        self.by_name = {m["name"]: m for m in self.methods}

    def cases(self, spp):
        return [(scene, frame) for scene, info in self.plan["scenes"]["test"].items()
                if spp in info["spps"] for frame in info["frames"]]

    def active(self, spp):
        return [m for m in self.methods if spp in m["spps"]]

    def metrics(self, method, spp):
        return load_case_metrics(self.out, method, "test", self.cases(spp), spp)

    def result_path(self, method, scene, frame, spp):
        kind = "input" if method == "noisy" else "res"
        if method == "noisy":
            return os.path.join(self.out, "input", "test", scene, f"{frame}_spp{spp}.exr")
        return case_path(self.out, kind, method, "test", scene, frame, spp, "exr")

    def ref_path(self, scene, frame):
        return os.path.join(self.out, "ref", "test", scene, f"{frame}.exr")

    def heatmap_path(self, method, scene, frame, spp):
        return case_path(self.out, "metrics", method, "test", scene, frame, spp, "png")

    def choice(self, method, spp):
        path = os.path.join(self.out, "choice", f"{method}_spp{spp}.json")
        if not os.path.exists(path):
            return None
        with open(path) as f:
            return json.load(f)

    def speed(self, method):
        path = os.path.join(self.out, "speed", f"{method}.json")
        if not os.path.exists(path):
            return None
        with open(path) as f:
            return json.load(f)

    def args(self, method, spp):
        path = os.path.join(self.out, "args", f"{method}_spp{spp}.args")
        with open(path) as f:
            return f.read().strip()


def mean_table(run, spp):
    """{method: {metric: mean}} over the test frames at spp."""
    table = {}
    if not run.cases(spp):
        return table
    for m in run.active(spp):
        values = run.metrics(m["name"], spp)
        table[m["name"]] = {k: float(np.mean([v[k] for v in values])) for k, _, _ in METRICS}
        table[m["name"]]["frames"] = len(values)
        table[m["name"]]["per_frame"] = values
    return table


# ---------------------------------------------------------------- "where" analysis

def region_errors(run, method, spp):
    """Per-pixel |error| sums by region and the signed luminance bias, over the test frames."""
    sums = {name: 0.0 for name, _, _ in BANDS}
    sums.update({"edges": 0.0, "flat": 0.0})
    counts = dict.fromkeys(sums, 0)
    signed, ref_total, pixels = 0.0, 0.0, 0
    for scene, frame in run.cases(spp):
        ref = clamp6(read_color(run.ref_path(scene, frame)))
        out = clamp6(read_color(run.result_path(method, scene, frame, spp)))
        error = np.abs(out - ref).mean(axis=-1)
        y = luminance(ref)
        tone = y / (1 + y)
        gy, gx = np.gradient(tone)
        gradient = np.hypot(gx, gy)
        edges = gradient > np.quantile(gradient, EDGE_QUANTILE)
        masks = {name: (y >= lo) & (y < hi) for name, lo, hi in BANDS}
        masks.update({"edges": edges, "flat": ~edges})
        for name, mask in masks.items():
            sums[name] += float(error[mask].sum())
            counts[name] += int(mask.sum())
        signed += float((luminance(out) - y).sum())
        ref_total += float(y.sum())
        pixels += y.size
    return {"sums": sums, "counts": counts, "pixels": pixels,
            "bias": signed / max(ref_total, 1e-12)}


def where_sentence(ours, base, ours_label, base_label):
    """Which regions hold the L1 gap between ours and a better baseline, from the sums."""
    gap = {k: ours["sums"][k] - base["sums"][k] for k in ours["sums"]}
    band_gap = sum(gap[name] for name, _, _ in BANDS)
    parts = []
    if band_gap > 0:
        shares = []
        for name, lo, hi in BANDS:
            share = gap[name] / band_gap
            pixel_share = ours["counts"][name] / ours["pixels"]
            limits = f"< {hi}" if lo == 0 else (f">= {lo}" if hi == math.inf else f"{lo}-{hi}")
            shares.append(f"{name} pixels (reference luminance {limits}, {pixel_share:.0%} of pixels): "
                          f"{share:.0%} of the gap")
        parts.append("; ".join(shares))
        edge_share = gap["edges"] / (gap["edges"] + gap["flat"]) if gap["edges"] + gap["flat"] > 0 else 0
        parts.append(f"edges and texture (top {1 - EDGE_QUANTILE:.0%} of reference gradients) hold "
                     f"{edge_share:.0%} of it")
    bias = (f"mean luminance bias {ours['bias']:+.1%} for {ours_label} vs "
            f"{base['bias']:+.1%} for {base_label}")
    if not parts:
        return f"the L1 gap is not positive in total; {bias}."
    return f"where the L1 gap lies: {'; '.join(parts)}; {bias}."


# ---------------------------------------------------------------- sections

def header(run, args):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    commit = shell_output(["git", "rev-parse", "HEAD"], cwd=root)
    dirty = shell_output(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root)
    dirty_text = f" (plus uncommitted changes in {len(dirty.splitlines())} tracked files)" if dirty else ""
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")
    mem = next((line.split()[1] for line in open("/proc/meminfo") if line.startswith("MemTotal")), "0")
    lines = ["# Results", "",
             "Generated by `experiments/report.py` from one run of `experiments/Makefile`; "
             "do not edit by hand: rerun the command below.", ""]
    if run.plan["note"]:
        lines += [f"> **Note on this run:** {run.plan['note']}", ""]
    lines += [
        "| | |", "|---|---|",
        f"| command | `{args.command}` |",
        f"| date | {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC |",
        f"| commit | `{commit or '?'}`{dirty_text} |",
        f"| machine | {os.cpu_count()} cores ({cpu}), {int(mem) / 2**20:.0f} GiB, {platform.system()} "
        f"{platform.release()}, load average {os.getloadavg()[0]:.1f} when the report was written |",
        f"| tools | `{args.bin}`; OIDN {oidn_version()} (pyoidn) |",
    ]
    lines += dataset_rows(run)
    lines += ["", "## Models", ""] + model_lines(run) + [""]
    return lines


def oidn_version():
    try:
        from pyoidn import version
        return version.oidn_version
    except Exception:  # missing module: reported in the skipped list
        return "(not available)"


def dataset_rows(run):
    test_dir = run.plan["splits"]["test"]
    tune_dir = run.plan["splits"]["tune"]
    manifest_path = os.path.join(os.path.dirname(test_dir), "manifest.json")
    rows = [f"| test split | `{test_dir}` |"]
    if os.path.exists(manifest_path):
        with open(manifest_path) as f:
            manifest = json.load(f)
        s = manifest.get("settings", {})
        rows.append(f"| data set | `{manifest_path}`: {s.get('res')}x{s.get('res')} px, {s.get('stacks')} stacks of "
                    f"{s.get('spp')} spp per frame, ground truth {s.get('gt_spp')} spp, scenes per split "
                    f"{manifest.get('scene_counts')}, {manifest.get('frame_count')} frames, generator "
                    f"{', '.join(manifest.get('generator_versions', []))}, {manifest.get('blender_version')} |")
    else:
        rows.append(f"| data set | no manifest.json next to the test split |")
    scenes = run.plan["scenes"]["test"]
    frames = sum(len(s["frames"]) for s in scenes.values())
    clean = sum(os.path.exists(os.path.join(s["src"], f, "gt_clean.exr")) for s in scenes.values() for f in s["frames"])
    rows.append(f"| frames used | {len(scenes)} test scenes, {frames} frames "
                f"(TEST_SCENES={run.plan['settings']['TEST_SCENES'] or 0}: 0 means all); references: "
                f"{clean} cleansed (`gt_clean.exr`), {frames - clean} the mean of `gt_a` and `gt_b` |")
    tune_scenes = run.plan["scenes"]["tune"]
    same = os.path.abspath(tune_dir) == os.path.abspath(test_dir)
    rows.append(f"| tuning split | `{tune_dir}`, {len(tune_scenes)} scenes"
                + (" (**the test split itself: no validation split was found, so tuned rows are optimistic**)"
                   if same else "") + " |")
    return rows


def model_lines(run):
    lines = ["| method | spp | model file | size | sha256 | modified |", "|---|---|---|---|---|---|"]
    for m in run.methods:
        for spp, path in sorted(m.get("models", {}).items(), key=lambda kv: int(kv[0])):
            if int(spp) not in m["spps"]:
                continue
            stat = os.stat(path)
            when = datetime.datetime.fromtimestamp(stat.st_mtime, datetime.timezone.utc)
            lines.append(f"| {m['label']} | {spp} | `{path}` | {stat.st_size / 1e6:.2f} MB | "
                         f"`{sha256(path)[:16]}` | {when:%Y-%m-%d %H:%M} |")
    if len(lines) == 2:
        lines.append("| (none: no learned model file was found) | | | | | |")
    skipped = []
    for m in run.methods:
        reasons = {}
        for spp, reason in m["skipped"].items():
            reasons.setdefault(reason, []).append(spp)
        for reason, spps in reasons.items():
            skipped.append(f"- **{m['label']}** is skipped at {', '.join(spps)} spp: {reason}.")
    if skipped:
        lines += ["", "Methods not in the tables (no rows are invented for them):", ""] + skipped
    return lines


def tables(run, means):
    lines = ["## Quality", "",
             "Means over the test frames. L1 on radiance clamped to [0, 6]; PSNR, SSIM and FLIP after "
             "the Reinhard tonemap `v / (1 + v)`; HDR-FLIP on linear radiance (all by `dnmetrics`, see "
             "docs/dnmetrics.md). Best value per column in bold.", ""]
    for spp in run.plan["spps"]:
        table = means.get(spp)
        if not table:
            lines += [f"### {spp} spp", "", f"No test frame has enough stacks for {spp} spp.", ""]
            continue
        frames = next(iter(table.values()))["frames"]
        lines += [f"### {spp} spp ({frames} frames)", "",
                  "| method | " + " | ".join(f"{label} {'↑' if key in HIGHER_IS_BETTER else '↓'}"
                                             for key, label, _ in METRICS) + " |",
                  "|---|" + "---:|" * len(METRICS)]
        best = {}
        for key, _, _ in METRICS:
            values = [row[key] for row in table.values()]
            best[key] = max(values) if key in HIGHER_IS_BETTER else min(values)
        for m in run.active(spp):
            row = table[m["name"]]
            cells = []
            for key, _, digits in METRICS:
                text = fmt(row[key], digits)
                cells.append(f"**{text}**" if fmt(best[key], digits) == text else text)
            lines.append(f"| {m['label']} | " + " | ".join(cells) + " |")
        notes = tuned_notes(run, spp) + identical_notes(run, table, spp)
        lines += [""] + notes + ([""] if notes else [])
    return lines


def identical_notes(run, table, spp):
    """Rows whose metrics agree on every frame: the methods produced the same images."""
    names, notes = [m["name"] for m in run.active(spp)], []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if table[a]["per_frame"] == table[b]["per_frame"]:
                notes.append(f"- {run.by_name[a]['label']} and {run.by_name[b]['label']} have identical "
                             "metrics on every frame.")
    return notes


def tuned_notes(run, spp):
    notes = []
    for m in run.active(spp):
        choice = run.choice(m["name"], spp)
        if not choice:
            continue
        chosen = next(c for c in choice["candidates"] if c["name"] == choice["best"])
        sweep = ", ".join(f"{c['steps']}/{c['skip']}: {c['mean'][choice['metric']]:.4g}"
                          for c in choice["candidates"])
        notes.append(f"- {m['label']}: `--steps {chosen['steps']} --skip {chosen['skip']}`, the best mean "
                     f"{choice['metric']} on the tuning split ({chosen['frames']} frames; steps/skip: "
                     f"{choice['metric']} = {sweep}).")
    return notes


def speed_section(run):
    lines = ["## Speed", "",
             "Wall-clock time of each method's command on this machine, in the same run: the median of "
             f"{run.plan['settings']['SPEED_REPEATS']} runs on a {run.plan['settings']['SPEED_SIZE']}-pixel "
             f"square input and on a {run.plan['settings']['SPEED_SMALL']}-pixel one (a test input, mirrored "
             "and tiled). Seconds per megapixel is the difference of the two over the difference in pixels, "
             "so process start and model loading (the fixed cost) are not in it; the unit of the last "
             "column is OIDN at its default quality. Tuned methods run with the settings chosen at the lowest "
             "spp; model files are named by their base name. Threads: "
             f"{run.plan['settings']['THREADS']}.", ""]
    unit = run.speed("oidn")
    rows = [(m, run.speed(m["name"])) for m in run.methods]
    rows = [(m, s) for m, s in rows if s and m["spps"]]  # skipped methods: stale timings
    if not rows:
        return lines + ["No method was timed.", ""]
    lines += ["| method | command arguments | s / megapixel | × OIDN | fixed cost (s) | load average |",
              "|---|---|---:|---:|---:|---:|"]
    for m, s in rows:
        ratio = (f"{s['seconds_per_megapixel'] / unit['seconds_per_megapixel']:.1f}"
                 if unit and unit["seconds_per_megapixel"] > 0 else "n/a")
        args = " ".join(os.path.basename(a) if a in m.get("models", {}).values() else a
                        for a in run.args(m["name"], m["spps"][0]).split())
        lines.append(f"| {m['label']} | `{args}` | {s['seconds_per_megapixel']:.3g} | {ratio} | "
                     f"{s['fixed_seconds']:.2f} | {s['load_average'][0]:.1f} → {s['load_average'][1]:.1f} |")
    load = max(max(s["load_average"]) for _, s in rows)
    if load > (os.cpu_count() or 1):
        lines += ["", f"The load average reached {load:.1f} on {os.cpu_count()} cores during timing: other "
                  "jobs shared the machine, so absolute times are inflated; ratios are rougher than usual."]
    return lines + [""]


def wins_losses(run, means):
    lines = ["## Wins and losses", "",
             "Generated from the tables above: for each of our rows, which methods do better, and where "
             "the L1 gap to the best of them lies (per-pixel |error| summed by region of the reference).", ""]
    any_ours = False
    for spp in run.plan["spps"]:
        table = means.get(spp)
        if not table:
            continue
        ours_rows = [n for n in OURS if n in table]
        if not ours_rows:
            continue
        any_ours = True
        lines.append(f"**{spp} spp.**")
        for name in ours_rows:
            label = run.by_name[name]["label"]
            others = [n for n in table if n not in OURS]
            losses, wins = [], []
            for key, metric_label, digits in METRICS:
                better_than_us = [n for n in others if better(key, table[n][key], table[name][key])]
                if better_than_us:
                    losses.append(f"{metric_label} (" + ", ".join(
                        f"{SHORT[n]} {fmt(table[n][key], digits)}" for n in better_than_us)
                        + f" vs {fmt(table[name][key], digits)})")
                else:
                    wins.append(metric_label)
            frames_lost = per_frame_losses(table, name, others)
            lines.append(f"- {label}: better than every other method on "
                         f"{', '.join(wins) if wins else 'no metric'}; "
                         + (f"loses on {'; '.join(losses)}." if losses else "loses on no metric.")
                         + (f" {frames_lost}" if frames_lost else ""))
            rival = strongest_rival(table, name, others)
            if rival:
                ours_regions = region_errors(run, name, spp)
                rival_regions = region_errors(run, rival, spp)
                lines.append(f"  Against {SHORT[rival]} (lowest L1 of the rows that beat it): "
                             + where_sentence(ours_regions, rival_regions, SHORT[name], SHORT[rival]))
        if "base" in table and "ours" in table:
            b, o = table["base"], table["ours"]
            lines.append(f"- Control Module effect (Ours vs the base prior alone): L1 {fmt(b['l1'], 4)} → "
                         f"{fmt(o['l1'], 4)}, PSNR {fmt(b['psnr'], 2)} → {fmt(o['psnr'], 2)} dB.")
        lines.append("")
    if not any_ours:
        lines += ["No model of ours was available for this run, so there is nothing of ours to compare: "
                  "the tables hold the baselines only.", ""]
    return lines


def per_frame_losses(table, name, others):
    """'L1 is worse than X on a of n frames' for every rival that wins any frame."""
    parts = []
    ours = table[name]["per_frame"]
    for n in others:
        lost = sum(1 for a, b in zip(ours, table[n]["per_frame"]) if b["l1"] < a["l1"])
        if lost:
            parts.append(f"{SHORT[n]} on {lost} of {len(ours)}")
    return f"Per frame, L1 is worse than {', '.join(parts)} frames." if parts else ""


def strongest_rival(table, name, others):
    rivals = [n for n in others if n != "noisy" and table[n]["l1"] < table[name]["l1"]]
    return min(rivals, key=lambda n: table[n]["l1"]) if rivals else None


# ---------------------------------------------------------------- figures

def crop_window(noisy, ref, size):
    """Top-left corner of the size x size window with the most noisy-input error."""
    h, w = ref.shape[:2]
    error = np.abs(noisy / (1 + noisy) - ref / (1 + ref)).mean(axis=-1)
    integral = np.pad(error, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    sums = (integral[size:, size:] - integral[:-size, size:] - integral[size:, :-size]
            + integral[:-size, :-size])
    y, x = np.unravel_index(np.argmax(sums), sums.shape)
    return int(y), int(x)


def save_png(pixels, path, scale):
    image = Image.fromarray(pixels)
    if scale > 1:
        image = image.resize((image.width * scale, image.height * scale), Image.NEAREST)
    image.save(path, optimize=True)


def figures(run, means, folder, results_path):
    for old in glob.glob(os.path.join(folder, "spp*_*.png")):
        os.remove(old)
    os.makedirs(folder, exist_ok=True)
    relative = os.path.relpath(folder, os.path.dirname(os.path.abspath(results_path)))
    lines = ["## Figures", "",
             "For each spp, the test frame where the noisy input has the highest FLIP, cropped to the "
             "window with the most noisy-input error; colour through dndenoise's default display "
             "transform (the built-in sRGB config: clamp to [0, 1], the sRGB curve; what `-o out.png` "
             "writes), enlarged without interpolation. "
             "Second row: FLIP error maps from `dnmetrics --heatmap` (magma, black = no error).", ""]
    for spp in run.plan["spps"]:
        table = means.get(spp)
        if not table or "noisy" not in table:
            continue
        cases = run.cases(spp)
        worst = int(np.argmax([v["flip"] for v in table["noisy"]["per_frame"]]))
        scene, frame = cases[worst]
        ref = clamp6(read_color(run.ref_path(scene, frame)))
        noisy = clamp6(read_color(run.result_path("noisy", scene, frame, spp)))
        size = min(FIGURE_CROP, *ref.shape[:2])
        y, x = crop_window(noisy, ref, size)
        scale = max(1, -(-FIGURE_MIN_WIDTH // size))
        window = (slice(y, y + size), slice(x, x + size))
        names, images, heats = [], [], []
        for m in run.active(spp):
            rgb = clamp6(read_color(run.result_path(m["name"], scene, frame, spp)))
            file = f"spp{spp}_{m['name']}.png"
            save_png(figure_tonemap(rgb[window]), os.path.join(folder, file), scale)
            heat = np.asarray(Image.open(run.heatmap_path(m["name"], scene, frame, spp)).convert("RGB"))
            heat_file = f"spp{spp}_{m['name']}_flip.png"
            save_png(heat[window], os.path.join(folder, heat_file), scale)
            names.append(f"{SHORT[m['name']]} (FLIP {table[m['name']]['per_frame'][worst]['flip']:.3f})")
            images.append(f"![{m['name']}]({relative}/{file})")
            heats.append(f"![{m['name']} FLIP]({relative}/{heat_file})")
        save_png(figure_tonemap(ref[window]), os.path.join(folder, f"spp{spp}_reference.png"), scale)
        names.append("Reference")
        images.append(f"![reference]({relative}/spp{spp}_reference.png)")
        heats.append("")
        lines += [f"### {spp} spp: `{scene}/{frame}`, pixels x {x}-{x + size - 1}, y {y}-{y + size - 1}", "",
                  "| " + " | ".join(names) + " |", "|" + "---|" * len(names),
                  "| " + " | ".join(images) + " |", "| " + " | ".join(heats) + " |", ""]
    return lines


def fvvdp_section(run):
    settings = run.plan["settings"]
    if settings.get("FVVDP_OK") != "1":
        return []
    lines = ["## FovVideoVDP", "",
             f"pyfvvdp (`{settings['FVVDP_PYTHON']}`), display model `{settings['FVVDP_DISPLAY']}`, on both "
             "images after the Reinhard tonemap and the sRGB curve (as for FLIP), as still images. "
             "JOD, higher is better. It costs seconds per frame on the CPU, so it runs on "
             f"FVVDP_FRAMES={settings['FVVDP_FRAMES']} evenly spaced test frames per method and spp "
             "(0 means all); the frame count is in each heading.", ""]
    for spp in run.plan["spps"]:
        rows = []
        for m in run.active(spp):
            path = os.path.join(run.out, "fvvdp", f"{m['name']}_spp{spp}.json")
            if os.path.exists(path):
                with open(path) as f:
                    values = [r["fvvdp"] for r in json.load(f)["results"]]
                rows.append((m["label"], float(np.mean(values)), len(values)))
        if not rows:
            continue
        best = max(v for _, v, _ in rows)
        lines += [f"### {spp} spp ({rows[0][2]} frames)", "", "| method | FovVideoVDP (JOD) ↑ |", "|---|---:|"]
        lines += [f"| {label} | {'**' if f'{v:.3f}' == f'{best:.3f}' else ''}{v:.3f}"
                  f"{'**' if f'{v:.3f}' == f'{best:.3f}' else ''} |" for label, v, _ in rows]
        lines.append("")
    return lines


def limitations(run):
    lines = ["## Not measured", "",
             "- LPIPS, DINO and CLIP need network weights that cannot be downloaded on these machines.",
             "- AFGSA is not implemented in this project."]
    if run.plan["settings"].get("FVVDP_OK") != "1":
        lines.append("- FovVideoVDP: the interpreter given as FVVDP_PYTHON "
                     f"(`{run.plan['settings'].get('FVVDP_PYTHON')}`) has no `pyfvvdp`. It runs offline once "
                     "installed, but `pip install pyfvvdp` pulls PyTorch from PyPI with its CUDA libraries "
                     "(several GB), so it is kept out of the main environment: "
                     "`python3 -m venv ~/fvvdp && ~/fvvdp/bin/pip install pyfvvdp OpenEXR numpy`, then "
                     "`FVVDP_PYTHON=~/fvvdp/bin/python`.")
    return lines + [""]


# Sections other scripts wrote into the old report, each with its own command.
KEPT_SECTIONS = ((SECTION_BEGIN, SECTION_END),
                 ("<!-- temporal_eval.py: begin -->", "<!-- temporal_eval.py: end -->"))


def kept_section(path):
    """The sections that eval_sets.py and temporal_eval.py wrote into the old report, if any."""
    old = open(path).read() if os.path.exists(path) else ""
    kept = []
    for begin, end in KEPT_SECTIONS:
        if begin in old and end in old:
            kept += ["", begin + old.split(begin, 1)[1].split(end, 1)[0] + end]
    return kept


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--plan", required=True)
    parser.add_argument("--results", required=True)
    parser.add_argument("--figures", required=True)
    parser.add_argument("--bin", required=True)
    parser.add_argument("--command", required=True)
    args = parser.parse_args()
    data = Run(args.plan)
    means = {spp: mean_table(data, spp) for spp in data.plan["spps"]}
    means = {spp: t for spp, t in means.items() if t and data.cases(spp)}
    lines = header(data, args)
    lines += tables(data, means)
    lines += wins_losses(data, means)
    lines += speed_section(data)
    lines += fvvdp_section(data)
    lines += figures(data, means, args.figures, args.results)
    lines += limitations(data)
    lines += kept_section(args.results)
    tmp = f"{args.results}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write("\n".join(lines).rstrip() + "\n")
    os.replace(tmp, args.results)


if __name__ == "__main__":
    sys.exit(main())
