"""Cycles cost and noise of one fixed scene, under whichever Blender runs this script.

Runs under Debian's Blender 3.4 and under PyPI bpy 5.x alike, so the two can be compared:

  blender -b --factory-startup --python bench/blender_versions.py -- --out /tmp/bv34
  /work/venv-bpy/bin/python bench/blender_versions.py --out /tmp/bv50
  python3 bench/blender_versions.py --compare /tmp/bv34 /tmp/bv50

The scene is the generator's kind (128x128, six objects of diffuse, glossy, metal and
glass materials on a floor, an HDRI plus an area, a spot and a small point light),
rendered with the generator's settings (all passes, no adaptive sampling, no clamping,
12 bounces, 2 threads) and each version's other defaults (the light tree is on from 3.5).
It writes timings.json (wall and CPU seconds of the first render, which includes the
kernel load, scene sync and BVH build, then of renders at 4, 64 and 256 spp) and
Combined-only float EXRs at 64 spp and at the reference count, for --compare's
relMSE (noise) and mean (bias) between versions.
"""

import argparse
import json
import math
import os
import sys
import time


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser(prog="blender_versions.py")
    p.add_argument("--out", help="folder for timings.json and the EXRs (run under Blender)")
    p.add_argument("--compare", nargs=2, metavar="DIR", help="compare two --out folders (plain python3)")
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--threads", type=int, default=2)
    return p.parse_args(argv)


def socket(node, *names):
    """The first input of node with one of names (Principled inputs were renamed in 4.0)."""
    for name in names:
        if name in node.inputs:
            return node.inputs[name]
    raise KeyError("%s has none of the inputs %s" % (node.bl_idname, names))


def build_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    def material(name, color, roughness, metallic=0.0, transmission=0.0):
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        socket(bsdf, "Base Color").default_value = (*color, 1.0)
        socket(bsdf, "Roughness").default_value = roughness
        socket(bsdf, "Metallic").default_value = metallic
        socket(bsdf, "Transmission Weight", "Transmission").default_value = transmission
        return mat

    def add(op, mat, **kwargs):
        op(**kwargs)
        obj = bpy.context.active_object
        obj.data.materials.append(mat)
        for poly in obj.data.polygons:
            poly.use_smooth = True
        return obj

    mesh = bpy.ops.mesh
    add(mesh.primitive_plane_add, material("floor", (0.6, 0.55, 0.5), 0.6), size=20)
    add(mesh.primitive_uv_sphere_add, material("red", (0.8, 0.1, 0.1), 0.3), radius=0.5, location=(-1.2, 0, 0.5))
    add(mesh.primitive_cube_add, material("blue", (0.1, 0.2, 0.8), 0.8), size=0.8, location=(0, 1.0, 0.4))
    add(mesh.primitive_torus_add, material("gold", (1.0, 0.75, 0.35), 0.15, metallic=1.0), location=(1.2, 0, 0.25))
    add(mesh.primitive_monkey_add, material("steel", (0.8, 0.8, 0.85), 0.3, metallic=1.0), size=0.8,
        location=(0.2, -0.8, 0.45))
    add(mesh.primitive_cylinder_add, material("green", (0.2, 0.6, 0.2), 0.5), radius=0.3, depth=1.0,
        location=(-0.6, 1.4, 0.5))
    add(mesh.primitive_ico_sphere_add, material("glass", (1, 1, 1), 0.0, transmission=1.0), radius=0.4,
        subdivisions=3, location=(0.9, 1.0, 0.4))

    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri_path(bpy))
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.5

    for kind, loc, energy, extra in [("AREA", (-2, -2, 3), 300.0, {"size": 1.0}),
                                     ("SPOT", (2, -2, 3), 600.0, {"shadow_soft_size": 0.05}),
                                     ("POINT", (0, 2.5, 1.2), 40.0, {"shadow_soft_size": 0.01})]:
        light = bpy.data.lights.new(kind.lower(), kind)
        light.energy = energy
        for k, v in extra.items():
            setattr(light, k, v)
        obj = bpy.data.objects.new(kind.lower(), light)
        scene.collection.objects.link(obj)
        obj.location = loc
        obj.rotation_euler = (Vector((0, 0, 0.3)) - Vector(loc)).to_track_quat("-Z", "Y").to_euler()

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 35
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.5, -5.0, 2.2)
    cam.rotation_euler = (cam.location - Vector((0, 0.3, 0.4))).to_track_quat("Z", "Y").to_euler()
    scene.camera = cam
    return scene


def hdri_path(bpy):
    import glob
    pattern = os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights", "world", "forest.exr")
    found = glob.glob(pattern) or glob.glob("/usr/share/blender/datafiles/studiolights/world/forest.exr")
    if not found:
        sys.exit("blender_versions.py: no forest.exr HDRI in this Blender's datafiles")
    return found[0]


