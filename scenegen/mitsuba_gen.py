#!/usr/bin/env python3
"""Training frames rendered by Mitsuba 3, whose pixel filters splat samples (docs/dataset.md).

Random scenes of its own (none of experiments/render_mitsuba.py's evaluation
scenes) in the data-set layout that libdenoise's loader reads:
DIR/<split>/scene_<seed:06d>/frame_<k>/spp<SPP>_<ii>.exr, gt_a.exr, gt_b.exr,
meta.json (written last). Each scene draws its pixel filter from --filters;
Mitsuba's default, a Gaussian of stddev 0.5 px, splats every sample over 4x4
pixels and so correlates the noise of neighbouring pixels (issue 23).

  /work/venv-render/bin/python scenegen/mitsuba_gen.py --out DATA --scenes 200 \
      --filters gaussian:0.7,box:0.2,tent:0.1 --shard 0/1

Runs under experiments/setup_renderers.sh's venv (mitsuba, numpy, OpenEXR).
The llvm_ad_rgb variant (1.8x the speed of scalar_rgb here) needs LLVM >= 17
(Debian: libllvm19); --variant auto falls back to scalar_rgb without it.
"""

import argparse
import glob
import hashlib
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from make_dataset import Progress, format_seconds, parse_shard, split_of, write_json_atomic  # noqa: E402

GENERATOR_VERSION = "mitsuba-1.0.0"
ARCHETYPES = ("room", "env_ground", "glass_emitters", "night")
# Filters as Mitsuba ships them (its defaults: gaussian stddev 0.5 px, tent radius 1 px).
FILTERS = {"gaussian": {"type": "gaussian", "stddev": 0.5},
           "box": {"type": "box"},
           "tent": {"type": "tent", "radius": 1.0}}
# HDRIs of the bpy wheel's studiolights; sunset.exr is left out: the evaluation scenes use it.
HDRIS = ("city.exr", "courtyard.exr", "forest.exr", "interior.exr", "night.exr", "studio.exr", "sunrise.exr")
METALS = ("Au", "Ag", "Cu", "Al", "Cr")
AOVS = "albedo:albedo,normals:sh_normal,depth:depth"
GT_CHUNK_SPP = 64  # ground truth is the mean of renders of this many spp (bounds llvm memory)
LLVM_CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
                   "/usr/lib/x86_64-linux-gnu/libLLVM-18.so", "/usr/lib/x86_64-linux-gnu/libLLVM-17.so")
HALF_MAX = 65504.0
VISIBLE_RADIANCE_CAP = 30000.0  # after exposure: directly seen emitters stay finite in half floats

mi = None  # mitsuba, imported once the variant is chosen
dr = None


# ------------------------------------------------------------------ arguments


def parse_filters(text):
    mix = {}
    for item in text.split(","):
        name, _, weight = item.partition(":")
        if name not in FILTERS:
            raise argparse.ArgumentTypeError("--filters: unknown filter %r (known: %s)" % (name, ", ".join(FILTERS)))
        try:
            mix[name] = float(weight) if weight else 1.0
        except ValueError:
            raise argparse.ArgumentTypeError("--filters: weight of %s is not a number: %r" % (name, weight))
    if sum(mix.values()) <= 0 or min(mix.values()) < 0:
        raise argparse.ArgumentTypeError("--filters: weights must be >= 0 and not all 0")
    return mix


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--scenes", type=int, default=10)
    p.add_argument("--first-seed", type=int, default=100000,
                   help="seeds of their own (the Blender set uses 0..); split by seed as make_dataset.py")
    p.add_argument("--seeds", default="", help="comma list of seeds; replaces --scenes/--first-seed")
    p.add_argument("--frames", type=int, default=2, help="camera poses per scene")
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--stacks", type=int, default=16)
    p.add_argument("--gt-spp", type=int, default=256, help="spp of each of gt_a and gt_b")
    p.add_argument("--filters", type=parse_filters, default=parse_filters("gaussian:0.7,box:0.2,tent:0.1"),
                   help="pixel filter mix NAME:WEIGHT,... of %s" % ", ".join(FILTERS))
    p.add_argument("--max-gt-relmse", type=float, default=0.1,
                   help="drop frames whose gt_a and gt_b differ more (relMSE without the 16 largest "
                        "per-pixel errors): ground truth that did not converge")
    p.add_argument("--all-train", action="store_true", help="every scene in train/ instead of the seed split")
    p.add_argument("--shard", type=parse_shard, default=(0, 1))
    p.add_argument("--threads", type=int, default=1, help="render threads (scene loading uses 2, see load_scene)")
    p.add_argument("--variant", choices=("auto", "llvm_ad_rgb", "scalar_rgb"), default="auto")
    args = p.parse_args(argv)
    args.seed_list = [int(x) for x in args.seeds.split(",") if x.strip()] if args.seeds else \
        list(range(args.first_seed, args.first_seed + args.scenes))
    if min(len(args.seed_list), args.frames, args.res, args.spp, args.stacks, args.gt_spp, args.threads) < 1:
        p.error("--scenes, --frames, --res, --spp, --stacks, --gt-spp and --threads must be positive")
    return args


