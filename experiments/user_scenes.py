"""Hand-built scenes rendered the way a Blender user renders them (Blender 3.4 Cycles).

The training data comes from scenegen/'s procedural generator with adaptive
sampling, denoising and clamping off. These scenes check dndenoise on renders
it has never seen, made as a user makes them: Blender's default render
settings (adaptive sampling on, indirect clamp 10, filter 1.5 px; Cycles'
own denoiser stays off because Debian's Blender is built without OIDN), a
16:9 frame, the view layer's Denoising Data and light passes switched on,
saved as a multilayer EXR.

  blender -b --factory-startup --python experiments/user_scenes.py -- \
      --scene interior --out DIR --res 384x216 --spp 4 16 64 --ref-spp 1024 --threads 2

writes DIR/<scene>_<N>spp.exr for each --spp and DIR/<scene>_ref.exr (adaptive
sampling off, an independent seed). With --frames N, an animation instead: the
camera slides by --move (world units per frame) with its aim kept, the noise
seed animated and the Vector pass on (motion blur off), written as
DIR/spp<N>.<frame>.exr and DIR/ref.<frame>.exr, as experiments/temporal_eval.py
reads them. Files are written under a
temporary name and renamed when complete; existing ones are skipped.
"""

import argparse
import math
import os
import sys

import bpy
from mathutils import Vector

