#!/usr/bin/env python3
"""Evaluation renders from Blender 5 (PyPI bpy 5.0.1, Cycles), made as a user makes them.

Hand-built scenes, rendered with Cycles at Blender 5's shipped sampling defaults
(light tree on, adaptive sampling on with threshold 0.01, indirect clamp 10,
Tabulated Sobol, 1.5 px Blackman-Harris filter). Only Cycles' own denoiser is
switched off, so that the Combined pass stays noisy; the Denoising Data and the
diffuse/glossy/transmission light passes and Z are on. Blender 5 writes an
OpenEXR MultiLayer file as a multi-part EXR with the passes' full names
(`ViewLayer.Diffuse Direct.R`, `ViewLayer.Denoising Albedo.R`, ...): kept as is.

  RENDER_VENV/bin/python experiments/render_blender5.py --scene cornell --out DIR \
      --res 192x192 --spp 4 16 64 --ref-spp 1024 --threads 1

writes DIR/spp<N>.exr for each --spp (seed N, adaptive sampling as shipped) and
DIR/ref.exr (--ref-spp samples, adaptive sampling off, seed 7919). Each file is
written under a temporary name and renamed when complete; existing files are
skipped, so an interrupted run resumes. --half writes half floats (test fixtures).
"""

import argparse
import math
import os
import sys
import time

import bpy
from mathutils import Vector

SCENES = ("cornell", "window", "hdri", "product", "exterior")
STUDIOLIGHTS = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
REF_SEED = 7919


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", choices=SCENES, required=True)
    p.add_argument("--out", required=True, help="output folder for this scene")
    p.add_argument("--res", default="192x192", help="WIDTHxHEIGHT")
    p.add_argument("--spp", type=int, nargs="*", default=[4, 16, 64])
    p.add_argument("--ref-spp", type=int, default=1024, help="0: no reference")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--half", action="store_true", help="half-float channels (default: float)")
    p.add_argument("--all-light-passes", action="store_true",
                   help="also Emission, Environment and Volume Direct/Indirect (denoised passes, issue 33)")
    p.add_argument("--border", default=None,
                   help="X0,Y0,X1,Y1 in [0, 1]: render and crop to this region (small fixtures)")
    return p.parse_args()


def material(name, color, roughness=0.5, metallic=0.0, transmission=0.0, emission=None,
             strength=0.0, ior=1.45):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Transmission Weight"].default_value = transmission
    bsdf.inputs["IOR"].default_value = ior
    if emission:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return mat


def checker(mat, color1, color2, scale):
    """Feeds a procedural checker texture into the material's base colour."""
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexChecker")
    tex.inputs["Color1"].default_value = (*color1, 1.0)
    tex.inputs["Color2"].default_value = (*color2, 1.0)
    tex.inputs["Scale"].default_value = scale
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def add(op, mat=None, smooth=False, **kwargs):
    op(**kwargs)
    obj = bpy.context.active_object
    if mat:
        obj.data.materials.append(mat)
    if smooth:
        for poly in obj.data.polygons:
            poly.use_smooth = True
    return obj


def box(mat, location, scale):
    return add(bpy.ops.mesh.primitive_cube_add, mat, location=location, scale=scale)


def light(kind, location, energy, size=None, color=(1, 1, 1), target=None, rotation=None):
    bpy.ops.object.light_add(type=kind, location=location, rotation=rotation or (0, 0, 0))
    obj = bpy.context.active_object
    obj.data.energy, obj.data.color = energy, color
    if size is not None:
        if kind == "SUN":
            obj.data.angle = size
        elif kind == "AREA":
            obj.data.size = size
        else:
            obj.data.shadow_soft_size = size
    if target is not None:
        obj.rotation_euler = (Vector(target) - obj.location).to_track_quat("-Z", "Y").to_euler()
    return obj


def clear_startup_scene():
    """Blender's startup scene without its cube and light: the camera and world stay."""
    for name in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[name])