def choose_variant(name):
    """llvm_ad_rgb when an LLVM that Dr.Jit can use is installed, else scalar_rgb."""
    global mi, dr
    if name in ("auto", "llvm_ad_rgb") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        found = [p for p in LLVM_CANDIDATES if os.path.exists(p)]
        if found:
            os.environ["DRJIT_LIBLLVM_PATH"] = found[0]
        elif name == "llvm_ad_rgb":
            sys.exit("mitsuba_gen.py: llvm_ad_rgb needs LLVM >= 17 (apt-get install libllvm19)")
        else:
            name = "scalar_rgb"
    import mitsuba
    import drjit
    mi, dr = mitsuba, drjit
    name = "llvm_ad_rgb" if name == "auto" else name
    mi.set_variant(name)
    return name


# ------------------------------------------------------------------ resources


_cache = {}


class pool_of_two:
    """Mitsuba 3.9 hangs reading an EXR (a file, or an envmap's) with a thread pool of one:
    files are read and scenes loaded with two threads, renders use --threads."""

    def __enter__(self):
        self.threads = dr.thread_count()
        dr.set_thread_count(2)

    def __exit__(self, *exc):
        dr.set_thread_count(self.threads)


def studiolight_dir():
    import importlib.util
    spec = importlib.util.find_spec("bpy")
    roots = glob.glob(os.path.join(os.path.dirname(spec.origin), "*", "datafiles", "studiolights", "world")) \
        if spec and spec.origin else []
    if not roots:
        sys.exit("mitsuba_gen.py: the HDRIs come from the bpy wheel; run experiments/setup_renderers.sh")
    return roots[0]


def hdri(name):
    """An HDRI as an RGB float bitmap, negative values (in some of the EXRs) clamped to 0."""
    if name not in _cache:
        with pool_of_two():
            pixels = np.array(mi.Bitmap(os.path.join(studiolight_dir(), name)), dtype=np.float32)[..., :3]
        _cache[name] = np.ascontiguousarray(np.maximum(pixels, 0.0))
    return _cache[name]


def photos():
    """mate-backgrounds' pictures, each once (not the larger copies named NAME_WxH)."""
    if "photos" not in _cache:
        files = glob.glob("/usr/share/backgrounds/mate/*/*.jpg") + glob.glob("/usr/share/backgrounds/mate/*/*.png")
        _cache["photos"] = sorted(f for f in files if not re.search(r"_\d+x\d+\.", f))
    return _cache["photos"]


def photo(path):
    """A photograph as a linear RGB bitmap at most 512 px wide (decoded once per process)."""
    if path not in _cache:
        with pool_of_two():
            bmp = mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
        w, h = bmp.size()
        scale = min(1.0, 512.0 / max(w, h))
        small = bmp.resample([max(8, int(w * scale)), max(8, int(h * scale))])
        _cache[path] = np.clip(np.array(small, dtype=np.float32), 0, 1)  # resampling overshoots a little
    return mi.Bitmap(_cache[path])


def sky_bitmap(rng):
    """A procedural lat-long sky: zenith to horizon gradient, darker ground, optional sun spot."""
    h, w = 128, 256
    elevation = (0.5 - (np.arange(h) + 0.5) / h) * math.pi
    zenith = rng.uniform([0.05, 0.15, 0.4], [0.3, 0.5, 1.2])
    horizon = rng.uniform([0.5, 0.5, 0.5], [1.3, 1.1, 1.2])
    ground = rng.uniform(0.05, 0.35, 3) * rng.uniform(0.3, 1.0)
    t = np.clip(np.sin(elevation), 0, 1) ** rng.uniform(0.3, 0.8)
    rows = np.where(elevation[:, None] > 0, horizon * (1 - t[:, None]) + zenith * t[:, None], ground)
    sky = np.repeat(rows[:, None, :], w, axis=1).astype(np.float32)
    sun = None
    if rng.uniform() < 0.6:
        el, az = rng.uniform(0.1, 1.2), rng.uniform(0, 2 * math.pi)
        sun = (el, az)
        v = np.clip(int((0.5 - el / math.pi) * h), 0, h - 1)
        u = int(az / (2 * math.pi) * w) % w
        sky[max(0, v - 1):v + 1, max(0, u - 1):u + 1] += np.float32(rng.uniform(200, 2000))
    return np.ascontiguousarray(sky), sun


# ------------------------------------------------------------------ scene pieces


def rgb(v):
    return {"type": "rgb", "value": [float(x) for x in v]}


def colour(rng, lo=0.05, hi=0.85):
    return rng.uniform(lo, hi, 3)


def reflectance(rng, desc, allow_texture=True):
    """A constant colour, a checkerboard or a photograph."""
    u = rng.uniform() if allow_texture else 0.0
    if u < 0.2:
        desc["texture"] = "checkerboard"
        return {"type": "checkerboard", "color0": rgb(colour(rng)), "color1": rgb(colour(rng)),
                "to_uv": mi.ScalarTransform4f().scale([float(rng.integers(2, 16))] * 2 + [1])}
    if u < 0.45 and photos():
        path = photos()[rng.integers(len(photos()))]
        desc["texture"] = "photo:" + os.path.basename(path)
        return {"type": "bitmap", "bitmap": photo(path), "filter_type": "bilinear",
                "to_uv": mi.ScalarTransform4f().scale([float(rng.uniform(0.5, 3))] * 2 + [1])}
    c = colour(rng)
    desc["texture"] = "constant"
    return rgb(c)


