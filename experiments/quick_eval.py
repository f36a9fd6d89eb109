#!/usr/bin/env python3
"""Score one dndenoise setting on a split, for tuning: mean L1, PSNR, SSIM and FLIP.

  quick_eval.py --split DATA/val --spp 4 16 64 --name skip22 -- --skip 22
  quick_eval.py --split DATA/val --spp 4 --name noisy          (no --: the noisy input)
  quick_eval.py --split DATA/test --gt-pair --name default      (high spp: gt_a against gt_b)

Inputs and references come from make_inputs.py (cached under --work), every
result is scored by dnmetrics; one line per spp, with the per-frame FLIP.
--gt-pair denoises each frame's first ground truth and scores it against the
second, an independent render of the same sample count: the check above 64 spp. The
experiment Makefile is the place for tables; this is the quick loop before it.
"""

import argparse
import glob
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def run(cmd):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--split", required=True, help="a data set split: folder of scene_* folders")
    parser.add_argument("--spp", nargs="+", type=int, default=[4, 16, 64])
    parser.add_argument("--name", required=True, help="name of the setting (output subfolder)")
    parser.add_argument("--bin", default=os.path.join(ROOT, "build", "bin"))
    parser.add_argument("--work", default=None, help="cache folder (default: /tmp/dn_quick_eval/<split>)")
    parser.add_argument("--threads", type=int, default=os.cpu_count())
    parser.add_argument("--gt-pair", action="store_true", help="input gt_a.exr, reference gt_b.exr")
    args, extra = parser.parse_known_args()
    if extra and extra[0] == "--":
        extra = extra[1:]
    split = os.path.abspath(args.split)
    work = args.work or os.path.join("/tmp/dn_quick_eval", split.strip("/").replace("/", "_"))
    scenes = sorted(glob.glob(os.path.join(split, "scene_*")))
    if not scenes:
        sys.exit(f"{split}: no scene_* folders")
    if args.gt_pair:
        frames = [os.path.join(scene, "frame_0") for scene in scenes]
        inputs = {"gt": [(os.path.join(f, "gt_a.exr"), os.path.join(f, "gt_b.exr")) for f in frames]}
    else:
        for scene in scenes:
            name = os.path.basename(scene)
            if not all(os.path.exists(os.path.join(work, "in", name, f"frame_0_spp{s}.exr")) for s in args.spp):
                run([sys.executable, os.path.join(HERE, "make_inputs.py"), "scene", scene, "--frames", "frame_0",
                     "--spps", *map(str, args.spp), "--inputs", os.path.join(work, "in", name),
                     "--refs", os.path.join(work, "ref", name)])
        inputs = {spp: [(os.path.join(work, "in", os.path.basename(scene), f"frame_0_spp{spp}.exr"),
                         os.path.join(work, "ref", os.path.basename(scene), "frame_0.exr")) for scene in scenes]
                  for spp in args.spp}
    for spp, pairs in inputs.items():
        out_dir = os.path.join(work, "out", args.name, str(spp))
        os.makedirs(out_dir, exist_ok=True)
        rows = []
        for scene, (source, reference) in zip(scenes, pairs):
            result = source
            if args.name != "noisy":
                result = os.path.join(out_dir, f"{os.path.basename(scene)}.exr")
                run([os.path.join(args.bin, "dndenoise"), "--rgb-only", "--float", "--threads",
                     str(args.threads), *extra, source, "-o", result])
            metrics = subprocess.run([os.path.join(args.bin, "dnmetrics"), "--format", "json", "--metrics",
                                      "l1,psnr,ssim,flip", reference, result],
                                     check=True, capture_output=True, text=True).stdout
            rows.append(json.loads(metrics)["results"][0])
        mean = {k: sum(r[k] for r in rows) / len(rows) for k in ("l1", "psnr", "ssim", "flip")}
        print(f"{args.name:24s} spp {spp:>3}  L1 {mean['l1']:.4f}  PSNR {mean['psnr']:.2f}  "
              f"SSIM {mean['ssim']:.4f}  FLIP {mean['flip']:.4f}   per-frame FLIP "
              + " ".join(f"{r['flip']:.4f}" for r in rows), flush=True)


if __name__ == "__main__":
    main()