SCENES = ("cube", "interior", "studio", "night", "kitchen", "outdoor", "product")
HDRI = "/usr/share/blender/datafiles/studiolights/world/forest.exr"
PHOTO = "/usr/share/backgrounds/mate/nature/Wood.jpg"
GRASS = "/usr/share/backgrounds/mate/nature/GreenMeadow.jpg"


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="user_scenes.py")
    p.add_argument("--scene", choices=SCENES, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--res", default="384x216")
    p.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    p.add_argument("--ref-spp", type=int, default=2048)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--frames", type=int, default=0, help="N > 0: an animation of N frames")
    p.add_argument("--move", default="0.05,0.03,0", help="the camera's move per frame, x,y,z")
    return p.parse_args(argv)


def material(name, color, roughness=0.5, metallic=0.0, transmission=0.0, emission=None,
             strength=0.0, image=None):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Transmission"].default_value = transmission
    if emission:
        bsdf.inputs["Emission"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    if image:
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(image)
        mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def add(op, mat=None, **kwargs):
    op(**kwargs)
    obj = bpy.context.active_object
    if mat:
        obj.data.materials.append(mat)
    return obj


def smooth(obj):
    for poly in obj.data.polygons:
        poly.use_smooth = True
    return obj


def clear_startup_scene():
    """Blender's startup scene without its cube and light: camera and world stay."""
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.data.objects.remove(bpy.data.objects["Light"])


def place_camera(location, target, lens=50):
    cam = bpy.data.objects["Camera"]
    cam.location = location
    cam.rotation_euler = (cam.location - Vector(target)).to_track_quat("Z", "Y").to_euler()
    cam.data.lens = lens


def world_color(color, strength):
    world = bpy.context.scene.world
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength


def world_texture(node_type, strength):
    """A texture node of node_type feeding the world's background; returns the node."""
    world = bpy.context.scene.world
    world.use_nodes = True
    nt = world.node_tree
    node = nt.nodes.new(node_type)
    nt.links.new(node.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    nt.nodes["Background"].inputs["Strength"].default_value = strength
    return node


def build_cube():
    """Blender's startup scene (cube, point light, camera) on a floor, with a glossy Suzanne."""
    cube = bpy.data.objects["Cube"]
    cube.data.materials.clear()
    cube.data.materials.append(material("cube", (0.8, 0.3, 0.1), roughness=0.4))
    add(bpy.ops.mesh.primitive_plane_add, material("floor", (0.6, 0.6, 0.6), 0.3), size=30,
        location=(0, 0, -1))
    monkey = add(bpy.ops.mesh.primitive_monkey_add,
                 material("monkey", (0.9, 0.9, 0.9), roughness=0.1, metallic=1.0),
                 location=(2.6, -0.8, 0.0), rotation=(0, 0, 0.6))
    modifier = monkey.modifiers.new("subsurf", "SUBSURF")
    modifier.levels = modifier.render_levels = 2
    smooth(monkey)
    world_color((0.05, 0.05, 0.05), 1.0)


def build_interior():
    """A closed room lit by the sun through one window: mostly indirect light."""
    clear_startup_scene()
    wall = material("wall", (0.75, 0.72, 0.65), 0.8)
    for loc, scale in [((0, 0, -0.05), (5, 4, 0.05)), ((0, 0, 3.05), (5, 4, 0.05)),
                       ((-5.05, 0, 1.5), (0.05, 4, 1.6)), ((0, 4.05, 1.5), (5, 0.05, 1.6)),
                       ((0, -4.05, 1.5), (5, 0.05, 1.6)),
                       # the window wall at x = 5, around an opening 2 m wide, 1.4 m high
                       ((5.05, -2.5, 1.5), (0.05, 1.5, 1.6)), ((5.05, 2.5, 1.5), (0.05, 1.5, 1.6)),
                       ((5.05, 0, 0.4), (0.05, 1.0, 0.45)), ((5.05, 0, 2.7), (0.05, 1.0, 0.35))]:
        add(bpy.ops.mesh.primitive_cube_add, wall, location=loc, scale=scale)
    floor = material("parquet", (1, 1, 1), 0.25, image=PHOTO)
    add(bpy.ops.mesh.primitive_plane_add, floor, size=9.9, location=(0, 0, 0.001))
    add(bpy.ops.mesh.primitive_cube_add, material("sofa", (0.15, 0.25, 0.55), 0.9),
        location=(-3.5, 0, 0.45), scale=(0.7, 2.0, 0.45))
    add(bpy.ops.mesh.primitive_cube_add, material("table", (0.35, 0.2, 0.1), 0.35),
        location=(-1.0, 0.5, 0.4), scale=(0.8, 0.6, 0.05))
    vase = add(bpy.ops.mesh.primitive_uv_sphere_add,
               material("vase", (0.9, 0.95, 1.0), roughness=0.0, transmission=1.0),
               radius=0.25, location=(-1.0, 0.5, 0.7))
    smooth(vase)
    add(bpy.ops.object.light_add, type="SUN", location=(10, 0, 6), rotation=(0, math.radians(60), 0))
    bpy.context.active_object.data.energy = 8.0
    bpy.context.active_object.data.angle = math.radians(1.5)
    world_color((0.4, 0.55, 0.8), 1.0)
    place_camera((3.8, -3.3, 1.7), (-2.0, 1.0, 0.8), lens=22)


def build_studio():
    """Glass, metal and a textured floor under an HDRI: caustics and reflections."""
    clear_startup_scene()
    add(bpy.ops.mesh.primitive_plane_add, material("wood", (1, 1, 1), 0.4, image=PHOTO), size=12,
        location=(0, 0, 0))
    glass = add(bpy.ops.mesh.primitive_uv_sphere_add,
                material("glass", (1, 1, 1), roughness=0.0, transmission=1.0),
                radius=0.9, location=(-1.0, 0.3, 0.9), segments=64, ring_count=32)
    smooth(glass)
    torus = add(bpy.ops.mesh.primitive_torus_add,
                material("gold", (1.0, 0.75, 0.35), roughness=0.2, metallic=1.0),
                location=(1.3, -0.2, 0.35), major_radius=0.8, minor_radius=0.3)
    smooth(torus)
    add(bpy.ops.mesh.primitive_cylinder_add, material("plastic", (0.1, 0.6, 0.2), 0.5),
        location=(0.5, 1.8, 0.6), radius=0.5, depth=1.2)
    world_texture("ShaderNodeTexEnvironment", 1.0).image = bpy.data.images.load(HDRI)
    place_camera((0.5, -6.0, 2.6), (0.0, 0.3, 0.6))


def build_night():
    """A street at night: small emitters and coloured area lights, glossy ground."""
    clear_startup_scene()
    add(bpy.ops.mesh.primitive_plane_add, material("asphalt", (0.08, 0.08, 0.09), 0.15), size=40)
    block = material("concrete", (0.5, 0.5, 0.5), 0.7)
    for x, y, h in [(-4, 4, 3), (-1, 5, 5), (2.5, 4.5, 4), (6, 5, 6), (-6, -2, 2)]:
        add(bpy.ops.mesh.primitive_cube_add, block, location=(x, y, h), scale=(1.2, 1.2, h))
    lamp = material("lamp", (1, 1, 1), emission=(1.0, 0.7, 0.35), strength=30.0)
    for x in (-3, 1, 5):
        add(bpy.ops.mesh.primitive_cylinder_add, block, location=(x, 1.5, 1.5), radius=0.05, depth=3)
        smooth(add(bpy.ops.mesh.primitive_uv_sphere_add, lamp, radius=0.15, location=(x, 1.5, 3.1)))
    for loc, color in [((-2, -1, 2.5), (0.2, 0.4, 1.0)), ((3, -2, 2.0), (1.0, 0.2, 0.5))]:
        add(bpy.ops.object.light_add, type="AREA", location=loc)
        light = bpy.context.active_object.data
        light.energy, light.color, light.size = 150.0, color, 1.0
    world_color((0.01, 0.012, 0.02), 1.0)
    place_camera((0.0, -9.0, 1.6), (0.5, 2.0, 1.6), lens=30)


def build_kitchen():
    """A kitchen corner: a ceiling panel light, a glossy counter, bowls and bottles."""
    clear_startup_scene()
    tiles = material("tiles", (0.85, 0.85, 0.8), 0.35)
    for loc, scale in [((0, 0, -0.05), (3, 3, 0.05)), ((0, 3.05, 1.5), (3, 0.05, 1.6)),
                       ((-3.05, 0, 1.5), (0.05, 3, 1.6)), ((0, 0, 3.05), (3, 3, 0.05))]:
        add(bpy.ops.mesh.primitive_cube_add, tiles, location=loc, scale=scale)
    add(bpy.ops.mesh.primitive_cube_add, material("counter", (0.1, 0.1, 0.12), 0.15),
        location=(-0.5, 2.3, 0.9), scale=(2.4, 0.6, 0.05))
    add(bpy.ops.mesh.primitive_cube_add, material("cabinet", (0.55, 0.3, 0.15), 0.6),
        location=(-0.5, 2.3, 0.42), scale=(2.4, 0.6, 0.42))
    for x, color in [(-1.8, (0.9, 0.2, 0.1)), (-0.6, (0.1, 0.4, 0.9)), (0.6, (0.95, 0.85, 0.3))]:
        bowl = add(bpy.ops.mesh.primitive_uv_sphere_add, material("bowl", color, 0.25),
                   radius=0.25, location=(x, 2.2, 1.1))
        bowl.scale.z = 0.5
        smooth(bowl)
    bottle = add(bpy.ops.mesh.primitive_cylinder_add,
                 material("bottle", (0.3, 0.8, 0.4), roughness=0.05, transmission=1.0),
                 radius=0.09, depth=0.5, location=(1.3, 2.3, 1.2))
    smooth(bottle)
    add(bpy.ops.object.light_add, type="AREA", location=(-0.5, 1.5, 2.95))
    light = bpy.context.active_object.data
    light.energy, light.size, light.color = 80.0, 1.2, (1.0, 0.92, 0.8)
    add(bpy.ops.object.light_add, type="POINT", location=(2.0, -1.0, 2.0))
    bpy.context.active_object.data.energy = 15.0
    world_color((0.02, 0.02, 0.025), 1.0)
    place_camera((1.2, -0.6, 1.7), (-0.6, 2.2, 1.0), lens=26)


def build_outdoor():
    """Houses in low sun under a physical sky: long shadows, sky light, a textured ground."""
    clear_startup_scene()
    add(bpy.ops.mesh.primitive_plane_add, material("ground", (1, 1, 1), 0.8, image=GRASS), size=60)
    walls = [(0.85, 0.8, 0.7), (0.7, 0.45, 0.35), (0.9, 0.9, 0.92)]
    for i, (x, y) in enumerate([(-4, 3), (1, 6), (5, 2), (-1, 12)]):
        add(bpy.ops.mesh.primitive_cube_add, material("wall%d" % i, walls[i % 3], 0.7),
            location=(x, y, 1.2), scale=(1.3, 1.5, 1.2))
        roof = add(bpy.ops.mesh.primitive_cone_add, material("roof%d" % i, (0.4, 0.12, 0.08), 0.6),
                   vertices=4, radius1=2.3, depth=1.2, location=(x, y, 3.0))
        roof.rotation_euler.z = math.radians(45)
    for x, y in [(-2, 0), (3, -1), (7, 6)]:
        tree = add(bpy.ops.mesh.primitive_ico_sphere_add, material("leaves", (0.1, 0.35, 0.08), 0.9),
                   radius=1.0, subdivisions=2, location=(x, y, 1.8))
        add(bpy.ops.mesh.primitive_cylinder_add, material("bark", (0.25, 0.15, 0.08), 0.9),
            radius=0.12, depth=1.4, location=(x, y, 0.7))
    add(bpy.ops.object.light_add, type="SUN", location=(0, 0, 10),
        rotation=(math.radians(75), 0, math.radians(-40)))
    bpy.context.active_object.data.energy = 1.5
    sky = world_texture("ShaderNodeTexSky", 0.1)
    sky.sky_type = "NISHITA"
    sky.sun_elevation = math.radians(15)
    place_camera((2.0, -9.0, 2.0), (0.0, 4.0, 1.2), lens=28)


def build_product():
    """A product shot: key and rim area lights on a dark sweep, glossy and rough objects."""
    clear_startup_scene()
    add(bpy.ops.mesh.primitive_plane_add, material("sweep", (0.05, 0.05, 0.06), 0.4), size=20)
    add(bpy.ops.mesh.primitive_plane_add, material("back", (0.05, 0.05, 0.06), 0.4), size=20,
        location=(0, 6, 0), rotation=(math.radians(90), 0, 0))
    smooth(add(bpy.ops.mesh.primitive_uv_sphere_add, material("red", (0.8, 0.05, 0.05), 0.08),
               radius=0.7, location=(-1.2, 0.5, 0.7), segments=64, ring_count=32))
    add(bpy.ops.mesh.primitive_cone_add, material("steel", (0.8, 0.8, 0.85), roughness=0.35,
                                                  metallic=1.0),
        radius1=0.6, depth=1.5, location=(0.6, 1.0, 0.75))
    box = add(bpy.ops.mesh.primitive_cube_add, material("soap", (0.9, 0.85, 0.6), 0.5),
              location=(1.6, -0.4, 0.35), scale=(0.5, 0.35, 0.35))
    bevel = box.modifiers.new("bevel", "BEVEL")
    bevel.width, bevel.segments = 0.08, 4
    for loc, energy, size in [((-3.0, -2.5, 3.0), 500.0, 2.0), ((2.5, 3.5, 2.5), 300.0, 1.0)]:
        add(bpy.ops.object.light_add, type="AREA", location=loc)
        light = bpy.context.active_object
        light.data.energy, light.data.size = energy, size
        direction = Vector((0, 0.5, 0.6)) - light.location
        light.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    world_color((0.0, 0.0, 0.0), 1.0)
    place_camera((0.3, -5.5, 1.8), (0.2, 0.5, 0.6), lens=45)


def configure(scene, args):
    """Blender's defaults, plus the passes the denoiser reads."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False  # no OIDN in Debian's Blender
    width, height = (int(v) for v in args.res.split("x"))
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.cycles.denoising_store_passes = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(layer, "use_pass_%s_%s" % (kind, part), True)


def render(scene, path, samples, seed, reference):
    if os.path.exists(path):
        return
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    scene.cycles.use_adaptive_sampling = not reference
    tmp = path + ".tmp%d.exr" % os.getpid()
    scene.render.filepath = tmp
    bpy.ops.render.render(write_still=True)
    os.replace(tmp, path)


def animate(scene, args):
    """The camera slides linearly over frames 1..N; the Vector pass and an animated seed."""
    cam = bpy.data.objects["Camera"]
    move = Vector(float(v) for v in args.move.split(","))
    start = cam.location.copy()
    for frame in (1, args.frames):
        cam.location = start + (frame - 1) * move
        cam.keyframe_insert("location", frame=frame)
    for curve in cam.animation_data.action.fcurves:
        for key in curve.keyframe_points:
            key.interpolation = "LINEAR"
    scene.frame_start, scene.frame_end = 1, args.frames
    scene.render.use_motion_blur = False  # Cycles writes the Vector pass only without it
    scene.view_layers[0].use_pass_vector = True
    scene.cycles.use_animated_seed = True


def main():
    args = parse_args()
    os.makedirs(args.out, exist_ok=True)
    globals()["build_" + args.scene]()
    scene = bpy.context.scene
    configure(scene, args)
    if args.frames > 0:
        animate(scene, args)
        for frame in range(1, args.frames + 1):
            scene.frame_set(frame)
            for spp in args.spp:
                render(scene, os.path.join(args.out, "spp%d.%04d.exr" % (spp, frame)), spp, spp, False)
            render(scene, os.path.join(args.out, "ref.%04d.exr" % frame), args.ref_spp, 7919, True)
        return
    for spp in args.spp:
        render(scene, os.path.join(args.out, "%s_%dspp.exr" % (args.scene, spp)), spp, spp, False)
    render(scene, os.path.join(args.out, "%s_ref.exr" % args.scene), args.ref_spp, 7919, True)


main()
