#!/usr/bin/env python3
"""Noisy inputs and references for the experiment, one scene per call.

  make_inputs.py scene SRC --frames frame_0 frame_1 --spps 4 16 --inputs DIR --refs DIR
      For every frame and spp N: DIR/<frame>_sppN.exr, the mean of the frame's first
      N / stack_spp stacks over EVERY channel (colour and aux buffers alike), with the
      stacks' Blender channel names and the sample count in the Cycles metadata
      (cycles.<view layer>.samples = N), so each tool reads it like a real render.
      The colour is stored as float32, other channels keep the stacks' pixel type.
      And DIR/<frame>.exr: the reference colour (gt_clean.exr if present, else the mean
      of gt_a.exr and gt_b.exr), plain float32 RGB.

  make_inputs.py tile IN.exr SIZE OUT.exr
      IN repeated (mirrored, so there are no seams) to SIZE x SIZE, or cropped when
      SIZE is smaller: an input of a chosen size for timing.
"""

import argparse
import json
import os
import sys

import numpy as np

from exrutil import ExrError, color_names, fail, read_channels, read_color, write_atomic, write_rgb


def stack_layout(frame_dir):
    """(samples per pixel of one stack, number of stacks) of a frame, from its meta.json."""
    meta_path = os.path.join(frame_dir, "meta.json")
    try:
        with open(meta_path) as f:
            meta = json.load(f)
        stack_spp, stacks = int(meta["spp"]), int(meta["stacks"])
    except (OSError, ValueError, KeyError) as error:
        raise ExrError(f"{meta_path}: cannot read spp and stacks ({error})") from error
    return stack_spp, stacks


def average_stacks(frame_dir, spp):
    stack_spp, stacks = stack_layout(frame_dir)
    if spp % stack_spp or spp // stack_spp > stacks:
        raise ExrError(f"{frame_dir}: {spp} spp needs {spp // stack_spp} stacks of {stack_spp} spp; "
                       f"the frame has {stacks}")
    paths = [os.path.join(frame_dir, f"spp{stack_spp}_{i:02d}.exr") for i in range(spp // stack_spp)]
    total, first_types, header = None, None, None
    for path in paths:
        channels, file_header = read_channels(path)
        if total is None:
            total = {n: a.astype(np.float64) for n, a in channels.items()}
            first_types = {n: a.dtype for n, a in channels.items()}
            header = file_header
            continue
        if set(channels) != set(total):
            raise ExrError(f"{path}: channels differ from {paths[0]}")
        for name, pixels in channels.items():
            if pixels.shape != total[name].shape:
                raise ExrError(f"{path}: {name} is {pixels.shape}, {paths[0]} has {total[name].shape}")
            total[name] += pixels
    color = set(color_names(total, paths[0]))
    color |= {n[:-1] + "A" for n in color if n[:-1] + "A" in total}
    averaged = {}
    for name, pixels in total.items():
        mean = pixels / len(paths)
        averaged[name] = mean.astype(np.float32 if name in color else first_types[name])
    # The mean of N/stack_spp independent renders is an N-spp render: record it
    # where Cycles does ("cycles.<view layer>.samples"), as a real render would.
    header = dict(header)
    for key in [k for k in header if k.startswith("cycles.") and k.endswith(".samples")]:
        header[key] = str(spp)
    return averaged, header


def reference(frame_dir):
    clean = os.path.join(frame_dir, "gt_clean.exr")
    if os.path.exists(clean):
        return read_color(clean)
    a = read_color(os.path.join(frame_dir, "gt_a.exr"))
    b = read_color(os.path.join(frame_dir, "gt_b.exr"))
    if a.shape != b.shape:
        raise ExrError(f"{frame_dir}: gt_a.exr and gt_b.exr differ in size")
    return (a + b) / 2


def make_scene(args):
    for frame in args.frames:
        frame_dir = os.path.join(args.src, frame)
        write_rgb(os.path.join(args.refs, f"{frame}.exr"), reference(frame_dir))
        for spp in args.spps:
            channels, header = average_stacks(frame_dir, spp)
            write_atomic(os.path.join(args.inputs, f"{frame}_spp{spp}.exr"), channels, header)


def tile(args):
    channels, header = read_channels(args.input)
    out = {}
    for name, pixels in channels.items():
        mirrored = np.concatenate([pixels, pixels[::-1]], axis=0)
        mirrored = np.concatenate([mirrored, mirrored[:, ::-1]], axis=1)
        reps = (-(-args.size // mirrored.shape[0]), -(-args.size // mirrored.shape[1]))
        out[name] = np.tile(mirrored, reps)[: args.size, : args.size]
    write_atomic(args.output, out, header)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = parser.add_subparsers(dest="verb", required=True)
    scene = verbs.add_parser("scene")
    scene.add_argument("src")
    scene.add_argument("--frames", nargs="+", required=True)
    scene.add_argument("--spps", nargs="+", type=int, required=True)
    scene.add_argument("--inputs", required=True)
    scene.add_argument("--refs", required=True)
    tiled = verbs.add_parser("tile")
    tiled.add_argument("input")
    tiled.add_argument("size", type=int)
    tiled.add_argument("output")
    args = parser.parse_args()
    try:
        make_scene(args) if args.verb == "scene" else tile(args)
    except ExrError as error:
        fail(f"make_inputs: {error}")


if __name__ == "__main__":
    sys.exit(main())
