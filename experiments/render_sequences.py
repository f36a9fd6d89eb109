"""Frame sequences with motion vectors, for temporal denoising (Blender 3.4 .. 5.x Cycles).

Run inside Blender, or under a Python with the bpy module (PyPI bpy 5):
  blender -b --factory-startup --python-exit-code 1 --python experiments/render_sequences.py -- \
      --scene pan --out /work/data/temporal/pan --res 160x120 --frames 1-8 --spp 4 16 --ref-spp 1024
  /work/venv-render/bin/python experiments/render_sequences.py --scene convention --out DIR ...

Scenes (all small, deterministic, built here):
  pan        a room with objects; the camera slides sideways and turns a little
  still      the same room, a locked-off camera (one reference for every frame)
  object     locked-off camera, a box sweeping in front of the room (disocclusions)
  light      locked-off camera, the key light moving across the room
  orbit      the camera circling the room while a ball rolls across the floor (camera and
             object motion together; added after the filter's thresholds were set, as a
             held-out design)
  dolly      the camera pushing in and turning while a box slides diagonally across the floor
             (scale change, parallax and object motion; added on 2026-11-27 as a second
             held-out design, after that day's changes to the filter were chosen)
  lamp       the key light swinging towards the back wall and dimming while the camera
             slides (light and camera change together; added on 2026-11-27, held out
             from the relighting of neighbours whose light changed)
  convention a camera looking straight down at a textured plane, moving a known number of
             pixels per frame: (+3, +2) px from frame 1 to 2 and (+6, +4) px from 2 to 3
             (x right, y up, in the camera's view), to establish the Vector pass's
             direction and sign (tests/test_motion.cpp)

Every frame is a multilayer EXR with Combined, the Vector pass (motion blur off, as
Cycles needs for it), Denoising Data, Z and the diffuse/glossy/transmission light
passes (the convention scene: no light passes). The noise seed is animated (Cycles' "use_animated_seed"), as users render
animations; each --spp and the reference use different base seeds, so their
noise is independent. Writes DIR/spp<N>.<frame>.exr and DIR/ref.<frame>.exr
(for `still`: DIR/ref.exr, the one reference every frame shares). Files are
written under a temporary name and renamed when complete; existing ones are kept.
"""

import argparse
import math
import os
import sys
import time

import bpy

CONVENTION_HEIGHT = 10.0  # the convention scene's camera height over its plane


def script_argv():
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", choices=("pan", "still", "object", "light", "orbit", "dolly", "lamp", "convention"), required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--res", default="160x120", help="WIDTHxHEIGHT")
    p.add_argument("--frames", default="1-8", help="FIRST-LAST")
    p.add_argument("--spp", type=int, nargs="*", default=[4, 16])
    p.add_argument("--ref-spp", type=int, default=1024, help="0: no reference")
    p.add_argument("--ref-seed", type=int, default=7919,
                   help="the reference's noise seed (another seed renders an independent reference)")
    p.add_argument("--ref-name", default="ref", help="the reference files' name: NAME.####.exr")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--half", action="store_true", help="half-float channels (default: float)")
    p.add_argument("--fixed-seed", action="store_true", help="same noise seed in every frame (Blender's default)")
    return p.parse_args(script_argv())


