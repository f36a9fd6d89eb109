#!/usr/bin/env python3
"""The variants of the denoised light passes on one render, per pass: PSNR (Reinhard)
against the reference's same pass, beside the noisy pass and OIDN's prefilter mode on
the pass alone (pyoidn). The variants are bench/passes_variants' files in OUTDIR.

  build/bin/passes_variants --model models/default.dnm IN.exr OUTDIR
  python3 experiments/passes_variants_table.py IN.exr OUTDIR REF.exr [REF2.exr]
"""
import glob
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import passes_eval as pe  # noqa: E402
from eval_renders import psnr  # noqa: E402


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    path, folder, refs = sys.argv[1], sys.argv[2], sys.argv[3:]
    _, beauty, albedo, normal, found, layers = pe.load(path)
    terms = pe.usable_terms(found)
    ref_passes = [pe.passes_of(pe.read_channels(r)[0])[0] for r in refs]
    reference = {k: np.mean([r[k] for r in ref_passes], axis=0) for k in found}
    residual = beauty - pe.recombine(terms, found)
    prefiltered, _ = pe.oidn_passes(pe.Oidn("default", 0), found, residual, beauty, albedo, normal, True)
    keys = [k for k in found if np.abs(reference[k]).mean() > 1e-4]  # passes with signal
    rows = {"noisy": found, "oidn_pre": prefiltered}
    for file in sorted(glob.glob(os.path.join(folder, "*.exr"))):
        channels, _ = pe.read_channels(file)
        rows[os.path.basename(file)[:-4]] = {k: pe.rgb(channels, k) for k in keys}
    print("| variant | " + " | ".join(layers[k] for k in keys) + " | mean |")
    print("|---" * (len(keys) + 2) + "|")
    for name, passes in rows.items():
        values = [psnr(reference[k], passes[k]) for k in keys]
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in values) + f" | {np.mean(values):.2f} |")


if __name__ == "__main__":
    main()
