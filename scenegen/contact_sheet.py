#!/usr/bin/env python3
"""A PNG grid of a data set's reference frames, one row per archetype (docs/dataset.md).

  python3 scenegen/contact_sheet.py DATA --out docs/dataset_contact_sheet.png --per-row 8
  python3 scenegen/contact_sheet.py MANIFEST.json --table     # frames per archetype and lighting

Each tile is the mean of a frame's ground truths (gt_a, gt_b; gt_clean when present),
tonemapped with Reinhard on luminance and the sRGB curve, labelled with its seed and
lighting. Frames are taken in seed order, frame 0 of each scene first.
"""

import argparse
import glob
import json
import os
import sys

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "experiments"))
from exrutil import ExrError, read_color  # noqa: E402

LABEL_H = 12


def tonemap(rgb):
    """Linear HDR to 8-bit sRGB: Reinhard on luminance keeps hues of bright lights."""
    lum = 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]
    scale = np.where(lum > 0, 1.0 / (1.0 + lum), 1.0)
    mapped = np.clip(rgb * scale[..., None], 0.0, 1.0)
    srgb = np.where(mapped <= 0.0031308, 12.92 * mapped, 1.055 * np.power(mapped, 1 / 2.4) - 0.055)
    return (255 * srgb + 0.5).astype(np.uint8)


def reference(frame_dir):
    clean = os.path.join(frame_dir, "gt_clean.exr")
    if os.path.exists(clean):
        return read_color(clean)
    gts = sorted(glob.glob(os.path.join(frame_dir, "gt_[ab].exr")))
    if not gts:
        raise ExrError("%s: no ground truth (gt_a.exr)" % frame_dir)
    return sum(read_color(p) for p in gts) / len(gts)


def frames_by_archetype(root):
    """{archetype: [(seed, frame, lighting, folder)]}, finished frames only, frame 0 of every scene first."""
    rows = {}
    for meta_path in sorted(glob.glob(os.path.join(root, "*", "scene_*", "frame_*", "meta.json"))):
        meta = json.load(open(meta_path))
        scene = json.load(open(os.path.join(os.path.dirname(os.path.dirname(meta_path)), "scene.json")))
        desc = scene["description"]
        arch = desc.get("archetype", "?")
        rows.setdefault(arch, []).append((meta["frame"], meta["seed"], desc.get("lighting", "?"),
                                          os.path.dirname(meta_path)))
    return {a: [(s, f, l, d) for f, s, l, d in sorted(v)] for a, v in rows.items()}


def print_table(manifest_path):
    """Markdown: frames per archetype (rows) and lighting (columns), from a manifest's frame_counts."""
    with open(manifest_path) as f:
        counts = json.load(f)["frame_counts"]
    lights = list(counts["lighting"])
    print("| archetype | " + " | ".join(lights) + " | frames |")
    print("|---|" + "---|" * (len(lights) + 1))
    for arch, row in counts["archetype_lighting"].items():
        print("| %s | " % arch + " | ".join(str(row.get(l, "")) for l in lights) + " | %d |" % sum(row.values()))
    print("| frames | " + " | ".join(str(counts["lighting"][l]) for l in lights) +
          " | %d |" % sum(counts["lighting"].values()))


def main(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", help="data set folder (with train/, val/, test/), or a manifest with --table")
    p.add_argument("--out", help="PNG to write")
    p.add_argument("--table", action="store_true", help="print the archetype x lighting table of a manifest")
    p.add_argument("--per-row", type=int, default=8, help="frames per archetype")
    p.add_argument("--tile", type=int, default=128, help="tile size in pixels")
    args = p.parse_args(argv)
    if args.table:
        print_table(args.data)
        return 0
    if not args.out:
        p.error("--out is needed for the contact sheet")
    rows = frames_by_archetype(args.data)
    if not rows:
        sys.exit("contact_sheet.py: %s: no finished frames" % args.data)
    label_w = 110
    t = args.tile
    sheet = Image.new("RGB", (label_w + args.per_row * t, len(rows) * (t + LABEL_H)), (32, 32, 32))
    draw = ImageDraw.Draw(sheet)
    for r, arch in enumerate(sorted(rows)):
        y = r * (t + LABEL_H)
        draw.text((4, y + t // 2), "%s\n(%d frames)" % (arch, len(rows[arch])), fill=(230, 230, 230))
        for c, (seed, frame, lighting, folder) in enumerate(rows[arch][:args.per_row]):
            try:
                tile = Image.fromarray(tonemap(reference(folder))).resize((t, t), Image.BILINEAR)
            except ExrError as err:
                sys.exit("contact_sheet.py: %s" % err)
            x = label_w + c * t
            sheet.paste(tile, (x, y))
            draw.text((x + 2, y + t), "%d/%d %s" % (seed, frame, lighting)[:22], fill=(200, 200, 200))
    tmp = args.out + ".tmp.png"
    sheet.save(tmp, optimize=True)
    os.replace(tmp, args.out)
    print("contact_sheet.py: %d archetypes, %s" % (len(rows), args.out), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