def material(rng, desc, kinds=None):
    kinds = kinds or ("diffuse", "diffuse", "plastic", "roughplastic", "conductor", "roughconductor",
                      "dielectric", "roughdielectric")
    kind = kinds[rng.integers(len(kinds))]
    desc["material"] = kind
    if kind == "diffuse":
        bsdf = {"type": "diffuse", "reflectance": reflectance(rng, desc)}
    elif kind in ("plastic", "roughplastic"):
        bsdf = {"type": kind, "diffuse_reflectance": reflectance(rng, desc), "int_ior": float(rng.uniform(1.4, 1.6))}
        if kind == "roughplastic":
            bsdf["alpha"] = desc["alpha"] = float(rng.uniform(0.03, 0.4))
    elif kind in ("conductor", "roughconductor"):
        desc["metal"] = METALS[rng.integers(len(METALS))]
        bsdf = {"type": kind, "material": desc["metal"]}
        if kind == "roughconductor":
            bsdf["alpha"] = desc["alpha"] = float(rng.uniform(0.02, 0.4))
    else:
        bsdf = {"type": kind, "int_ior": float(rng.uniform(1.33, 1.7))}
        if rng.uniform() < 0.3:
            bsdf["specular_transmittance"] = rgb(rng.uniform(0.5, 1.0, 3))
        if kind == "roughdielectric":
            bsdf["alpha"] = desc["alpha"] = float(rng.uniform(0.03, 0.3))
        return bsdf
    return {"type": "twosided", "bsdf": bsdf}


def transform(center, scale, rotate_y=0.0, rotate_x=0.0):
    return (mi.ScalarTransform4f().translate([float(c) for c in center]).rotate([0, 1, 0], float(rotate_y))
            .rotate([1, 0, 0], float(rotate_x)).scale([float(s) for s in scale]))


def write_obj(path, vertices, faces):
    with open(path, "w") as f:
        f.writelines("v %.6f %.6f %.6f\n" % tuple(v) for v in vertices)
        f.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in faces)


def grid_faces(rows, cols, wrap_cols=True):
    faces = []
    for i in range(rows - 1):
        for j in range(cols if wrap_cols else cols - 1):
            a, b = i * cols + j, i * cols + (j + 1) % cols
            c, d = a + cols, b + cols
            faces += [(a, c, b), (b, c, d)]
    return faces


def torus_mesh(path, rng):
    major, minor = 1.0, float(rng.uniform(0.15, 0.45))
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 32, endpoint=False), np.linspace(0, 2 * np.pi, 17))
    r = major + minor * np.cos(v)
    verts = np.stack([r * np.cos(u), minor * np.sin(v), r * np.sin(u)], -1).reshape(-1, 3)
    write_obj(path, verts, grid_faces(17, 32))


def vase_mesh(path, rng):
    """A lathed profile (vase, bowl, cup): radius varies with height, open top."""
    h = np.linspace(0, 1, 24)
    k = rng.uniform(0.5, 3.0, 3)
    radius = 0.25 + 0.2 * np.sin(np.pi * h * k[0] + k[1]) ** 2 + 0.1 * h * k[2]
    u = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    verts = np.stack([radius[:, None] * np.cos(u), np.repeat(h[:, None], 32, 1), radius[:, None] * np.sin(u)],
                     -1).reshape(-1, 3)
    write_obj(path, verts, grid_faces(24, 32))


def add_object(scene, descs, rng, name, pos, size, tmpdir, kinds=None):
    """One object of a random shape standing on the ground at pos (x, z)."""
    desc = {"name": name}
    bsdf = material(rng, desc, kinds)
    shapes = ("sphere", "cube", "cylinder", "disk", "rectangle", "torus", "vase")
    shape = shapes[rng.integers(len(shapes))]
    desc["shape"] = shape
    x, z = pos
    rot = rng.uniform(0, 360)
    if shape == "sphere":
        scene[name] = {"type": "sphere", "center": [x, size, z], "radius": size, "bsdf": bsdf}
    elif shape == "cube":
        half = size * rng.uniform(0.5, 1.0, 3)
        scene[name] = {"type": "cube", "to_world": transform((x, half[1], z), half, rot), "bsdf": bsdf}
    elif shape == "cylinder":
        height, radius = size * rng.uniform(1, 3), size * rng.uniform(0.2, 0.7)
        scene[name] = {"type": "cylinder", "p0": [x, 0, z], "p1": [x, height, z], "radius": radius, "bsdf": bsdf}
        scene[name + "_cap"] = {"type": "disk", "bsdf": bsdf,
                                "to_world": transform((x, height, z), (radius, radius, 1), 0, -90)}
    elif shape == "disk":  # a standing round panel
        scene[name] = {"type": "disk", "to_world": transform((x, size, z), (size, size, 1), rot), "bsdf": bsdf}
    elif shape == "rectangle":  # a standing panel (a picture, a card)
        half = size * rng.uniform(0.5, 1.2, 2)
        scene[name] = {"type": "rectangle", "to_world": transform((x, half[1], z), (half[0], half[1], 1), rot),
                       "bsdf": bsdf}
    else:
        path = os.path.join(tmpdir, "%s.obj" % name)
        (torus_mesh if shape == "torus" else vase_mesh)(path, rng)
        if shape == "torus":
            to_world = transform((x, size * 0.5, z), (size, size, size), rot, rng.uniform(0, 90))
        else:
            to_world = transform((x, 0, z), (size * 1.5, size * 2.5, size * 1.5), rot)
        scene[name] = {"type": "obj", "filename": path, "to_world": to_world, "bsdf": bsdf, "face_normals": False}
    descs.append(desc)