def configure(scene, threads):
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.sample_clamp_direct = 0.0
    cyc.sample_clamp_indirect = 0.0
    cyc.max_bounces = 12
    scene.render.resolution_x = scene.render.resolution_y = 128
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads
    scene.render.use_persistent_data = True
    scene.render.use_compositing = False
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.use_pass_normal = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(layer, "use_pass_%s_%s" % (kind, part), True)
    layer.use_pass_emit = True
    layer.use_pass_environment = True
    layer.cycles.denoising_store_passes = True
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"


def timed_render(bpy, scene, samples, seed, path=None):
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    w0, c0 = time.time(), time.process_time()
    # Always written: in background mode a render that writes nothing may be skipped.
    scene.render.filepath = path or os.path.join(os.path.dirname(scene.render.filepath), "scratch.exr")
    bpy.ops.render.render(write_still=True)
    return {"spp": samples, "wall": round(time.time() - w0, 3), "cpu": round(time.process_time() - c0, 3)}


def run(args):
    global Vector
    t0 = time.time()
    import bpy
    from mathutils import Vector
    import_s = time.time() - t0
    os.makedirs(args.out, exist_ok=True)
    t1 = time.time()
    scene = build_scene(bpy)
    configure(scene, args.threads)
    scene.render.filepath = os.path.join(args.out, "scratch.exr")
    build_s = time.time() - t1
    first = timed_render(bpy, scene, 1, 1)
    renders = [timed_render(bpy, scene, spp, 10 + i) for i, spp in enumerate([4, 4, 4, 4, 64, 64, 256])]
    noisy = timed_render(bpy, scene, 64, 99, os.path.join(args.out, "spp64.exr"))
    ref = timed_render(bpy, scene, args.ref_spp, 7919, os.path.join(args.out, "ref.exr"))
    result = {"blender": bpy.app.version_string, "import_or_startup_s": round(import_s, 3),
              "build_s": round(build_s, 3), "first_render_1spp": first, "renders": renders,
              "noisy_64_written": noisy, "reference": ref,
              "light_tree": bool(getattr(scene.cycles, "use_light_tree", False))}
    with open(os.path.join(args.out, "timings.json"), "w") as f:
        json.dump(result, f, indent=1)
    print(json.dumps(result))


def compare(dirs):
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "experiments"))
    import numpy as np
    from exrutil import read_color
    rows = []
    refs = [read_color(os.path.join(d, "ref.exr")).astype(np.float64) for d in dirs]
    for d in dirs:
        t = json.load(open(os.path.join(d, "timings.json")))
        per = {}
        for r in t["renders"]:
            per.setdefault(r["spp"], []).append(r)
        s4 = sum(r["cpu"] for r in per[4]) / len(per[4])
        s64 = sum(r["cpu"] for r in per[64]) / len(per[64])
        s256 = per[256][0]["cpu"]
        per_sample = (s256 - s4) / 252.0
        noisy = read_color(os.path.join(d, "spp64.exr")).astype(np.float64)
        errs = []
        for ref in refs:  # against both versions' references: noise, and whether they converge alike
            per_pixel = np.sort(np.mean((noisy - ref) ** 2 / (ref ** 2 + 1e-2), axis=2).ravel())
            kept = per_pixel[:len(per_pixel) - len(per_pixel) // 1000]  # one firefly can dominate a mean
            errs.append((float(per_pixel.mean()), float(kept.mean())))
        rows.append((t["blender"], t["light_tree"], t["import_or_startup_s"], t["build_s"],
                     t["first_render_1spp"]["cpu"], s4, s64, s256, per_sample, t["reference"]["cpu"], errs))
    print("| Blender | light tree | import bpy s | build s | first render (1 spp) CPU s | 4 spp CPU s | "
          "64 spp CPU s | 256 spp CPU s | CPU ms per spp | reference CPU s | relMSE of 64 spp vs own reference "
          "(without the 0.1% largest) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for i, r in enumerate(rows):
        own = r[10][i]
        print("| %s | %s | %.2f | %.2f | %.2f | %.3f | %.2f | %.2f | %.1f | %.1f | %.4f (%.4f) |"
              % (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], 1000 * r[8], r[9], own[0], own[1]))
    means = [float(np.mean(ref)) for ref in refs]
    rel = float(np.mean(np.abs(refs[0] - refs[1]) / (np.abs(refs[1]) + 1e-2)))
    print("reference means: %s; mean relative difference between the references: %.4f"
          % (", ".join("%.5f" % m for m in means), rel))


def main():
    args = parse_args()
    if args.compare:
        compare(args.compare)
    elif args.out:
        run(args)
    else:
        sys.exit("blender_versions.py: give --out DIR (under Blender) or --compare DIR DIR")


if __name__ == "__main__":
    try:
        main()
    except BaseException as err:  # Blender exits 0 on script errors in background mode
        if isinstance(err, SystemExit) and err.code in (0, None):
            os._exit(0)
        import traceback
        traceback.print_exc()
        sys.stderr.flush()
        os._exit(1)
