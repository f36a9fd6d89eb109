#!/usr/bin/env python3
"""Which networks make OIDN's prefilter mode pay: pyoidn on every evaluation set.

  oidn_prefilter_variants.py [--threads N] [--work /work/eval] [--user /work/agree/user]
                             [--evaldata /work/evaldata]

Per set and spp, the mean PSNR (Reinhard v / (1 + v), computed here: compare
the columns with each other, not with dnmetrics' tables) of
  plain       OIDN's usual call: colour + albedo + normal as rendered
  aux_L+col_L the prefilter mode at OIDN's default quality: large albedo and
              normal networks, then the large colour network for clean aux
  aux_D+col_L default-size albedo and normal networks, then the large colour one
              (what dndenoise runs)
  aux_D+col_D all three at the default size (OIDN's balanced quality)
  alb_D+col_L only the albedo denoised (default size), the normal as rendered,
              then the large colour network
  col_L       the large clean-aux colour network on the buffers as rendered
Inputs and references as eval_sets.py finds them (its test-split inputs must exist).
"""
import argparse
import collections
import glob
import os
import sys

import numpy as np
import pyoidn
from pyoidn.filter import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_BALANCED, OIDN_QUALITY_DEFAULT

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from oidn_denoise import load_buffers  # noqa: E402
from exrutil import color_names, read_channels  # noqa: E402


def pairs(work, user, evaldata):
    for scene in sorted(glob.glob(os.path.join(work, "test_in", "scene_*"))):
        name = os.path.basename(scene)
        for spp in (4, 16, 64):
            yield "test", f"{scene}/frame_0_spp{spp}.exr", os.path.join(work, "test_ref", name, "frame_0.exr"), spp
    for ref in sorted(glob.glob(os.path.join(user, "*_ref.exr"))):
        for spp in (4, 16, 64):
            yield "user", ref.replace("_ref.exr", f"_{spp}spp.exr"), ref, spp
    for ref in sorted(glob.glob(os.path.join(evaldata, "blender5", "*", "ref.exr"))):
        for spp in (4, 16, 64):
            yield "blender5", os.path.join(os.path.dirname(ref), f"spp{spp}.exr"), ref, spp


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--work", default="/work/eval")
    ap.add_argument("--user", default="/work/agree/user")
    ap.add_argument("--evaldata", default="/work/evaldata")
    args = ap.parse_args()
    device = pyoidn.Device()
    if args.threads > 0:
        device.set_int("numThreads", args.threads)
    device.commit()

    def run(images, quality, hdr=True, clean_aux=False):
        f = pyoidn.Filter(device, "RT")
        f.set_quality(quality)
        f.set_bool("hdr", hdr)
        f.set_bool("cleanAux", clean_aux)
        out = np.zeros_like(next(iter(images.values())))
        for name, image in list(images.items()) + [("output", out)]:
            f.set_image(name, image, OIDN_FORMAT_FLOAT3)
        f.commit()
        f.execute()
        return out

    def psnr(x, ref):
        t = lambda v: np.clip(v, 0, None) / (1 + np.clip(v, 0, None))  # noqa: E731
        return 10 * np.log10(1 / np.mean((t(x) - t(ref)) ** 2))

    sums = collections.defaultdict(list)
    for group, source, reference, spp in pairs(args.work, args.user, args.evaldata):
        if not os.path.exists(source):
            continue
        color, albedo, normal = load_buffers(source)
        channels, _ = read_channels(reference)
        ref = np.stack([channels[n] for n in color_names(channels, reference)], -1).astype(np.float32)
        aux = {q: {n: run({n: b}, q, hdr=False) for n, b in (("albedo", albedo), ("normal", normal))}
               for q in (OIDN_QUALITY_DEFAULT, OIDN_QUALITY_BALANCED)}
        results = {
            "plain": run({"color": color, "albedo": albedo, "normal": normal}, OIDN_QUALITY_DEFAULT),
            "aux_L+col_L": run({"color": color, **aux[OIDN_QUALITY_DEFAULT]}, OIDN_QUALITY_DEFAULT, clean_aux=True),
            "aux_D+col_L": run({"color": color, **aux[OIDN_QUALITY_BALANCED]}, OIDN_QUALITY_DEFAULT, clean_aux=True),
            "aux_D+col_D": run({"color": color, **aux[OIDN_QUALITY_BALANCED]}, OIDN_QUALITY_BALANCED,
                               clean_aux=True),
            "alb_D+col_L": run({"color": color, "albedo": aux[OIDN_QUALITY_BALANCED]["albedo"], "normal": normal},
                               OIDN_QUALITY_DEFAULT, clean_aux=True),
            "col_L": run({"color": color, "albedo": albedo, "normal": normal}, OIDN_QUALITY_DEFAULT, clean_aux=True),
        }
        for name, image in results.items():
            sums[(group, spp, name)].append(psnr(image, ref))
    names = ["plain", "aux_L+col_L", "aux_D+col_L", "aux_D+col_D", "alb_D+col_L", "col_L"]
    print("| set | spp | frames | " + " | ".join(names) + " |")
    print("|---|---|---|" + "---|" * len(names))
    for group, spp in sorted({(g, s) for g, s, _ in sums}):
        cells = [f"{np.mean(sums[(group, spp, n)]):.2f}" for n in names]
        print(f"| {group} | {spp} | {len(sums[(group, spp, 'plain')])} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