def place_objects(scene, descs, rng, count, radius, tmpdir, kinds=None, size=(0.15, 0.6)):
    """count objects on the ground within radius of the origin, not overlapping (as circles)."""
    placed = []
    for i in range(count):
        for _ in range(30):
            s = rng.uniform(*size)
            p = rng.uniform(-radius, radius, 2)
            if all(np.hypot(*(p - q)) > s + t + 0.05 for q, t in placed):
                placed.append((p, s))
                add_object(scene, descs, rng, "obj%d" % i, p, s, tmpdir, kinds)
                break
    return placed


def ground(scene, descs, rng, half_size, kinds=("diffuse", "diffuse", "roughplastic", "plastic")):
    desc = {"name": "ground", "shape": "rectangle"}
    scene["ground"] = {"type": "rectangle", "bsdf": material(rng, desc, kinds),
                       "to_world": transform((0, 0, 0), (half_size, half_size, 1), 0, -90)}
    descs.append(desc)


def area_radiance(rng, lo, hi):
    tint = np.array([1.0, rng.uniform(0.75, 1.0), rng.uniform(0.5, 1.0)])
    return tint * float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


# ------------------------------------------------------------------ archetypes


def arch_room(rng, scene, d, tmpdir):
    w, depth, h = rng.uniform(4, 8), rng.uniform(4, 8), rng.uniform(2.5, 3.5)
    wall = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": rgb(colour(rng, 0.3, 0.85))}}
    ground(scene, d["objects"], rng, max(w, depth) / 2)
    scene["ceiling"] = {"type": "rectangle", "bsdf": wall,
                        "to_world": transform((0, h, 0), (w / 2, depth / 2, 1), 0, 90)}
    for name, c, s, ry in (("wall_n", (0, h / 2, -depth / 2), (w / 2, h / 2, 1), 0),
                           ("wall_s", (0, h / 2, depth / 2), (w / 2, h / 2, 1), 180),
                           ("wall_w", (-w / 2, h / 2, 0), (depth / 2, h / 2, 1), 90),
                           ("wall_e", (w / 2, h / 2, 0), (depth / 2, h / 2, 1), -90)):
        scene[name] = {"type": "rectangle", "bsdf": wall, "to_world": transform(c, s, ry)}
    lights = []
    for i in range(rng.integers(1, 4)):
        rad = area_radiance(rng, 3, 40)
        size = rng.uniform(0.2, 0.8, 2)
        c = (rng.uniform(-w / 3, w / 3), h - 0.01, rng.uniform(-depth / 3, depth / 3))
        scene["light%d" % i] = {"type": "rectangle", "to_world": transform(c, (size[0], size[1], 1), 0, 90),
                                "emitter": {"type": "area", "radiance": rgb(rad)},
                                "bsdf": {"type": "diffuse", "reflectance": rgb((0, 0, 0))}}
        lights.append({"kind": "area", "radiance": rad.tolist(), "size": size.tolist()})
    d["lights"] = lights
    d["visible_radiance"] = max(max(l["radiance"]) for l in lights)
    placed = place_objects(scene, d["objects"], rng, rng.integers(2, 7), min(w, depth) / 4, tmpdir)
    r = min(w, depth) / 2 - 0.3
    return {"keep_out": placed, "target": (0, rng.uniform(0.3, 0.9), 0), "distance": (1.5, max(1.6, r)),
            "elevation": (5, 35), "height_max": h - 0.2}


