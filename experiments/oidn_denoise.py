#!/usr/bin/env python3
"""Intel Open Image Denoise 2.x (through pyoidn) on Blender multilayer EXRs.

  oidn_denoise.py [--quality default|high|balanced|fast] [--threads N]
                  [--aux albedo,normal|albedo|none] IN.exr... -o OUT
      HDR colour (the Combined pass) + Denoising Albedo + Denoising Normal (Mitsuba:
      albedo, normals), RT filter
      (noisy auxiliary buffers, as rendered). --prefilter is OIDN's prefilter mode:
      albedo and normal denoised first (balanced quality: the default-size
      networks), then the colour with cleanAux (the large network at the default
      quality). --aux gives OIDN fewer buffers:
      colour + albedo, or colour alone, and OIDN picks its network for that set.
      OUT is a file for one input, or a folder (ending in /) for several: the
      results keep the inputs' file names. Each result is plain float32 RGB.
"""

import argparse
import os
import sys

import numpy as np
import pyoidn
from pyoidn.filter import (OIDN_FORMAT_FLOAT3, OIDN_QUALITY_BALANCED, OIDN_QUALITY_DEFAULT,
                           OIDN_QUALITY_FAST, OIDN_QUALITY_HIGH)

from exrutil import ExrError, color_names, fail, find_channels, read_channels, write_rgb

QUALITIES = {"default": OIDN_QUALITY_DEFAULT, "high": OIDN_QUALITY_HIGH,
             "balanced": OIDN_QUALITY_BALANCED, "fast": OIDN_QUALITY_FAST}


def first_found(channels, layers, suffixes, path):
    """Blender's layer names, else Mitsuba's AOV names (experiments/render_mitsuba.py)."""
    for layer in layers[:-1]:
        try:
            return find_channels(channels, layer, suffixes, path)
        except ExrError:
            pass
    return find_channels(channels, layers[-1], suffixes, path)


def load_buffers(path):
    """Colour (finite, >= 0), albedo in [0, 1] and normals in [-1, 1], float32 (H, W, 3)."""
    channels, _ = read_channels(path)
    color = np.stack([channels[n].astype(np.float32) for n in color_names(channels, path)], axis=-1)
    color = np.nan_to_num(color, nan=0.0, posinf=0.0, neginf=0.0).clip(min=0.0)
    albedo = first_found(channels, ("Denoising Albedo", "albedo"), "RGB", path).clip(0.0, 1.0)
    normal = first_found(channels, ("Denoising Normal", "normals"), "XYZ", path).clip(-1.0, 1.0)
    return [np.ascontiguousarray(a) for a in (color, albedo, normal)]


class Denoiser:
    """One OIDN device and RT filter, reused for every image."""

    def __init__(self, quality, threads):
        self.device = pyoidn.Device()
        if threads > 0:
            self.device.set_int("numThreads", threads)
        self.device.commit()
        self.check("device creation")
        self.filter = pyoidn.Filter(self.device, "RT")
        self.filter.set_bool("hdr", True)
        self.filter.set_quality(QUALITIES[quality])

    def check(self, what):
        error = self.device.get_error()
        if error:
            raise RuntimeError(f"OIDN {what} failed: {error}")

    def prefilter(self, name, image):
        """The albedo or normal (name) denoised by OIDN's own network for it."""
        aux_filter = pyoidn.Filter(self.device, "RT")
        aux_filter.set_quality(OIDN_QUALITY_BALANCED)
        output = np.empty_like(image)
        aux_filter.set_image(name, image, OIDN_FORMAT_FLOAT3)
        aux_filter.set_image("output", output, OIDN_FORMAT_FLOAT3)
        aux_filter.commit()
        aux_filter.execute()
        self.check("aux prefiltering")
        return output

    def run(self, color, albedo, normal, aux=("albedo", "normal"), prefilter=False):
        output = np.empty_like(color)
        self.filter.set_bool("cleanAux", prefilter)
        if prefilter:
            albedo = self.prefilter("albedo", albedo)
            normal = self.prefilter("normal", normal)
        images = {"color": color, "albedo": albedo, "normal": normal}
        for name in ("albedo", "normal"):
            if name not in aux:
                self.filter.unset_image(name)
        for name in ["color"] + list(aux) + ["output"]:
            self.filter.set_image(name, output if name == "output" else images[name], OIDN_FORMAT_FLOAT3)
        self.filter.commit()
        self.filter.execute()
        self.check("filter execution")
        return output


def output_paths(inputs, output):
    if output.endswith("/"):
        return [os.path.join(output, os.path.basename(p)) for p in inputs]
    if len(inputs) != 1:
        fail(f"oidn_denoise: {len(inputs)} inputs need an output folder ending in '/', not {output}")
    return [output]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="+")
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--quality", choices=sorted(QUALITIES), default="default")
    parser.add_argument("--threads", type=int, default=0, help="0: all cores (OIDN's default)")
    parser.add_argument("--aux", choices=["albedo,normal", "albedo", "none"], default="albedo,normal",
                        help="auxiliary buffers given to OIDN (default: albedo,normal)")
    parser.add_argument("--prefilter", action="store_true",
                        help="denoise albedo and normal first, then the colour with cleanAux")
    args = parser.parse_args()
    if args.prefilter and args.aux != "albedo,normal":
        parser.error("--prefilter needs --aux albedo,normal")
    outputs = output_paths(args.inputs, args.output)
    denoiser = Denoiser(args.quality, args.threads)
    for source, target in zip(args.inputs, outputs):
        if os.path.abspath(source) == os.path.abspath(target):
            fail(f"oidn_denoise: {target}: the output would replace the input")
        try:
            aux = () if args.aux == "none" else tuple(args.aux.split(","))
            write_rgb(target, denoiser.run(*load_buffers(source), aux=aux, prefilter=args.prefilter))
        except (ExrError, RuntimeError) as error:
            fail(f"oidn_denoise: {error}")


if __name__ == "__main__":
    sys.exit(main())