def place_camera(location, target, lens=50):
    cam = bpy.data.objects["Camera"]
    cam.location = location
    cam.rotation_euler = (cam.location - Vector(target)).to_track_quat("Z", "Y").to_euler()
    cam.data.lens = lens


def world_color(color, strength):
    bg = bpy.context.scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength


def world_texture(node_type, strength):
    """A texture node of node_type feeding the world's background; returns the node."""
    tree = bpy.context.scene.world.node_tree
    node = tree.nodes.new(node_type)
    tree.links.new(node.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    tree.nodes["Background"].inputs["Strength"].default_value = strength
    return node


def build_cornell():
    """A Cornell box lit by its ceiling panel, with a glass sphere and a brushed-metal block."""
    clear_startup_scene()
    white = material("white", (0.73, 0.73, 0.73), 0.9)
    for loc, scale in [((0, 0, -0.05), (1.05, 1.05, 0.05)), ((0, 0, 2.05), (1.05, 1.05, 0.05)),
                       ((0, 1.05, 1.0), (1.05, 0.05, 1.05))]:
        box(white, loc, scale)
    box(material("red", (0.63, 0.065, 0.05), 0.9), (-1.05, 0, 1.0), (0.05, 1.05, 1.05))
    box(material("green", (0.14, 0.45, 0.09), 0.9), (1.05, 0, 1.0), (0.05, 1.05, 1.05))
    lamp = material("lamp", (0, 0, 0), emission=(1.0, 0.85, 0.6), strength=40.0)
    add(bpy.ops.mesh.primitive_plane_add, lamp, size=0.5, location=(0, 0, 1.995))
    add(bpy.ops.mesh.primitive_uv_sphere_add,
        material("glass", (1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5), smooth=True,
        radius=0.35, location=(-0.4, -0.25, 0.35), segments=64, ring_count=32)
    block = box(material("metal", (0.95, 0.64, 0.54), roughness=0.25, metallic=1.0),
                (0.4, 0.35, 0.6), (0.3, 0.3, 0.6))
    block.rotation_euler.z = math.radians(20)
    world_color((0, 0, 0), 1.0)
    place_camera((0, -3.35, 1.0), (0, 0, 1.0), lens=38)


def build_window():
    """A room lit by a low sun and the sky through one window: mostly indirect light."""
    clear_startup_scene()
    wall = material("plaster", (0.8, 0.78, 0.72), 0.85)
    for loc, scale in [((0, 0, 2.65), (3.0, 3.0, 0.05)), ((-3.05, 0, 1.3), (0.05, 3, 1.4)),
                       ((0, 3.05, 1.3), (3, 0.05, 1.4)), ((0, -3.05, 1.3), (3, 0.05, 1.4)),
                       # the window wall at x = 3, around an opening 1.6 m wide, 1.2 m high
                       ((3.05, -1.9, 1.3), (0.05, 1.1, 1.4)), ((3.05, 1.9, 1.3), (0.05, 1.1, 1.4)),
                       ((3.05, 0, 0.45), (0.05, 0.8, 0.5)), ((3.05, 0, 2.4), (0.05, 0.8, 0.3))]:
        box(wall, loc, scale)
    floor = checker(material("floor", (1, 1, 1), 0.3), (0.45, 0.3, 0.18), (0.3, 0.18, 0.1), 12.0)
    box(floor, (0, 0, -0.05), (3.0, 3.0, 0.05))
    box(material("bed", (0.7, 0.2, 0.15), 0.9), (-2.0, 1.4, 0.3), (1.0, 1.4, 0.3))
    box(material("desk", (0.9, 0.9, 0.88), 0.2), (0.8, 2.5, 0.75), (1.0, 0.45, 0.04))
    add(bpy.ops.mesh.primitive_cylinder_add,
        material("jar", (0.85, 0.95, 0.9), roughness=0.05, transmission=1.0), smooth=True,
        radius=0.12, depth=0.35, location=(1.2, 2.5, 0.97))
    add(bpy.ops.mesh.primitive_uv_sphere_add,
        material("chrome", (0.9, 0.9, 0.9), roughness=0.05, metallic=1.0), smooth=True,
        radius=0.18, location=(0.4, 2.5, 0.97))
    light("SUN", (10, 0, 6), 10.0, size=math.radians(1.0), rotation=(0, math.radians(62), math.radians(15)))
    world_color((0.35, 0.5, 0.85), 2.0)
    place_camera((-2.6, -2.6, 1.5), (1.5, 1.0, 0.9), lens=18)


def build_hdri():
    """Metals and glass on a checker floor under one of Blender's studio-light HDRIs."""
    clear_startup_scene()
    floor = checker(material("floor", (1, 1, 1), 0.35), (0.8, 0.8, 0.8), (0.15, 0.15, 0.15), 8.0)
    add(bpy.ops.mesh.primitive_plane_add, floor, size=10)
    add(bpy.ops.mesh.primitive_uv_sphere_add,
        material("glass", (1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5), smooth=True,
        radius=0.6, location=(-0.9, 0.2, 0.6), segments=64, ring_count=32)
    add(bpy.ops.mesh.primitive_torus_add,
        material("gold", (1.0, 0.77, 0.34), roughness=0.15, metallic=1.0), smooth=True,
        major_radius=0.55, minor_radius=0.2, location=(0.8, -0.3, 0.2))
    monkey = add(bpy.ops.mesh.primitive_monkey_add,
                 material("copper", (0.95, 0.6, 0.5), roughness=0.3, metallic=1.0), smooth=True,
                 size=0.9, location=(0.3, 1.3, 0.6), rotation=(0, 0, math.radians(-20)))
    mod = monkey.modifiers.new("subsurf", "SUBSURF")
    mod.levels = mod.render_levels = 1
    add(bpy.ops.mesh.primitive_cube_add,
        material("frosted", (0.9, 0.95, 1.0), roughness=0.25, transmission=1.0),
        size=0.5, location=(1.6, 0.9, 0.25))
    world_texture("ShaderNodeTexEnvironment", 1.0).image = bpy.data.images.load(
        os.path.join(STUDIOLIGHTS, "courtyard.exr"))
    place_camera((0.5, -4.2, 1.8), (0.2, 0.4, 0.45), lens=40)


def build_product():
    """A product shot: key, fill and rim area lights on a seamless sweep."""
    clear_startup_scene()
    sweep = material("sweep", (0.6, 0.62, 0.65), 0.5)
    add(bpy.ops.mesh.primitive_plane_add, sweep, size=20)
    add(bpy.ops.mesh.primitive_plane_add, sweep, size=20, location=(0, 4, 0), rotation=(math.radians(90), 0, 0))
    bottle = add(bpy.ops.mesh.primitive_cylinder_add,
                 material("bottle", (0.55, 0.8, 0.6), roughness=0.02, transmission=1.0), smooth=True,
                 radius=0.35, depth=1.4, vertices=64, location=(-0.5, 0.6, 0.7))
    bevel = bottle.modifiers.new("bevel", "BEVEL")
    bevel.width, bevel.segments = 0.1, 3
    add(bpy.ops.mesh.primitive_cylinder_add,
        material("cap", (0.9, 0.9, 0.92), roughness=0.2, metallic=1.0), smooth=True,
        radius=0.16, depth=0.25, vertices=48, location=(-0.5, 0.6, 1.52))
    add(bpy.ops.mesh.primitive_uv_sphere_add, material("coat", (0.05, 0.1, 0.5), 0.45), smooth=True,
        radius=0.4, location=(0.6, 0.2, 0.4), segments=48, ring_count=24)
    light("AREA", (-2.5, -2.0, 2.5), 250.0, size=1.5, target=(0, 0.5, 0.6))
    light("AREA", (2.5, -1.5, 1.5), 60.0, size=2.0, target=(0, 0.5, 0.6), color=(0.8, 0.9, 1.0))
    light("AREA", (0.5, 2.5, 2.5), 150.0, size=0.6, target=(0, 0.5, 0.8))
    world_color((0.02, 0.02, 0.02), 1.0)
    place_camera((0.2, -4.5, 1.3), (0.0, 0.5, 0.65), lens=50)


def build_exterior():
    """Houses and trees in afternoon sun under Blender's physical sky texture (its default model)."""
    clear_startup_scene()
    add(bpy.ops.mesh.primitive_plane_add, material("grass", (0.12, 0.25, 0.06), 0.9), size=80)
    walls = [(0.85, 0.8, 0.7), (0.7, 0.45, 0.35), (0.9, 0.9, 0.92)]
    for i, (x, y) in enumerate([(-4, 3), (1, 6), (5, 2), (-1, 12)]):
        box(material("wall%d" % i, walls[i % 3], 0.7), (x, y, 1.2), (1.3, 1.5, 1.2))
        box(material("window%d" % i, (0.05, 0.07, 0.1), 0.05), (x, y - 1.51, 1.4), (0.5, 0.01, 0.4))
        roof = add(bpy.ops.mesh.primitive_cone_add, material("roof%d" % i, (0.4, 0.12, 0.08), 0.6),
                   vertices=4, radius1=2.3, depth=1.2, location=(x, y, 3.0))
        roof.rotation_euler.z = math.radians(45)
    for x, y in [(-2, 0), (3, -1), (7, 6)]:
        add(bpy.ops.mesh.primitive_ico_sphere_add, material("leaves", (0.1, 0.35, 0.08), 0.9),
            radius=1.0, subdivisions=2, location=(x, y, 1.8))
        add(bpy.ops.mesh.primitive_cylinder_add, material("bark", (0.25, 0.15, 0.08), 0.9),
            radius=0.12, depth=1.4, location=(x, y, 0.7))
    sky = world_texture("ShaderNodeTexSky", 0.25)
    sky.sun_elevation = math.radians(25)
    sky.sun_rotation = math.radians(-60)
    place_camera((2.0, -9.0, 1.8), (0.0, 4.0, 1.6), lens=28)


def configure(scene, args):
    """Blender 5's defaults, Cycles' own denoiser off, the passes a denoiser reads on."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False  # the Combined pass stays noisy
    width, height = (int(v) for v in args.res.split("x"))
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    if args.border:
        x0, y0, x1, y1 = (float(v) for v in args.border.split(","))
        scene.render.use_border, scene.render.use_crop_to_border = True, True
        scene.render.border_min_x, scene.render.border_min_y = x0, y0
        scene.render.border_max_x, scene.render.border_max_y = x1, y1
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"  # Blender 5: chosen before the file format
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "16" if args.half else "32"
    settings.exr_codec = "ZIP"
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.cycles.denoising_store_passes = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(layer, "use_pass_%s_%s" % (kind, part), True)
    if args.all_light_passes:
        layer.use_pass_emit = True
        layer.use_pass_environment = True
        layer.cycles.use_pass_volume_direct = True
        layer.cycles.use_pass_volume_indirect = True


def render(scene, path, samples, seed, reference):
    if os.path.exists(path):
        return
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    scene.cycles.use_adaptive_sampling = not reference
    tmp = path + ".tmp%d.exr" % os.getpid()
    scene.render.filepath = tmp
    start = time.time()
    bpy.ops.render.render(write_still=True)
    os.replace(tmp, path)
    print("render_blender5: %s (%d spp) in %.1f s" % (path, samples, time.time() - start), flush=True)


def main():
    args = parse_args()
    os.makedirs(args.out, exist_ok=True)
    globals()["build_" + args.scene]()
    scene = bpy.context.scene
    configure(scene, args)
    for spp in args.spp:
        render(scene, os.path.join(args.out, "spp%d.exr" % spp), spp, spp, False)
    if args.ref_spp > 0:
        render(scene, os.path.join(args.out, "ref.exr"), args.ref_spp, REF_SEED, True)


if __name__ == "__main__":
    sys.exit(main())