def environment(rng, scene, d, strength=(0.5, 2.0)):
    """An HDRI (not the evaluation scenes') or a procedural sky, randomly rotated."""
    scale = float(np.exp(rng.uniform(*np.log(strength))))
    rot = float(rng.uniform(0, 360))
    if rng.uniform() < 0.6:
        name = HDRIS[rng.integers(len(HDRIS))]
        pixels = hdri(name)
        d["world"] = {"kind": "hdri", "name": name, "scale": scale, "rotate": rot}
    else:
        pixels, sun = sky_bitmap(rng)
        d["world"] = {"kind": "sky", "sun": sun, "scale": scale, "rotate": rot}
    scene["env"] = {"type": "envmap", "bitmap": mi.Bitmap(pixels), "scale": scale,
                    "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], rot)}
    return float(pixels.max()) * scale


def arch_env_ground(rng, scene, d, tmpdir):
    d["visible_radiance"] = environment(rng, scene, d)
    d["lights"] = []
    if rng.uniform() < 0.3:
        rad = area_radiance(rng, 5, 50)
        c = (rng.uniform(-2, 2), rng.uniform(1.5, 3), rng.uniform(-2, 2))
        scene["light0"] = {"type": "sphere", "center": list(c), "radius": float(rng.uniform(0.05, 0.3)),
                           "emitter": {"type": "area", "radiance": rgb(rad)}}
        d["lights"].append({"kind": "sphere", "radiance": rad.tolist()})
        d["visible_radiance"] = max(d["visible_radiance"], float(rad.max()))
    ground(scene, d["objects"], rng, 30)
    placed = place_objects(scene, d["objects"], rng, rng.integers(3, 9), 1.8, tmpdir)
    return {"keep_out": placed, "target": (0, rng.uniform(0.2, 0.8), 0), "distance": (2.5, 6), "elevation": (5, 50)}


def arch_glass_emitters(rng, scene, d, tmpdir):
    if rng.uniform() < 0.5:
        d["visible_radiance"] = environment(rng, scene, d, (0.02, 0.3))
    else:
        level = float(rng.uniform(0.0, 0.03))
        scene["env"] = {"type": "constant", "radiance": rgb((level, level, level * 1.2))}
        d["world"] = {"kind": "constant", "radiance": level}
        d["visible_radiance"] = level
    ground(scene, d["objects"], rng, 20)
    if rng.uniform() < 0.5:
        scene["backdrop"] = {"type": "rectangle", "bsdf": material(rng, {}, ("diffuse",)),
                             "to_world": transform((0, 2, -2.5), (5, 2, 1))}
    placed = place_objects(scene, d["objects"], rng, rng.integers(2, 6), 1.3, tmpdir,
                           ("dielectric", "dielectric", "roughdielectric", "conductor", "roughconductor"))
    d["lights"] = []
    for i in range(rng.integers(2, 7)):
        rad = area_radiance(rng, 50, 2000)
        if placed and rng.uniform() < 0.5:  # inside or just beside a glass object
            p, s = placed[rng.integers(len(placed))]
            c = (p[0] + rng.uniform(-0.3, 0.3) * s, s * rng.uniform(0.5, 1.5), p[1] + rng.uniform(-0.3, 0.3) * s)
        else:
            c = (rng.uniform(-1.5, 1.5), rng.uniform(0.1, 1.5), rng.uniform(-1.5, 1.5))
        scene["lamp%d" % i] = {"type": "sphere", "center": [float(x) for x in c],
                               "radius": float(rng.uniform(0.005, 0.03)),
                               "emitter": {"type": "area", "radiance": rgb(rad)}}
        d["lights"].append({"kind": "small sphere", "radiance": rad.tolist()})
        d["visible_radiance"] = max(d["visible_radiance"], float(rad.max()))
    return {"keep_out": placed, "target": (0, rng.uniform(0.2, 0.6), 0), "distance": (2, 4.5), "elevation": (5, 40)}


def arch_night(rng, scene, d, tmpdir):
    level = float(rng.uniform(0.001, 0.02))
    scene["env"] = {"type": "constant", "radiance": rgb((level * 0.5, level * 0.7, level * 1.3))}
    d["world"] = {"kind": "night", "radiance": level}
    ground(scene, d["objects"], rng, 30, ("roughplastic", "plastic", "diffuse"))
    placed = place_objects(scene, d["objects"], rng, rng.integers(3, 8), 2.0, tmpdir)
    d["lights"] = []
    d["visible_radiance"] = level
    pole = {"type": "roughconductor", "material": "Al", "alpha": 0.2}
    for i in range(rng.integers(1, 5)):
        x, z, h = rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(2, 4)
        intensity = area_radiance(rng, 3, 60)
        if rng.uniform() < 0.5:
            scene["light%d" % i] = {"type": "point", "position": [float(x), float(h), float(z)],
                                    "intensity": rgb(intensity)}
            kind = "point"
        else:
            scene["light%d" % i] = {"type": "spot", "intensity": rgb(intensity * 3),
                                    "cutoff_angle": float(rng.uniform(20, 50)),
                                    "to_world": mi.ScalarTransform4f().look_at(
                                        origin=[float(x), float(h), float(z)],
                                        target=[float(x + rng.uniform(-1, 1)), 0.0, float(z + rng.uniform(-1, 1))],
                                        up=[0, 0, 1])}
            kind = "spot"
        scene["pole%d" % i] = {"type": "cylinder", "p0": [float(x), 0, float(z)], "p1": [float(x), float(h) - 0.15,
                                                                                        float(z)],
                               "radius": 0.04, "bsdf": pole}
        d["lights"].append({"kind": kind, "intensity": intensity.tolist(), "height": float(h)})
    if rng.uniform() < 0.5:
        rad = area_radiance(rng, 20, 300)
        scene["glow"] = {"type": "sphere", "center": [float(rng.uniform(-2, 2)), float(rng.uniform(0.1, 1)),
                                                      float(rng.uniform(-2, 2))],
                         "radius": float(rng.uniform(0.03, 0.1)), "emitter": {"type": "area", "radiance": rgb(rad)}}
        d["lights"].append({"kind": "emissive sphere", "radiance": rad.tolist()})
        d["visible_radiance"] = max(d["visible_radiance"], float(rad.max()))
    return {"keep_out": placed, "target": (0, rng.uniform(0.3, 1.0), 0), "distance": (3, 7), "elevation": (5, 35)}


def camera_poses(rng, cam, frames):
    """A start pose around the target and an orbit/dolly move over the frames, drawn again (up to 50
    times) while a position is within 0.4 m of an object's footprint."""
    for _ in range(50):
        poses = draw_move(rng, cam, frames)
        if all(np.hypot(pose["origin"][0] - p[0], pose["origin"][2] - p[1]) > s * 1.6 + 0.4
               for pose in poses for p, s in cam["keep_out"]):
            break
    return poses


def draw_move(rng, cam, frames):
    az0 = rng.uniform(0, 360)
    el = rng.uniform(*cam["elevation"])
    dist0 = rng.uniform(*cam["distance"])
    step_az, step_dist = rng.uniform(-8, 8), rng.uniform(-0.15, 0.15) * dist0
    fov = float(rng.uniform(30, 65))
    target = np.array(cam["target"], dtype=float)
    poses = []
    for k in range(frames):
        az = math.radians(az0 + step_az * k)
        dist = max(cam["distance"][0] * 0.8, dist0 + step_dist * k)
        e = math.radians(el)
        origin = target + dist * np.array([math.cos(e) * math.sin(az), math.sin(e), math.cos(e) * math.cos(az)])
        origin[1] = min(origin[1], cam.get("height_max", 1e9))
        poses.append({"origin": origin.tolist(), "target": target.tolist(), "up": [0, 1, 0], "fov": fov})
    return poses


def build_scene(seed, frames, filters, tmpdir):
    """The scene dict (without sensor and integrator), its description and camera poses."""
    rng = np.random.default_rng([seed, 0])
    arch = ARCHETYPES[rng.integers(len(ARCHETYPES))]
    d = {"seed": seed, "archetype": arch, "objects": []}
    scene = {"type": "scene"}
    cam = globals()["arch_" + arch](rng, scene, d, tmpdir)
    d["poses"] = camera_poses(rng, cam, frames)
    frng = np.random.default_rng([seed, 1])  # the filter has its own stream: the mix does not change scenes
    names = sorted(filters)
    weights = np.array([filters[n] for n in names], dtype=float)
    d["filter"] = names[frng.choice(len(names), p=weights / weights.sum())]
    lights = {l["kind"] for l in d["lights"]}
    world = d.get("world", {}).get("kind", "room")
    d["lighting"] = world + ("+lamps" if lights and world != "room" else "")
    return scene, d


def load_scene(scene, pose, res, filter_name):
    scene = dict(scene)
    scene["integrator"] = {"type": "aov", "aovs": AOVS, "integrator": {"type": "path"}}
    scene["sensor"] = {"type": "perspective", "fov": pose["fov"],
                       "to_world": mi.ScalarTransform4f().look_at(origin=pose["origin"], target=pose["target"],
                                                                  up=pose["up"]),
                       "sampler": {"type": "independent"},
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": FILTERS[filter_name]}}
    with pool_of_two():
        return mi.load_dict(scene)


# ------------------------------------------------------------------ rendering


def render_seed(seed, frame, name, tag=""):
    return int(hashlib.sha256(("mitsuba:%d:%d:%s:%s" % (seed, frame, name, tag)).encode()).hexdigest()[:8], 16) >> 1


def render_buffers(scene, spp, seed):
    """(colour, albedo, world normal, depth) as float32 arrays, the mean of chunks of GT_CHUNK_SPP."""
    chunks = [GT_CHUNK_SPP] * (spp // GT_CHUNK_SPP) + ([spp % GT_CHUNK_SPP] if spp % GT_CHUNK_SPP else [])
    total = None
    for i, n in enumerate(chunks):
        mi.render(scene, spp=n, seed=(seed + 7919 * i) & 0x7FFFFFFF)
        bmp = scene.sensors()[0].film().bitmap(raw=False)
        struct = bmp.struct_()
        names = [struct[j].name for j in range(len(struct))]
        pixels = np.array(bmp, dtype=np.float64)
        pick = lambda chans: pixels[..., [names.index(c) for c in chans]]  # noqa: E731
        parts = np.concatenate([pick(["R", "G", "B"]), pick(["albedo.R", "albedo.G", "albedo.B"]),
                                pick(["normals.X", "normals.Y", "normals.Z"]), pick(["depth.T"])], -1)
        total = parts * n if total is None else total + parts * n
    total /= spp
    return total[..., 0:3], total[..., 3:6], total[..., 6:9], total[..., 9]


def camera_space(normals, pose):
    """World normals in the camera frame that Cycles' Denoising Normal uses: x right, y up, z forward."""
    origin, target, up = (np.array(pose[k], dtype=float) for k in ("origin", "target", "up"))
    forward = (target - origin) / np.linalg.norm(target - origin)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    return normals @ np.stack([right, true_up, forward], 1)


def write_exr(path, buffers, exposure, pose, half_colour):
    """Colour (R,G,B, after exposure), albedo.*, Denoising Normal.* (camera space), normals.* (world), depth.T."""
    import OpenEXR
    colour, albedo, normal, depth = buffers
    colour = np.minimum(colour * exposure, HALF_MAX) if half_colour else colour * exposure
    cdtype = np.float16 if half_colour else np.float32
    channels = {}
    for i, c in enumerate("RGB"):
        channels[c] = colour[..., i].astype(cdtype)
        channels["albedo." + c] = albedo[..., i].astype(cdtype)
    cam = camera_space(normal, pose)
    for i, c in enumerate("XYZ"):
        channels["Denoising Normal." + c] = cam[..., i].astype(np.float32)
        channels["normals." + c] = normal[..., i].astype(np.float32)
    channels["depth.T"] = depth.astype(np.float32)
    channels = {k: np.ascontiguousarray(v) for k, v in channels.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    tmp = "%s.tmp%d" % (path, os.getpid())
    try:
        OpenEXR.File(header, channels).write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def exposure_for(scene, d, pose_seed):
    """Scale s with mean(min(s * luminance, 6)) = goal (log-uniform in [0.05, 0.6]) on a 4-spp probe,
    lowered so that emitters seen directly stay below VISIBLE_RADIANCE_CAP."""
    colour = render_buffers(scene, 4, pose_seed)[0]
    lum = colour @ np.array([0.2126, 0.7152, 0.0722])
    goal = float(np.exp(np.random.default_rng([d["seed"], 2]).uniform(np.log(0.05), np.log(0.6))))
    lo, hi = 1e-6, 1e6
    for _ in range(100):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if np.minimum(mid * lum, 6).mean() < goal else (lo, mid)
    s = math.sqrt(lo * hi)
    cap = VISIBLE_RADIANCE_CAP / max(d["visible_radiance"], 1e-6)
    d["exposure"] = {"goal": goal, "probe_scale": s, "cap": cap}
    return min(s, cap)


def gt_rel_mse(fdir, trim=16):
    """relMSE of gt_a's colour against gt_b's, mean((a - b)^2 / (b^2 + 0.01)), without the `trim`
    largest per-pixel errors (as scenegen/mitsuba_noise.py reports it)."""
    import OpenEXR
    a, b = (OpenEXR.File(os.path.join(fdir, n)).channels()["RGB"].pixels.astype(np.float64)
            for n in ("gt_a.exr", "gt_b.exr"))
    per_pixel = np.sort(np.mean((a - b) ** 2 / (b * b + 0.01), axis=-1).ravel())
    return float(per_pixel[:per_pixel.size - trim].mean())


def reject(fdir, files, value, limit):
    """Drops a frame whose two ground truths disagree (light a path tracer does not converge,
    such as caustics of tiny emitters seen through glass): meta.json goes first so that no
    reader sees a frame without its files; rejected.json makes resumed runs skip it."""
    for name in ["meta.json"] + list(files):
        if os.path.exists(os.path.join(fdir, name)):
            os.remove(os.path.join(fdir, name))
    write_json_atomic(os.path.join(fdir, "rejected.json"),
                      {"gt_relmse_trim16": value, "limit": limit,
                       "reason": "gt_a and gt_b disagree: the ground truth is not converged"})


def frame_done(fdir, args):
    """Finished (meta.json and its files) or rejected. Frames made before the ground-truth check
    are checked now."""
    if os.path.exists(os.path.join(fdir, "rejected.json")):
        return True
    try:
        with open(os.path.join(fdir, "meta.json")) as f:
            meta = json.load(f)
    except (OSError, ValueError):
        return False
    settings = {"res": args.res, "spp": args.spp, "stacks": args.stacks, "gt_spp": args.gt_spp}
    wrong = {k: meta.get(k) for k, v in settings.items() if meta.get(k) != v}
    if wrong:
        sys.exit("mitsuba_gen.py: %s was made with other settings (%s); use another --out" % (fdir, wrong))
    if not all(os.path.exists(os.path.join(fdir, f)) for f in meta["files"]):
        return False
    if "gt_relmse_trim16" not in meta:
        meta["gt_relmse_trim16"] = gt_rel_mse(fdir)
        if meta["gt_relmse_trim16"] > args.max_gt_relmse:
            reject(fdir, meta["files"], meta["gt_relmse_trim16"], args.max_gt_relmse)
            print("mitsuba_gen.py: %s rejected: relMSE of gt_a against gt_b %.3f > %.3f"
                  % (fdir, meta["gt_relmse_trim16"], args.max_gt_relmse), file=sys.stderr)
        else:
            write_json_atomic(os.path.join(fdir, "meta.json"), meta)
    return True


def scene_dir(args, seed):
    return os.path.join(args.out, "train" if args.all_train else split_of(seed), "scene_%06d" % seed)


def render_frame(args, seed, k, scene_dict, d, variant):
    fdir = os.path.join(scene_dir(args, seed), "frame_%d" % k)
    os.makedirs(fdir, exist_ok=True)
    for leftover in glob.glob(os.path.join(fdir, "*.tmp*")):
        os.remove(leftover)
    start, cpu_start = time.time(), time.process_time()
    pose = d["poses"][k]
    scene = load_scene(scene_dict, pose, args.res, d["filter"])
    load_s = time.time() - start
    jobs = [("spp%d_%02d.exr" % (args.spp, i), args.spp, True) for i in range(args.stacks)]
    jobs += [("gt_a.exr", args.gt_spp, True), ("gt_b.exr", args.gt_spp, True)]
    seeds, seconds, cpu = {}, {}, {}
    for name, spp, half in jobs:
        seeds[name] = render_seed(seed, k, name)
        path = os.path.join(fdir, name)
        if os.path.exists(path):  # from an interrupted run; every file has its own seed
            seconds[name] = cpu[name] = None
            continue
        t, c = time.time(), time.process_time()
        write_exr(path, render_buffers(scene, spp, seeds[name]), d["exposure_scale"], pose, half)
        seconds[name], cpu[name] = round(time.time() - t, 3), round(time.process_time() - c, 3)
    meta = {"generator_version": GENERATOR_VERSION, "renderer": "mitsuba %s" % mi.__version__,
            "mitsuba_variant": variant, "seed": seed, "frame": k, "res": args.res, "spp": args.spp,
            "stacks": args.stacks, "gt_spp": args.gt_spp, "gt_count": 2, "gt_depth": "16", "threads": args.threads,
            "files": [j[0] for j in jobs], "render_seeds": seeds, "render_seconds": seconds,
            "render_cpu_seconds": cpu, "frame_seconds": round(time.time() - start, 3),
            "frame_cpu_seconds": round(time.process_time() - cpu_start, 3), "scene_load_seconds": round(load_s, 3),
            "archetype": d["archetype"], "lighting": d["lighting"], "pixel_filter": FILTERS[d["filter"]],
            "filter": d["filter"], "exposure_scale": d["exposure_scale"], "camera": pose,
            "channels": {"color": "R G B (half)", "albedo": "albedo.R G B (half)",
                         "normal": "Denoising Normal.X Y Z: camera space as Cycles (x right, y up, z forward)",
                         "normals": "normals.X Y Z: world space (Mitsuba's sh_normal, y up)",
                         "depth": "depth.T: distance along the camera ray"}}
    meta["gt_relmse_trim16"] = gt_rel_mse(fdir)
    if meta["gt_relmse_trim16"] > args.max_gt_relmse:
        reject(fdir, meta["files"], meta["gt_relmse_trim16"], args.max_gt_relmse)
        return meta["gt_relmse_trim16"]
    write_json_atomic(os.path.join(fdir, "meta.json"), meta)
    return None


def prepare_scene(args, seed, tmpdir):
    """The scene of a seed, its description with the exposure (computed once, kept in scene.json)."""
    start = time.time()
    scene, d = build_scene(seed, args.frames, args.filters, tmpdir)
    path = os.path.join(scene_dir(args, seed), "scene.json")
    try:
        with open(path) as f:
            old = json.load(f)
    except (OSError, ValueError):
        old = None
    if old and old.get("generator_version") == GENERATOR_VERSION and old.get("filter") == d["filter"]:
        d["exposure"], d["exposure_scale"] = old["exposure"], old["exposure_scale"]
    else:
        probe = load_scene(scene, d["poses"][args.frames // 2], args.res, d["filter"])
        d["exposure_scale"] = exposure_for(probe, d, render_seed(seed, -1, "probe"))
        d["generator_version"] = GENERATOR_VERSION
        os.makedirs(os.path.dirname(path), exist_ok=True)
        write_json_atomic(path, d)
    d["build_seconds"] = time.time() - start
    return scene, d


def main(argv):
    args = parse_args(argv)
    variant = choose_variant(args.variant)
    dr.set_thread_count(args.threads)
    os.makedirs(args.out, exist_ok=True)
    shard_i, shard_n = args.shard
    seeds = [s for j, s in enumerate(args.seed_list) if j % shard_n == shard_i]
    work = [(s, [k for k in range(args.frames)
                 if not frame_done(os.path.join(scene_dir(args, s), "frame_%d" % k), args)]) for s in seeds]
    work = [(s, todo) for s, todo in work if todo]
    total = sum(len(todo) for _, todo in work)
    print("mitsuba_gen.py: mitsuba %s %s, shard %d/%d: %d scenes, %d frames to render, %d already done"
          % (mi.__version__, variant, shard_i, shard_n, len(seeds), total, len(seeds) * args.frames - total),
          file=sys.stderr, flush=True)
    progress = Progress(total, len(work))
    tmpdir = tempfile.mkdtemp(prefix="mitsuba_gen")
    try:
        for seed, todo in work:
            scene, d = prepare_scene(args, seed, tmpdir)
            for k in todo:
                rejected = render_frame(args, seed, k, scene, d, variant)
                if rejected is not None:
                    print("mitsuba_gen.py: seed %d frame %d rejected: relMSE of gt_a against gt_b %.3f > %.3f"
                          % (seed, k, rejected, args.max_gt_relmse), file=sys.stderr)
                progress.frame(seed, k)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    print("mitsuba_gen.py: done in %s" % format_seconds(time.time() - progress.start), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
