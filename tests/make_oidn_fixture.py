#!/usr/bin/env python3
"""Makes testdata/oidn/: a crop of the example render and OIDN's own output on it.

  python3 tests/make_oidn_fixture.py [--threads N]

crop.exr      80x72 pixels at (100, 60) of testdata/example/scene000201_4spp.exr:
              the colour, Denoising Albedo and Denoising Normal channels as they are.
              80x72 is not a multiple of 16, so OIDN's padding is exercised.
crop_oidn.exr OIDN's RT filter (pyoidn, hdr mode, default quality) on the crop,
              float32, one layer per input set: hdr.{R,G,B} (colour alone),
              hdr_alb.* (+ albedo), hdr_alb_nrm.* (+ albedo + normal); and its
              prefilter mode: alb.* (the albedo denoised), nrm.* (the normal
              denoised), prefiltered.* (colour + both, with cleanAux: the
              large network).
The raw buffers go to OIDN unchanged: it sanitises them itself, as our code must.
tests/test_oidn_base.cpp compares dn's LibTorch base against this file, so CI
needs no pyoidn.
"""
import argparse
import os
import sys

import numpy as np
import OpenEXR
import pyoidn
from pyoidn.filter import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_BALANCED, OIDN_QUALITY_DEFAULT

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SOURCE = os.path.join(ROOT, "testdata", "example", "scene000201_4spp.exr")
OUT = os.path.join(ROOT, "testdata", "oidn")
X0, Y0, W, H = 100, 60, 80, 72
LAYERS = {"color": ("ViewLayer.Combined", "RGB"), "albedo": ("ViewLayer.Denoising Albedo", "RGB"),
          "normal": ("ViewLayer.Denoising Normal", "XYZ")}
SETS = {"hdr": ["color"], "hdr_alb": ["color", "albedo"], "hdr_alb_nrm": ["color", "albedo", "normal"]}


def crop_buffers():
    channels = {n: c.pixels for n, c in OpenEXR.File(SOURCE, separate_channels=True).channels().items()}
    cropped = {}
    for layer, suffixes in LAYERS.values():
        for s in suffixes:
            cropped[f"{layer}.{s}"] = np.ascontiguousarray(channels[f"{layer}.{s}"][Y0:Y0 + H, X0:X0 + W])
    return cropped


def buffer(cropped, name):
    layer, suffixes = LAYERS[name]
    return np.ascontiguousarray(np.stack([cropped[f"{layer}.{s}"].astype(np.float32) for s in suffixes], -1))


def denoise(device, images, hdr=True, clean_aux=False, quality=OIDN_QUALITY_DEFAULT):
    filt = pyoidn.Filter(device, "RT")
    filt.set_quality(quality)
    filt.set_bool("hdr", hdr)
    filt.set_bool("cleanAux", clean_aux)
    output = np.zeros_like(next(iter(images.values())))
    for name, image in list(images.items()) + [("output", output)]:
        filt.set_image(name, image, OIDN_FORMAT_FLOAT3)
    filt.commit()
    filt.execute()
    error = device.get_error()
    if error:
        sys.exit(f"make_oidn_fixture: OIDN failed: {error}")
    return output


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, default=0)
    args = parser.parse_args()
    cropped = crop_buffers()
    os.makedirs(OUT, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, dict(cropped)).write(os.path.join(OUT, "crop.exr"))
    device = pyoidn.Device()
    if args.threads > 0:
        device.set_int("numThreads", args.threads)
    device.commit()
    results = {}
    for set_name, names in SETS.items():
        out = denoise(device, {n: buffer(cropped, n) for n in names})
        for i, c in enumerate("RGB"):
            results[f"{set_name}.{c}"] = np.ascontiguousarray(out[..., i])
    # The prefilter mode: aux denoised first (balanced quality: the default-size
    # networks; the default quality would pick the large ones, which measure no
    # better), then the colour at the default quality (its large clean-aux network).
    clean = {name: denoise(device, {name: buffer(cropped, name)}, hdr=False, quality=OIDN_QUALITY_BALANCED)
             for name in ("albedo", "normal")}
    prefiltered = denoise(device, {"color": buffer(cropped, "color"), **clean}, clean_aux=True)
    for layer, out in (("alb", clean["albedo"]), ("nrm", clean["normal"]), ("prefiltered", prefiltered)):
        for i, c in enumerate("RGB"):
            results[f"{layer}.{c}"] = np.ascontiguousarray(out[..., i])
    OpenEXR.File(header, dict(results)).write(os.path.join(OUT, "crop_oidn.exr"))
    print(f"make_oidn_fixture: wrote {OUT}/crop.exr and crop_oidn.exr ")


if __name__ == "__main__":
    main()
