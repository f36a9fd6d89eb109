#!/usr/bin/env python3
"""How to use Cycles' diffuse light passes with OIDN's networks: pyoidn on the
Cycles evaluation sets (test split, user-style scenes, Blender 5).

  light_path_variants.py [--threads N] [--test-split DIR] [--user DIR...] [--evaldata DIR] [--work DIR]

Every variant starts from OIDN's prefilter mode (default-size albedo and normal
networks, then the large colour network for clean aux), as dndenoise runs it.
The diffuse part is D = DiffCol * (DiffDir + DiffInd), the rest max(colour - D, 0).
Per set and spp, the mean PSNR (Reinhard v / (1 + v), computed here) and L1 of
  whole     the prefilter mode on the whole render (dndenoise --light-paths off)
  parts     D denoised with its prefiltered diffuse colour as albedo, plus the
            rest with the prefiltered albedo
  mean      (whole + parts) / 2
  mean_T    the same with the parts denoised on the transposed frame
            (what dndenoise runs by default)
  mean_T_D  the same with the parts denoised by the default-size network for
            clean aux (OIDN's balanced quality) instead of the large one
  whole_T   (whole + whole on the transposed frame) / 2: no passes needed
  mean3     (whole + parts + parts with the glossy part split off as well) / 3
Inputs and references as eval_sets.py finds them.
"""
import argparse
import collections
import os
import sys

import numpy as np
import pyoidn
from pyoidn.filter import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_BALANCED, OIDN_QUALITY_DEFAULT

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import eval_sets  # noqa: E402
from exrutil import ExrError, find_channels, read_channels, read_color  # noqa: E402
from oidn_denoise import load_buffers  # noqa: E402

NAMES = ["whole", "parts", "mean", "mean_T", "mean_T_D", "whole_T", "mean3"]
PASSES = {"DiffCol": "Diffuse Color", "DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect",
          "GlossCol": "Glossy Color", "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect"}


def light_pass(channels, short, path):
    """A Cycles pass under Blender 3.4's short name or Blender 4/5's full one."""
    try:
        return find_channels(channels, short, "RGB", path)
    except ExrError:
        return find_channels(channels, PASSES[short], "RGB", path)


def transposed(image):
    return np.ascontiguousarray(image.transpose(1, 0, 2))


class Oidn:
    def __init__(self, threads):
        self.device = pyoidn.Device()
        if threads > 0:
            self.device.set_int("numThreads", threads)
        self.device.commit()

    def run(self, images, quality=OIDN_QUALITY_DEFAULT, hdr=True, clean_aux=True):
        f = pyoidn.Filter(self.device, "RT")
        f.set_quality(quality)
        f.set_bool("hdr", hdr)
        f.set_bool("cleanAux", clean_aux)
        out = np.zeros_like(next(iter(images.values())))
        for name, image in list(images.items()) + [("output", out)]:
            f.set_image(name, np.ascontiguousarray(image, np.float32), OIDN_FORMAT_FLOAT3)
        f.commit()
        f.execute()
        return out

    def clean(self, name, image):
        return self.run({name: image}, OIDN_QUALITY_BALANCED, hdr=False, clean_aux=False)

    def colour(self, color, albedo, normal, quality=OIDN_QUALITY_DEFAULT):
        return self.run({"color": color, "albedo": albedo, "normal": normal}, quality)


def variants(oidn, path):
    color, albedo, normal = load_buffers(path)
    channels, _ = read_channels(path)
    p = {k: light_pass(channels, k, path) for k in PASSES}
    diffuse_colour, glossy_colour = p["DiffCol"].clip(0, 1), p["GlossCol"].clip(0, 1)
    diffuse = diffuse_colour * np.maximum(p["DiffDir"] + p["DiffInd"], 0)
    glossy = glossy_colour * np.maximum(p["GlossDir"] + p["GlossInd"], 0)

    def denoised(t, parts, quality=OIDN_QUALITY_DEFAULT):
        """In orientation t: each (part, its colour) denoised with that colour as albedo, plus
        what the parts leave of the render with the albedo, summed."""
        albedo_t, normal_t = oidn.clean("albedo", t(albedo)), oidn.clean("normal", t(normal))
        out, rest = 0, color
        for part, guide in parts:
            out = out + oidn.colour(t(part), oidn.clean("albedo", t(guide)), normal_t, quality)
            rest = rest - part
        return t(out + oidn.colour(t(np.maximum(rest, 0)), albedo_t, normal_t, quality))

    same = lambda x: x  # noqa: E731
    whole = denoised(same, [])
    split = denoised(same, [(diffuse, diffuse_colour)])
    return {"whole": whole, "parts": split, "mean": (whole + split) / 2,
            "mean_T": (whole + denoised(transposed, [(diffuse, diffuse_colour)])) / 2,
            "mean_T_D": (whole + denoised(transposed, [(diffuse, diffuse_colour)], OIDN_QUALITY_BALANCED)) / 2,
            "whole_T": (whole + denoised(transposed, [])) / 2,
            "mean3": (whole + split + denoised(same, [(diffuse, diffuse_colour), (glossy, glossy_colour)])) / 3}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--test-split", default="/work/data/scenes/test")
    ap.add_argument("--user", nargs="*", default=["/work/agree/user"])
    ap.add_argument("--evaldata", default="/work/evaldata")
    ap.add_argument("--work", default="/work/eval")
    args = ap.parse_args()
    pairs = eval_sets.test_pairs(os.path.abspath(args.test_split), args.work) if os.path.isdir(
        args.test_split) else []
    for folder in args.user:
        pairs += eval_sets.user_pairs(folder)
    pairs += [p for p in eval_sets.evaldata_pairs(args.evaldata) if p[0] == "blender5"]
    oidn = Oidn(args.threads)
    scores = collections.defaultdict(list)
    for group, _, spp, source, reference in pairs:
        ref = read_color(reference)
        t = lambda v: np.clip(v, 0, None) / (1 + np.clip(v, 0, None))  # noqa: E731
        for name, image in variants(oidn, source).items():
            scores[(group, spp, name)].append((10 * np.log10(1 / np.mean((t(image) - t(ref)) ** 2)),
                                               float(np.mean(np.abs(image - ref)))))
    print("| set | spp | frames | " + " | ".join(f"{n} PSNR / L1" for n in NAMES) + " |")
    print("|---|---|---|" + "---|" * len(NAMES))
    for group, spp in sorted({(g, s) for g, s, _ in scores}):
        cells = [f"{np.mean([v[0] for v in scores[(group, spp, n)]]):.2f} / "
                 f"{np.mean([v[1] for v in scores[(group, spp, n)]]):.4f}" for n in NAMES]
        print(f"| {group} | {spp} | {len(scores[(group, spp, 'whole')])} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