def set_file_format(image_settings, file_format):
    """Blender 5 picks the media type (single or multilayer image) before the format."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "MULTI_LAYER_IMAGE" if file_format == "OPEN_EXR_MULTILAYER" else "IMAGE"
    image_settings.file_format = file_format


def configure(scene, args):
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.max_bounces = 6
    cyc.sample_clamp_indirect = 10.0
    cyc.use_animated_seed = not args.fixed_seed
    width, height = (int(v) for v in args.res.split("x"))
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    scene.render.use_persistent_data = True
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.use_motion_blur = False  # Cycles writes no Vector pass with motion blur on
    scene.render.use_file_extension = False
    set_file_format(scene.render.image_settings, "OPEN_EXR_MULTILAYER")
    scene.render.image_settings.exr_codec = "ZIP"
    scene.render.image_settings.color_depth = "16" if args.half else "32"
    layer = scene.view_layers[0]
    layer.name = "ViewLayer"
    layer.use_pass_combined = True
    layer.use_pass_z = True
    layer.use_pass_vector = True
    if args.scene != "convention":  # the test fixture keeps to what the tests read
        for kind in ("diffuse", "glossy", "transmission"):
            for part in ("direct", "indirect", "color"):
                setattr(layer, "use_pass_%s_%s" % (kind, part), True)
    layer.cycles.denoising_store_passes = True


def clear_scene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)


def material(name, color, roughness=0.8, checker=None):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = roughness
    if checker is None:
        bsdf.inputs["Base Color"].default_value = (*color, 1.0)
        return mat
    tex = nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = checker
    tex.inputs["Color1"].default_value = (*color, 1.0)
    tex.inputs["Color2"].default_value = tuple(0.25 * c for c in color) + (1.0,)
    noise = nodes.new("ShaderNodeTexNoise")  # texture detail, so misregistration shows
    noise.inputs["Scale"].default_value = checker * 1.7
    mix = nodes.new("ShaderNodeMixRGB")
    mix.inputs["Fac"].default_value = 0.35
    links = mat.node_tree.links
    links.new(tex.outputs["Color"], mix.inputs["Color1"])
    links.new(noise.outputs["Color"], mix.inputs["Color2"])
    links.new(mix.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def add_mesh(kind, name, location, scale, mat, rotation=(0, 0, 0)):
    ops = {"plane": bpy.ops.mesh.primitive_plane_add, "cube": bpy.ops.mesh.primitive_cube_add,
           "sphere": bpy.ops.mesh.primitive_uv_sphere_add, "cylinder": bpy.ops.mesh.primitive_cylinder_add}
    ops[kind](location=location, rotation=rotation)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = scale
    obj.data.materials.append(mat)
    if kind in ("sphere", "cylinder"):
        bpy.ops.object.shade_smooth()
    return obj


def drive(obj, path, index, expression):
    """Animation by a driver on `frame`: Cycles evaluates frames -1/+1 for the Vector
    pass through the depsgraph, and simple expressions need no Python auto-run."""
    fcurve = obj.driver_add(path, index)
    fcurve.driver.type = "SCRIPTED"
    fcurve.driver.expression = expression


def build_room(scene, args):
    """A small room: floor, back and side walls, three objects, a window-like area light
    (the key, direct) and a dim fill, so much of it is lit indirectly."""
    add_mesh("plane", "floor", (0, 0, 0), (6, 6, 1), material("floor", (0.7, 0.6, 0.45), 0.6, checker=6))
    add_mesh("plane", "back", (0, 4, 3), (6, 3, 1), material("back", (0.55, 0.6, 0.7), 0.9, checker=4),
             rotation=(math.pi / 2, 0, 0))
    add_mesh("plane", "left", (-4, 0, 3), (6, 3, 1), material("left", (0.7, 0.2, 0.15), 0.9),
             rotation=(math.pi / 2, 0, math.pi / 2))
    add_mesh("sphere", "ball", (-1.2, 1.2, 0.8), (0.8, 0.8, 0.8), material("ball", (0.8, 0.8, 0.8), 0.15))
    add_mesh("cube", "block", (1.3, 1.8, 0.6), (0.6, 0.6, 0.6), material("block", (0.2, 0.5, 0.25), 0.5),
             rotation=(0, 0, 0.5))
    add_mesh("cylinder", "pillar", (2.6, 0.2, 1.0), (0.35, 0.35, 1.0), material("pillar", (0.85, 0.75, 0.3), 0.3))
    key = bpy.data.lights.new("key", "AREA")
    key.energy = 900
    key.size = 1.5
    key_obj = bpy.data.objects.new("key", key)
    key_obj.location = (3.5, -1.0, 5.0)
    key_obj.rotation_euler = (0.5, 0.4, 0)
    scene.collection.objects.link(key_obj)
    fill = bpy.data.lights.new("fill", "POINT")
    fill.energy = 60
    fill_obj = bpy.data.objects.new("fill", fill)
    fill_obj.location = (-3.0, -3.0, 2.5)
    scene.collection.objects.link(fill_obj)
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.02, 0.025, 0.03, 1)
    scene.world = world

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 30
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.location = (0.5, -6.5, 2.6)
    cam.rotation_euler = (math.radians(76), 0, 0)
    if args.scene == "pan":  # about 2 px per frame sideways at 160 px, with a slow turn
        drive(cam, "location", 0, "0.5 - 0.06 * frame")
        drive(cam, "rotation_euler", 2, "0.004 * frame")
    elif args.scene == "object":  # a box sweeping right to left in front of the room, 5 px/frame
        box = add_mesh("cube", "mover", (0, -1.5, 0.9), (0.45, 0.45, 0.9),
                       material("mover", (0.15, 0.3, 0.8), 0.4, checker=3))
        drive(box, "location", 0, "3.0 - 0.28 * frame")
    elif args.scene == "light":  # the key light slides along the ceiling
        drive(key_obj, "location", 0, "3.5 - 0.6 * frame")
    elif args.scene == "orbit":  # about 1.5 degrees a frame around the room's centre, a ball rolling
        drive(cam, "location", 0, "0.5 + 7.0 * sin(0.026 * frame)")
        drive(cam, "location", 1, "0.5 - 7.0 * cos(0.026 * frame)")
        drive(cam, "rotation_euler", 2, "0.026 * frame")
        ball = add_mesh("sphere", "roller", (0, -1.0, 0.5), (0.5, 0.5, 0.5),
                        material("roller", (0.8, 0.35, 0.1), 0.3, checker=4))
        drive(ball, "location", 0, "-2.5 + 0.3 * frame")
        drive(ball, "rotation_euler", 1, "0.6 * frame")
    elif args.scene == "lamp":  # the key swinging back and dimming, the camera sliding 1 px/frame
        drive(key_obj, "location", 1, "-1.0 + 0.45 * frame")
        drive(key, "energy", -1, "900 - 50 * frame")
        drive(cam, "location", 0, "0.5 - 0.03 * frame")
    elif args.scene == "dolly":  # pushing in about 0.12 m a frame, turning left, a box sliding
        drive(cam, "location", 0, "0.5 + 0.04 * frame")
        drive(cam, "location", 1, "-6.5 + 0.12 * frame")
        drive(cam, "rotation_euler", 2, "0.006 * frame")
        box = add_mesh("cube", "mover", (-1.5, -0.5, 0.45), (0.35, 0.35, 0.45),
                       material("mover", (0.6, 0.15, 0.5), 0.4, checker=3))
        drive(box, "location", 0, "-1.8 + 0.2 * frame")
        drive(box, "location", 1, "-0.8 + 0.1 * frame")


def build_convention(scene, args):
    """A perspective camera looking straight down at a lit, textured plane, moving
    parallel to it: every point of the plane moves by the same known number of
    pixels. (An orthographic camera would do too, but Blender 5.0's Vector pass
    shows a zoom for one; a perspective camera is what users animate.)"""
    width, height = (int(v) for v in args.res.split("x"))
    add_mesh("plane", "ground", (0, 0, 0), (20, 20, 1), material("ground", (0.8, 0.7, 0.5), 0.9, checker=8))
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 3
    sun_obj = bpy.data.objects.new("sun", sun)
    sun_obj.rotation_euler = (0.3, 0.2, 0)
    scene.collection.objects.link(sun_obj)
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.3, 0.3, 1)
    scene.world = world
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens, cam_data.sensor_width, cam_data.sensor_fit = 50.0, 36.0, "HORIZONTAL"
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.location = (0, 0, CONVENTION_HEIGHT)  # looking down -Z: view x = world +X, view up = world +Y
    unit = CONVENTION_HEIGHT * cam_data.sensor_width / (cam_data.lens * width)  # world units per pixel
    # Position in pixels at frame f = 1, 2, 3: x = 1.5 (f - 1) f = 0, 3, 9; y = (f - 1) f = 0, 2, 6.
    drive(cam, "location", 0, "%.9g * 1.5 * (frame - 1) * frame" % unit)
    drive(cam, "location", 1, "%.9g * (frame - 1) * frame" % unit)


def render(scene, path, samples, seed):
    if os.path.exists(path):
        return
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    tmp = path + ".tmp.exr"
    scene.render.filepath = tmp
    start = time.time()
    bpy.ops.render.render(write_still=True)
    os.replace(tmp, path)
    print("render_sequences: %s (%d spp) in %.1f s" % (path, samples, time.time() - start), flush=True)


def main():
    args = parse_args()
    scene = bpy.context.scene
    clear_scene()
    configure(scene, args)
    (build_convention if args.scene == "convention" else build_room)(scene, args)
    first, last = (int(v) for v in args.frames.split("-"))
    scene.frame_start, scene.frame_end = first, last
    os.makedirs(args.out, exist_ok=True)
    for frame in range(first, last + 1):
        scene.frame_set(frame)
        for spp in args.spp:
            render(scene, os.path.join(args.out, "spp%d.%04d.exr" % (spp, frame)), spp, 1000 * spp)
        if args.ref_spp > 0 and (args.scene != "still" or frame == first):
            name = args.ref_name + (".exr" if args.scene == "still" else ".%04d.exr" % frame)
            render(scene, os.path.join(args.out, name), args.ref_spp, args.ref_seed)


if __name__ == "__main__":
    main()
