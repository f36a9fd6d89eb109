#!/usr/bin/env python3
"""Evaluation renders from Mitsuba 3 (PyPI mitsuba, CPU variant scalar_rgb).

Hand-built scenes rendered as a Mitsuba user renders them: the `path`
integrator at its defaults (unlimited depth, Russian roulette from depth 5)
inside the `aov` integrator that adds albedo and shading normal, an `hdrfilm`
at its defaults (RGBA, float32), the `independent` sampler. The pixel filter
is the variant:

  --filter box       <rfilter type="box"/>: each sample lands in one pixel, the
                     noise of neighbouring pixels is uncorrelated (issue 22)
  --filter gaussian  Mitsuba's default (stddev 0.5 px, radius 2 px): samples are
                     splatted, the noise is correlated (issue 23)

The aov integrator is given 'albedo:albedo,normals:sh_normal', the AOV names of
Mitsuba's own denoising tutorial, so each file holds the channels a user gets
from film.bitmap(): R G B A (the colour), integrator.R/G/B/A (the nested path
integrator's copy of it), albedo.R/G/B, normals.X/Y/Z (world space, [-1, 1]).

  RENDER_VENV/bin/python experiments/render_mitsuba.py --scene cornell --filter box \
      --out DIR --res 192x192 --spp 4 16 64 --ref-spp 512 --threads 2

writes DIR/spp<N>.exr (seed N) and DIR/ref.exr (seed 7919), each under a temporary
name renamed when complete; existing files are skipped. --half: half floats.
"""

import argparse
import importlib.util
import os
import sys
import time

import mitsuba as mi
import numpy as np
import OpenEXR

mi.set_variant("scalar_rgb")
T = mi.ScalarTransform4f

SCENES = ("cornell", "matpreview", "interior", "lanterns")
AOVS = "albedo:albedo,normals:sh_normal"
REF_SEED = 7919


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", choices=SCENES, required=True)
    p.add_argument("--filter", choices=("box", "gaussian"), required=True)
    p.add_argument("--out", required=True, help="output folder for this scene")
    p.add_argument("--res", default="192x192", help="WIDTHxHEIGHT")
    p.add_argument("--spp", type=int, nargs="*", default=[4, 16, 64])
    p.add_argument("--ref-spp", type=int, default=1024, help="0: no reference")
    p.add_argument("--threads", type=int, default=2, help="at least 2 (see main)")
    p.add_argument("--half", action="store_true", help="half-float channels (default: float)")
    return p.parse_args()


def studiolight(name):
    """One of the HDRIs that ship in the bpy wheel (installed beside mitsuba by setup_renderers.sh)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("render_mitsuba.py: the environment maps come from the bpy wheel; run experiments/setup_renderers.sh")
    root = os.path.dirname(spec.origin)
    for version in sorted(os.listdir(root)):
        path = os.path.join(root, version, "datafiles", "studiolights", "world", name)
        if os.path.isfile(path):
            return path
    sys.exit(f"render_mitsuba.py: {name}: not found under {root}/*/datafiles/studiolights/world")


def rgb(value):
    return {"type": "rgb", "value": list(value)}


def diffuse(color):
    return {"type": "diffuse", "reflectance": rgb(color)}


def glass(ior=1.5):
    return {"type": "dielectric", "int_ior": ior, "ext_ior": 1.0}


def metal(material, alpha):
    return {"type": "roughconductor", "material": material, "alpha": alpha}


def area_light(radiance):
    return {"type": "area", "radiance": rgb(radiance)}


def rectangle(bsdf, to_world, emitter=None):
    shape = {"type": "rectangle", "to_world": to_world, "bsdf": bsdf}
    if emitter:
        shape["emitter"] = emitter
    return shape


def cube(bsdf, center, half_size, rotate_y=0.0):
    return {"type": "cube", "bsdf": bsdf,
            "to_world": T().translate(center).rotate([0, 1, 0], rotate_y).scale(half_size)}


def sphere(bsdf, center, radius, emitter=None):
    shape = {"type": "sphere", "center": list(center), "radius": radius, "bsdf": bsdf}
    if emitter:
        shape["emitter"] = emitter
    return shape


def camera(origin, target, fov, width, height, rfilter):
    film = {"type": "hdrfilm", "width": width, "height": height}
    if rfilter == "box":
        film["rfilter"] = {"type": "box"}
    return {"type": "perspective", "fov": fov, "to_world": T().look_at(origin=origin, target=target, up=[0, 1, 0]),
            "sampler": {"type": "independent"}, "film": film}


def scene_cornell():
    """Mitsuba's Cornell box with a glass sphere and a rough gold sphere in place of the boxes."""
    scene = mi.cornell_box()
    del scene["large-box"], scene["small-box"], scene["integrator"], scene["sensor"]
    scene["glass"] = sphere(glass(), (0.38, -0.68, 0.3), 0.32)
    scene["gold"] = sphere(metal("Au", 0.12), (-0.35, -0.6, -0.3), 0.4)
    return scene, ((0, 0, 3.9), (0, 0, 0), 39.3)


