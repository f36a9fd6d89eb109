#!/usr/bin/env python3
"""Writes a tiny synthetic data set in the layout of docs/dataset.md, with
Blender-style multilayer EXRs holding every buffer the default model reads, for
end-to-end tests of the training and denoising tools (seconds, not hours).

  make_tiny_dataset.py OUT [--size 32] [--frames 2] [--stacks 4]
"""
import argparse
import json
import os

import numpy as np
import OpenEXR

LAYERS = {  # Blender pass name -> channel letters
    "Combined": "RGBA", "Denoising Albedo": "RGB", "Denoising Normal": "XYZ", "Denoising Depth": "Z",
    "DiffDir": "RGB", "DiffInd": "RGB", "DiffCol": "RGB", "GlossDir": "RGB", "GlossInd": "RGB",
    "GlossCol": "RGB", "TransDir": "RGB", "TransInd": "RGB", "TransCol": "RGB",
}


def write_frame(path, passes):
    channels = {}
    for layer, letters in LAYERS.items():
        data = passes[layer]
        for i, letter in enumerate(letters):
            plane = data[:, :, i] if data.ndim == 3 else data
            channels[f"ViewLayer.{layer}.{letter}"] = np.ascontiguousarray(plane.astype(np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def scene(rng, size):
    y, x = np.mgrid[0:size, 0:size] / size
    albedo = np.dstack([0.2 + 0.6 * (x > 0.5), 0.3 + 0.4 * y, 0.5 + 0.3 * np.sin(9 * x)])
    light = 0.5 + 2.0 * np.exp(-((x - rng.random()) ** 2 + (y - rng.random()) ** 2) * 8)
    normal = np.dstack([np.zeros_like(x), np.zeros_like(x), np.ones_like(x)])
    return albedo, light[:, :, None], normal, 2 + 3 * y


def passes_for(albedo, light, normal, depth, noise):
    diffuse = albedo * light * noise
    zero = np.zeros_like(albedo)
    return {"Combined": np.dstack([diffuse, np.ones(depth.shape)]), "Denoising Albedo": albedo,
            "Denoising Normal": normal, "Denoising Depth": depth, "DiffDir": diffuse * 0.7,
            "DiffInd": diffuse * 0.3, "DiffCol": albedo, "GlossDir": zero, "GlossInd": zero,
            "GlossCol": zero, "TransDir": zero, "TransInd": zero, "TransCol": zero}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--stacks", type=int, default=4)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    for split in ("train", "val"):
        for f in range(args.frames):
            d = os.path.join(args.out, split, f"scene_{f}", "frame_0")
            os.makedirs(d, exist_ok=True)
            albedo, light, normal, depth = scene(rng, args.size)
            for k in range(args.stacks):
                noise = rng.gamma(1.0, 1.0, albedo.shape)
                write_frame(os.path.join(d, f"spp4_{k:02d}.exr"), passes_for(albedo, light, normal, depth, noise))
            for tag in "ab":
                noise = rng.gamma(400.0, 1 / 400.0, albedo.shape)
                write_frame(os.path.join(d, f"gt_{tag}.exr"), passes_for(albedo, light, normal, depth, noise))
            with open(os.path.join(d, "meta.json"), "w") as fh:
                json.dump({"synthetic": True, "spp": 4, "stacks": args.stacks}, fh)


if __name__ == "__main__":
    main()
