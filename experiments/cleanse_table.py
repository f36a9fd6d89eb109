#!/usr/bin/env python3
"""How clean is the training target? Raw ground truth against cleansed, scored on a
much higher-spp reference (docs/dncleanse.md, "Which target").

  python3 experiments/cleanse_table.py --data /work/data/train /work/data/gt32 \
      --ref /work/data/ref2048 --bin build/bin --model models/oidn.dnm

--data are data sets (gt_a.exr and gt_b.exr per frame); --ref holds the same
scenes and frames rendered once at a higher spp with another --seed-tag
(make_dataset.py --gt-count 1), or, with --ref-mean, twice (the reference is the
mean of its gt_a and gt_b). Each candidate target is scored with dnmetrics
against the reference: relMSE (linear), PSNR (Reinhard) and FLIP.
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exrutil  # noqa: E402

METRICS = ("relmse", "psnr", "flip")


def frames_of(root):
    """split/scene/frame paths (relative) of every finished frame under root."""
    found = []
    for dirpath, _, files in os.walk(root):
        if "meta.json" in files and "gt_a.exr" in files:
            found.append(os.path.relpath(dirpath, root))
    return sorted(found)


def spp_of(frame_dir):
    with open(os.path.join(frame_dir, "meta.json")) as f:
        return json.load(f)["gt_spp"]


def score(dnmetrics, ref, test):
    out = subprocess.run([dnmetrics, "--format", "json", "--metrics", ",".join(METRICS), "--threads", "2",
                          ref, test], check=True, capture_output=True, text=True).stdout
    row = json.loads(out)["results"][0]
    return {m: float(row[m]) for m in METRICS}


def cleanse(dncleanse, model, data, source):
    subprocess.run([dncleanse, "apply", "--model", model, "--data", data, "--source", source, "--force",
                    "--threads", "2"], check=True, capture_output=True)


def reference_of(a, frame, work):
    """The reference image of one frame: its gt_a, or with --ref-mean the mean of gt_a and gt_b."""
    d = os.path.join(a.ref, frame)
    if not a.ref_mean:
        return os.path.join(d, "gt_a.exr")
    path = os.path.join(work, "ref", frame, "mean.exr")
    if not os.path.isfile(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        rgb = 0.5 * (exrutil.read_color(os.path.join(d, "gt_a.exr")) + exrutil.read_color(os.path.join(d, "gt_b.exr")))
        exrutil.write_rgb(path, rgb)
    return path


def score_targets(a, data, frames):
    """{label: [metrics per frame]} of the raw and the cleansed targets of one data set."""
    gt_spp = spp_of(os.path.join(data, frames[0]))
    dnmetrics, dncleanse = os.path.join(a.bin, "dnmetrics"), os.path.join(a.bin, "dncleanse")
    work = tempfile.mkdtemp(prefix="cleanse_table.")
    try:
        # A data set of links to the chosen frames, which dncleanse apply cleanses in place.
        for f in frames:
            os.makedirs(os.path.join(work, "set", f))
            for name in ("gt_a.exr", "gt_b.exr", "meta.json"):
                os.symlink(os.path.abspath(os.path.join(data, f, name)), os.path.join(work, "set", f, name))
            a_rgb = exrutil.read_color(os.path.join(data, f, "gt_a.exr"))
            b_rgb = exrutil.read_color(os.path.join(data, f, "gt_b.exr"))
            exrutil.write_rgb(os.path.join(work, "set", f, "mean.exr"), 0.5 * (a_rgb + b_rgb))
        candidates = {f"raw, one render ({gt_spp} spp)": lambda f: os.path.join(data, f, "gt_a.exr"),
                      f"raw, mean of two ({2 * gt_spp} spp)": lambda f: os.path.join(work, "set", f, "mean.exr")}
        for source, label in (("a", f"OIDN-cleansed, one render ({gt_spp} spp)"),
                              ("mean", f"OIDN-cleansed, mean of two ({2 * gt_spp} spp)")):
            cleanse(dncleanse, a.model, os.path.join(work, "set"), source)
            for f in frames:
                d = os.path.join(work, "set", f)
                os.replace(os.path.join(d, "gt_clean.exr"), os.path.join(d, f"clean_{source}.exr"))
            candidates[label] = lambda f, s=source: os.path.join(work, "set", f, f"clean_{s}.exr")
        return {label: [score(dnmetrics, reference_of(a, f, work), path(f)) for f in frames]
                for label, path in candidates.items()}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, nargs="+", help="data sets whose targets are compared")
    p.add_argument("--ref", required=True)
    p.add_argument("--ref-mean", action="store_true", help="the reference is the mean of its gt_a and gt_b")
    p.add_argument("--bin", default="build/bin")
    p.add_argument("--model", default="models/oidn.dnm", help="the cleanser given to dncleanse apply")
    a = p.parse_args()

    frames = [f for f in frames_of(a.ref) if all(os.path.isfile(os.path.join(d, f, "meta.json")) for d in a.data)]
    if not frames:
        exrutil.fail(f"{a.ref}: no frame that every --data set has")
    ref_spp = spp_of(os.path.join(a.ref, frames[0])) * (2 if a.ref_mean else 1)
    results = {}
    for data in a.data:
        results.update(score_targets(a, data, frames))
    print(f"{len(frames)} frames, against a {ref_spp}-spp reference of each ({a.ref}):\n")
    print("| target | relMSE (median) | relMSE (mean) | PSNR (dB) | FLIP |")
    print("|---|---:|---:|---:|---:|")
    for label, rows in results.items():
        rel = [r["relmse"] for r in rows]
        print(f"| {label} | {statistics.median(rel):.5f} | {np.mean(rel):.5f} | "
              f"{np.mean([r['psnr'] for r in rows]):.2f} | {np.mean([r['flip'] for r in rows]):.4f} |")
    print("\nper frame, relMSE: " + "; ".join(
        f"{f}: " + ", ".join(f"{results[label][i]['relmse']:.5f}" for label in results) for i, f in enumerate(frames)))


if __name__ == "__main__":
    main()