def scene_matpreview():
    """A material preview: copper, glass and plastic spheres on a checker floor under an HDRI."""
    floor = {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": rgb((0.2, 0.2, 0.2)),
                                                "color1": rgb((0.7, 0.7, 0.7)),
                                                "to_uv": T().scale([8, 8, 1])}}
    scene = {
        "type": "scene",
        "env": {"type": "envmap", "filename": studiolight("sunset.exr"), "scale": 1.0,
                "to_world": T().rotate([0, 1, 0], 200)},
        "floor": rectangle(floor, T().rotate([1, 0, 0], -90).scale(6)),
        "copper": sphere(metal("Cu", 0.2), (-1.1, 0.5, 0), 0.5),
        "glass": sphere(glass(), (0, 0.5, 0.3), 0.5),
        "plastic": sphere({"type": "roughplastic", "diffuse_reflectance": rgb((0.1, 0.25, 0.7)),
                           "alpha": 0.1}, (1.1, 0.5, 0), 0.5),
    }
    return scene, ((0, 1.6, 4.2), (0, 0.45, 0), 40)


def scene_interior():
    """A room lit by a sun and a sky through one window, a mirror ball and a glass vase inside."""
    wall = diffuse((0.75, 0.72, 0.66))
    scene = {"type": "scene",
             "sky": {"type": "constant", "radiance": rgb((1.0, 1.3, 2.0))},
             "sun": {"type": "directional", "direction": [-1.0, -0.55, -0.35], "irradiance": rgb((9, 8.5, 7.5))},
             "floor": cube(diffuse((0.35, 0.22, 0.12)), (0, -0.05, 0), (3, 0.05, 3)),
             "ceiling": cube(wall, (0, 2.65, 0), (3, 0.05, 3)),
             "back": cube(wall, (-3.05, 1.3, 0), (0.05, 1.4, 3)),
             "left": cube(wall, (0, 1.3, -3.05), (3, 1.4, 0.05)),
             "right": cube(wall, (0, 1.3, 3.05), (3, 1.4, 0.05)),
             # the window wall at x = 3, around an opening 1.6 m wide and 1.2 m high
             "win-a": cube(wall, (3.05, 1.3, -1.9), (0.05, 1.4, 1.1)),
             "win-b": cube(wall, (3.05, 1.3, 1.9), (0.05, 1.4, 1.1)),
             "win-c": cube(wall, (3.05, 0.45, 0), (0.05, 0.5, 0.8)),
             "win-d": cube(wall, (3.05, 2.4, 0), (0.05, 0.3, 0.8)),
             "sofa": cube(diffuse((0.15, 0.25, 0.55)), (-2.2, 0.4, 0.5), (0.6, 0.4, 1.5)),
             "table": cube(diffuse((0.8, 0.8, 0.78)), (0.2, 0.7, 0.4), (0.7, 0.04, 0.5)),
             "ball": sphere(metal("Ag", 0.02), (0.0, 0.94, 0.3), 0.2),
             "vase": sphere(glass(), (0.5, 0.92, 0.6), 0.18)}
    return scene, ((2.4, 1.6, -2.5), (-1.0, 0.7, 0.9), 65)


