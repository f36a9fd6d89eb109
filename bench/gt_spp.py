#!/usr/bin/env python3
"""How many samples the ground truth needs: targets at several spp against a brute-force reference.

  python3 bench/gt_spp.py --out /tmp/gt_spp --seeds 1,3,6,8,9,23 --gt-spps 128,256,512 --ref-spp 4096

Renders, with scenegen/make_dataset.py, the seeds' frame 0 four ways: the data set's
16 stacks of 4 spp with two ground truths at the smallest --gt-spps, two ground truths
at each other count (own render seeds, --seed-tag), and one --ref-spp reference
(--seed-tag ref). Then prints, per frame and on average, the error against the reference
of the training target (mean of gt_a and gt_b) at each count, of the 64-spp input (mean
of the 16 stacks), and of OIDN (colour + albedo + normal, quality high, when pyoidn is
installed) on each target (a stand-in for cleansing) and on that input: relMSE = mean((x - ref)^2 / (ref^2 + 0.01)) and PSNR after x / (1 + x).
The reference's own noise is included in every number (about N / ref_spp of a target's).
"""

import argparse
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "experiments"))
sys.path.insert(0, os.path.join(ROOT, "scenegen"))
from exrutil import find_channels, read_channels, read_color  # noqa: E402
from make_dataset import scene_dir  # noqa: E402


def render(out, seeds, res, threads, blender, **kw):
    cmd = [sys.executable, os.path.join(ROOT, "scenegen", "make_dataset.py"), "--out", out, "--seeds", seeds,
           "--res", str(res), "--frames", "1", "--threads", str(threads), "--blender", blender, "--batch", "50"]
    for key, value in kw.items():
        cmd += ["--" + key.replace("_", "-"), str(value)]
    subprocess.run(cmd, check=True)


def rel_mse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + 0.01)))


def psnr(x, ref):
    a, b = x / (1 + np.maximum(x, 0)), ref / (1 + np.maximum(ref, 0))
    return float(10 * np.log10(1.0 / max(np.mean((a - b) ** 2), 1e-12)))


def oidn_mean(frame_dir, names):
    """OIDN (quality high, colour + albedo + normal) on the mean of the named files; None without pyoidn."""
    try:
        from oidn_denoise import Denoiser
    except ImportError:
        return None
    color, albedo, normal = 0, 0, 0
    for name in names:
        ch, _ = read_channels(os.path.join(frame_dir, name))
        color = color + find_channels(ch, "Combined", "RGB", frame_dir)
        albedo = albedo + find_channels(ch, "Denoising Albedo", "RGB", frame_dir)
        normal = normal + find_channels(ch, "Denoising Normal", "XYZ", frame_dir)
    arrays = [np.ascontiguousarray(a / len(names), dtype=np.float32) for a in (color, albedo, normal)]
    arrays[0] = arrays[0].clip(min=0)
    arrays[1] = arrays[1].clip(0, 1)
    arrays[2] = arrays[2].clip(-1, 1)
    return Denoiser("high", 2).run(*arrays).astype(np.float64)


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--seeds", default="1,3,6,8,9,23")
    p.add_argument("--gt-spps", default="128,256,512")
    p.add_argument("--ref-spp", type=int, default=4096)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--blender", default="blender")
    args = p.parse_args(argv)
    spps = [int(s) for s in args.gt_spps.split(",")]
    dirs = {spps[0]: os.path.join(args.out, "gt%d" % spps[0])}
    render(dirs[spps[0]], args.seeds, args.res, args.threads, args.blender, gt_spp=spps[0], stacks=16)
    for n in spps[1:]:
        dirs[n] = os.path.join(args.out, "gt%d" % n)
        render(dirs[n], args.seeds, args.res, args.threads, args.blender, gt_spp=n, stacks=1, seed_tag="gt%d" % n)
    ref_dir = os.path.join(args.out, "ref")
    render(ref_dir, args.seeds, args.res, args.threads, args.blender, gt_spp=args.ref_spp, stacks=1, gt_count=1,
           seed_tag="ref")
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        ref = read_color(os.path.join(scene_dir(ref_dir, seed), "frame_0", "gt_a.exr")).astype(np.float64)
        row = {"seed": seed}
        for n in spps:
            fdir = os.path.join(scene_dir(dirs[n], seed), "frame_0")
            target = (read_color(os.path.join(fdir, "gt_a.exr")) + read_color(os.path.join(fdir, "gt_b.exr"))) / 2
            row["gt%d" % n] = (rel_mse(target, ref), psnr(target, ref))
            cleansed = oidn_mean(fdir, ["gt_a.exr", "gt_b.exr"])
            if cleansed is not None:
                row["oidn_gt%d" % n] = (rel_mse(cleansed, ref), psnr(cleansed, ref))
        fdir = os.path.join(scene_dir(dirs[spps[0]], seed), "frame_0")
        noisy = sum(read_color(os.path.join(fdir, "spp4_%02d.exr" % i)).astype(np.float64) for i in range(16)) / 16
        row["input64"] = (rel_mse(noisy, ref), psnr(noisy, ref))
        denoised = oidn_mean(fdir, ["spp4_%02d.exr" % i for i in range(16)])
        if denoised is not None:
            row["oidn64"] = (rel_mse(denoised, ref), psnr(denoised, ref))
        rows.append(row)
    oidn = "oidn64" in rows[0]
    keys = ["gt%d" % n for n in spps] + (["oidn_gt%d" % n for n in spps] if oidn else []) + ["input64"] + \
        (["oidn64"] if oidn else [])
    names = ["target 2x%d spp" % n for n in spps] + (["OIDN on target 2x%d" % n for n in spps] if oidn else []) + \
        ["input 64 spp"] + (["OIDN on 64 spp"] if oidn else [])
    print("relMSE / PSNR (dB) against a %d-spp reference, %dx%d, frame 0" % (args.ref_spp, args.res, args.res))
    print("| seed | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for row in rows:
        print("| %d | " % row["seed"] + " | ".join("%.5f / %.1f" % row[k] for k in keys) + " |")
    print("| mean | " + " | ".join("%.5f / %.1f" % (np.mean([r[k][0] for r in rows]), np.mean([r[k][1] for r in rows]))
                                   for k in keys) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
