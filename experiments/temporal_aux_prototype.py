#!/usr/bin/env python3
"""A temporal idea measured and not kept (docs/RESULTS.md, "Sequences"): each
frame's albedo and normal replaced by their mean over the neighbours within
--window frames that see the same surface, before denoising. At 4 spp the
guides' anti-aliased edges are noisy; averaged over frames they are cleaner,
which the networks turn into cleaner edges, but on a moving camera the
nearest pixel is up to half a pixel off.

The neighbours are followed along Blender's Vector pass hop by hop (nearest
pixel, the motion back must return within 1 px) and kept where depth, normal
and albedo agree (dndenoise's thresholds: 5 % depth, cosine 0.9, albedo
0.08 + 25 %). Writes the frames with the averaged guides to --out, then
scores `dndenoise --temporal on` on them when --dndenoise and --dnmetrics are
given:

  python3 experiments/temporal_aux_prototype.py --data /work/data/temporal5/object --spp 4 \\
      --out /tmp/aux/object --dndenoise build/bin/dndenoise --dnmetrics build/bin/dnmetrics
"""
import argparse
import glob
import json
import os
import subprocess

import numpy as np
import OpenEXR

LAYER = "ViewLayer."


def part(exr, name):
    return next(p for p in exr.parts if p.name() == LAYER + name)


def read_frame(path):
    exr = OpenEXR.File(path, separate_channels=True)

    def channels(name, suffixes):
        p = part(exr, name)
        return np.stack([p.channels[f"{LAYER}{name}.{c}"].pixels.astype(np.float64) for c in suffixes], -1)

    v = channels("Vector", "XYZW")  # X,Y: to the previous frame; Z,W: from the next; y up
    return {"exr": exr, "albedo": channels("Denoising Albedo", "RGB"),
            "normal": channels("Denoising Normal", "XYZ"), "depth": channels("Depth", "Z")[..., 0],
            "previous": np.stack([v[..., 0], -v[..., 1]], -1), "next": np.stack([-v[..., 2], v[..., 3]], -1)}


def nearest(image, x, y):
    h, w = image.shape[:2]
    return image[np.clip(np.rint(y).astype(int), 0, h - 1), np.clip(np.rint(x).astype(int), 0, w - 1)]


def same_surface(frame, x, y, current):
    depth, albedo, normal = (nearest(frame[k], x, y) for k in ("depth", "albedo", "normal"))
    ok = np.abs(depth - current["depth"]) <= 0.05 * np.maximum(np.abs(current["depth"]), 1e-6)
    ls, lc = np.linalg.norm(normal, axis=-1), np.linalg.norm(current["normal"], axis=-1)
    ok &= (ls < 1e-3) == (lc < 1e-3)
    ok &= (ls < 1e-3) | ((normal * current["normal"]).sum(-1) >= 0.9 * ls * lc)
    ok &= (np.abs(albedo - current["albedo"]) <= 0.08 + 0.25 * np.maximum(albedo, current["albedo"])).all(-1)
    return ok, albedo, normal


def averaged_guides(frames, t, window):
    current = frames[t]
    h, w = current["depth"].shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    albedo, normal, count = current["albedo"].copy(), current["normal"].copy(), np.ones((h, w))
    for side in (-1, 1):
        x, y, alive = xs.copy(), ys.copy(), np.ones((h, w), bool)
        for k in range(1, window + 1):
            a, b = t + side * (k - 1), t + side * k
            if not 0 <= b < len(frames):
                break
            step = nearest(frames[a]["next" if side > 0 else "previous"], x, y)
            nx, ny = x + step[..., 0], y + step[..., 1]
            alive &= (nx >= -0.5) & (ny >= -0.5) & (nx <= w - 0.5) & (ny <= h - 0.5)
            back = nearest(frames[b]["previous" if side > 0 else "next"], nx, ny)
            alive &= (nx + back[..., 0] - x) ** 2 + (ny + back[..., 1] - y) ** 2 <= 1.0
            x, y = nx, ny
            ok, a_b, n_b = same_surface(frames[b], x, y, current)
            ok &= alive
            albedo[ok] += a_b[ok]
            normal[ok] += n_b[ok]
            count += ok
    return albedo / count[..., None], normal / count[..., None], count.mean()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a render_sequences.py folder")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--window", type=int, default=4)
    ap.add_argument("--out", required=True)
    ap.add_argument("--dndenoise")
    ap.add_argument("--dnmetrics")
    args = ap.parse_args()
    paths = sorted(glob.glob(os.path.join(args.data, f"spp{args.spp}.*.exr")))
    frames = [read_frame(p) for p in paths]
    os.makedirs(args.out, exist_ok=True)
    for t, path in enumerate(paths):
        albedo, normal, used = averaged_guides(frames, t, args.window)
        exr = frames[t]["exr"]
        for name, values, suffixes in (("Denoising Albedo", albedo, "RGB"), ("Denoising Normal", normal, "XYZ")):
            for i, c in enumerate(suffixes):
                part(exr, name).channels[f"{LAYER}{name}.{c}"].pixels = values[..., i].astype(np.float32)
        exr.write(os.path.join(args.out, os.path.basename(path)))
        print(f"{os.path.basename(path)}: guides averaged over {used:.2f} frames a pixel")
    if not (args.dndenoise and args.dnmetrics):
        return
    pattern = os.path.join(args.out, f"spp{args.spp}.#.exr")
    result = os.path.join(args.out, "denoised.#.exr")
    subprocess.run([args.dndenoise, pattern, "-o", result, "--rgb-only", "--float", "--temporal", "on",
                    "--frames", f"1-{len(paths)}"], check=True)
    shared = os.path.join(args.data, "ref.exr")
    ref = shared if os.path.exists(shared) else os.path.join(args.data, "ref.#.exr")
    scores = subprocess.run([args.dnmetrics, ref, result, "--metrics", "psnr,flip", "--format", "json"],
                            check=True, capture_output=True, text=True).stdout
    rows = json.loads(scores)["results"]
    print(f"temporal default on the averaged guides: PSNR {np.mean([r['psnr'] for r in rows]):.2f} dB, "
          f"FLIP {np.mean([r['flip'] for r in rows]):.4f}")


if __name__ == "__main__":
    main()