def scene_lanterns():
    """Small bright lamps inside glass globes and behind a glass pane: light reaches the room
    only through glass, so next-event estimation cannot see it (caustics, fireflies)."""
    lamp = area_light((80, 60, 38))
    scene = {"type": "scene",
             "dim": {"type": "constant", "radiance": rgb((0.01, 0.01, 0.012))},
             "floor": rectangle(diffuse((0.5, 0.5, 0.5)), T().rotate([1, 0, 0], -90).scale(5)),
             "wall": rectangle(diffuse((0.6, 0.55, 0.5)), T().translate([0, 2, -2]).scale(5)),
             "pane": cube(glass(), (1.0, 0.8, -0.6), (0.5, 0.8, 0.02)),
             "lamp-pane": sphere(diffuse((0, 0, 0)), (1.0, 0.9, -1.0), 0.08, lamp),
             "block": cube(diffuse((0.7, 0.15, 0.1)), (-0.2, 0.25, 0.3), (0.25, 0.25, 0.25), 30)}
    for i, (x, z) in enumerate([(-1.3, -0.6), (0.4, -1.2)]):
        scene[f"globe{i}"] = sphere(glass(), (x, 0.9, z), 0.25)
        scene[f"lamp{i}"] = sphere(diffuse((0, 0, 0)), (x, 0.9, z), 0.08, lamp)
    scene["chrome"] = sphere(metal("Cr", 0.05), (0.9, 0.3, 0.6), 0.3)
    return scene, ((0.2, 1.7, 4.2), (0, 0.6, -0.6), 45)


def build(name, width, height, rfilter):
    scene, (origin, target, fov) = globals()["scene_" + name]()
    scene["integrator"] = {"type": "aov", "aovs": AOVS, "integrator": {"type": "path"}}
    scene["sensor"] = camera(origin, target, fov, width, height, rfilter)
    return mi.load_dict(scene)


def write_exr(path, bitmap, half):
    """The film's channels under the names Mitsuba gives them, ZIP-compressed."""
    struct = bitmap.struct_()
    names = [struct[i].name for i in range(len(struct))]
    pixels = np.array(bitmap, copy=False)
    dtype = np.float16 if half else np.float32
    channels = {n: np.ascontiguousarray(pixels[..., i].astype(dtype)) for i, n in enumerate(names)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    tmp = f"{path}.tmp{os.getpid()}.exr"
    try:
        OpenEXR.File(header, channels).write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def render(scene, path, spp, seed, half):
    if os.path.exists(path):
        return
    start = time.time()
    mi.render(scene, spp=spp, seed=seed)
    write_exr(path, scene.sensors()[0].film().bitmap(raw=False), half)
    print("render_mitsuba: %s (%d spp) in %.1f s" % (path, spp, time.time() - start), flush=True)


def main():
    args = parse_args()
    import drjit as dr
    # With a pool of one thread, Mitsuba 3.9's scalar variant hangs while loading an envmap.
    dr.set_thread_count(max(args.threads, 2))
    os.makedirs(args.out, exist_ok=True)
    width, height = (int(v) for v in args.res.split("x"))
    scene = build(args.scene, width, height, args.filter)
    for spp in args.spp:
        render(scene, os.path.join(args.out, "spp%d.exr" % spp), spp, spp, args.half)
    if args.ref_spp > 0:
        render(scene, os.path.join(args.out, "ref.exr"), args.ref_spp, REF_SEED, args.half)


if __name__ == "__main__":
    sys.exit(main())
