"""The evaluation shots: fifteen Blender 5 scenes of distinct designs, animated or locked off.

Run under a Python with the bpy module (PyPI bpy 5), one shot a call:
  build-venv-bpy/bin/python experiments/shots/shots.py --shot room_dolly --out /work/data/shots/room_dolly
  ... --res 64x48 --frames 1-1 --spp 16 --ref-spp 0      (a timing smoke test)
  ... --list                                             (the shots and their settings)
build_set.py runs every shot; README.md says what each covers, SPLIT.md which
half it belongs to.

Writes DIR/spp<N>.<frame>.exr and DIR/ref.<frame>.exr as experiments/render_sequences.py
does (a shot where nothing moves: one DIR/ref.exr), half-float multilayer EXR with
Combined, Vector (motion blur off), Denoising Data, Z and the diffuse, glossy and
transmission light passes; the noise seed animated. --check-frames also renders
DIR/ref2.<frame>.exr, a reference of another seed, to measure the reference's noise
(check_refs.py). Each file is written under a temporary name and renamed; existing
files are kept, so a run that was stopped resumes.
"""

import argparse
import math
import os
import sys
import time

import bpy
from mathutils import Vector

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ASSETS = os.path.join(ROOT, "assets", "gltf")
NOISY_SEED = 1000      # spp N uses seed 1000 * N (as render_sequences.py)
REF_SEED = 7919        # the reference
CHECK_SEED = 104729    # the second reference (ref2), independent of the first

# name: (resolution, reference spp, whether anything moves). The reference spp
# follows the measured noise of two references of different seeds and the hour
# the set may take (README.md, "References").
SHOTS = {
    "room_dolly":      ("128x96", 1024, True),
    "room_pan":        ("128x96", 1024, True),
    "room_still":      ("128x96", 4096, False),
    "fox_walk":        ("128x96", 2048, True),
    "helmet_orbit":    ("128x96", 1024, True),
    "vase_handheld":   ("96x128", 1024, True),
    "toycar_pass":     ("128x96", 1024, True),
    "truck_track":     ("128x96", 1024, True),
    "lamp_swing":      ("128x96", 1024, True),
    "sun_sweep":       ("128x96", 1024, True),
    "glass_turntable": ("128x96", 1024, True),
    "texture_dolly":   ("128x96", 1024, True),
    "fox_yard":        ("128x96", 1024, True),
    "attic_still":     ("128x96", 4096, False),
    "porch_still":     ("128x96", 4096, False),
}


def script_argv():
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--shot", choices=sorted(SHOTS))
    p.add_argument("--out")
    p.add_argument("--res", default="", help="WIDTHxHEIGHT (default: the shot's)")
    p.add_argument("--frames", default="1-8", help="FIRST-LAST")
    p.add_argument("--spp", type=int, nargs="*", default=[4, 16])
    p.add_argument("--ref-spp", type=int, default=-1, help="default: the shot's; 0: no reference")
    p.add_argument("--check-frames", default="", help="frames (comma-separated) that also get ref2")
    p.add_argument("--check-spp", type=int, default=0, help="ref2's spp (default: the reference's)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--list", action="store_true")
    return p.parse_args(script_argv())


# ---------------------------------------------------------------- render settings

def configure(scene, res, threads):
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.max_bounces = 8
    cyc.transmission_bounces = 8
    cyc.sample_clamp_indirect = 10.0
    cyc.sample_clamp_direct = 10.0  # sun and softbox glints on glass and chrome: +6 dB of reference noise on glass_turntable
    cyc.use_animated_seed = True
    scene.render.resolution_x, scene.render.resolution_y = (int(v) for v in res.split("x"))
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads
    scene.render.use_persistent_data = True
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.use_motion_blur = False  # Cycles writes no Vector pass with motion blur on
    scene.render.use_file_extension = False
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5 picks the media type before the format
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.exr_codec = "ZIP"
    settings.color_depth = "16"
    layer = scene.view_layers[0]
    layer.name = "ViewLayer"
    layer.use_pass_combined = layer.use_pass_z = layer.use_pass_vector = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(layer, "use_pass_%s_%s" % (kind, part), True)
    layer.cycles.denoising_store_passes = True


# ---------------------------------------------------------------- building blocks

def drive(target, path, index, expression):
    """Animate by a driver on `frame` (Cycles evaluates the neighbouring frames for
    the Vector pass; simple expressions need no Python auto-run)."""
    fcurve = target.driver_add(path, index)
    fcurve.driver.type = "SCRIPTED"
    fcurve.driver.expression = expression


def material(name, color, roughness=0.7, texture=None, scale=8.0, metallic=0.0, transmission=0.0):
    """A Principled BSDF; texture 'checker', 'brick', 'wood' or 'noise' modulates the colour."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Transmission Weight"].default_value = transmission
    dark = tuple(0.3 * c for c in color) + (1.0,)
    if texture is None:
        bsdf.inputs["Base Color"].default_value = (*color, 1.0)
        return mat
    if texture == "checker":
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Color1"].default_value, tex.inputs["Color2"].default_value = (*color, 1.0), dark
    elif texture == "brick":
        tex = nodes.new("ShaderNodeTexBrick")
        tex.inputs["Color1"].default_value, tex.inputs["Color2"].default_value = (*color, 1.0), dark
        tex.inputs["Mortar"].default_value = (0.9, 0.9, 0.85, 1.0)
        tex.inputs["Mortar Size"].default_value = 0.015
    elif texture == "wood":  # stretched wave bands: grain
        tex = nodes.new("ShaderNodeTexWave")
        tex.inputs["Distortion"].default_value = 6.0
        tex.inputs["Detail"].default_value = 4.0
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.elements[0].color, ramp.color_ramp.elements[1].color = dark, (*color, 1.0)
        links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
        tex.inputs["Scale"].default_value = scale
        links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
        return mat
    else:
        tex = nodes.new("ShaderNodeTexNoise")
        tex.inputs["Detail"].default_value = 12.0
    tex.inputs["Scale"].default_value = scale
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def box(name, centre, size, mat):
    bpy.ops.mesh.primitive_cube_add(location=centre)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = tuple(0.5 * s for s in size)
    obj.data.materials.append(mat)
    return obj


def sphere(name, centre, radius, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(location=centre, radius=radius, segments=48, ring_count=24)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(mat)
    bpy.ops.object.shade_smooth()
    return obj


def cylinder(name, centre, radius, depth, mat, smooth=True):
    bpy.ops.mesh.primitive_cylinder_add(location=centre, radius=radius, depth=depth, vertices=64)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(mat)
    if smooth:  # smooth sides, flat caps
        bpy.ops.object.shade_smooth_by_angle(angle=math.radians(40))
    return obj


def play(action):
    """Play one of the imported armature's actions (the Fox's Walk, Run or Survey) in
    place of the clips the importer stacked in the NLA."""
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    for track in list(arm.animation_data.nla_tracks):
        arm.animation_data.nla_tracks.remove(track)
    arm.animation_data.action = bpy.data.actions[action]
    return arm


def model(name, size, location=(0, 0, 0), turn=0.0, drop=()):
    """A glTF sample model from assets/gltf under one empty: its largest extent (as
    posed at import) `size` metres, standing on z = location.z, centred on location
    in x and y. Imported cameras and lights, and the objects named in `drop`, are removed."""
    folder = os.path.join(ASSETS, name)
    path = os.path.join(folder, name + ".glb")
    if not os.path.exists(path):
        path = os.path.join(folder, "glTF", name + ".gltf")
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=path)
    new = [o for o in bpy.data.objects if o not in before]
    for o in [o for o in new if o.type in ("CAMERA", "LIGHT") or o.name in drop]:
        new.remove(o)
        bpy.data.objects.remove(o, do_unlink=True)
    bpy.context.view_layer.update()
    graph = bpy.context.evaluated_depsgraph_get()
    corners = []
    for o in (o for o in new if o.type == "MESH"):
        posed = o.evaluated_get(graph)  # with the armature's deformation
        corners += [o.matrix_world @ v.co for v in posed.to_mesh().vertices]
        posed.to_mesh_clear()
    low = Vector([min(c[i] for c in corners) for i in range(3)])
    high = Vector([max(c[i] for c in corners) for i in range(3)])
    scale = size / max(high - low)
    holder = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(holder)
    inner = bpy.data.objects.new(name + "_offset", None)  # centres the model on the holder's origin
    bpy.context.scene.collection.objects.link(inner)
    inner.parent = holder
    for o in new:
        if o.parent is None:
            o.parent = inner
    inner.location = (-(low.x + high.x) / 2, -(low.y + high.y) / 2, -low.z)
    holder.scale = (scale, scale, scale)
    holder.location = location
    holder.rotation_euler = (0, 0, turn)
    return holder


def world_hdri(name, strength=1.0, turn=0.0):
    """One of Blender's bundled studio-light HDRIs (city, courtyard, forest, interior,
    night, studio, sunrise, sunset) as the world."""
    path = os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights", "world", name + ".exr")
    world = bpy.data.worlds.new(name)
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(path)
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0, 0, turn)
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    nodes["Background"].inputs["Strength"].default_value = strength
    bpy.context.scene.world = world
    return world


def world_colour(colour, strength=1.0):
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (*colour, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = strength
    bpy.context.scene.world = world
    return world


def light(kind, name, location, energy, size=0.1, rotation=(0, 0, 0), colour=(1, 1, 1)):
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    data.color = colour
    if kind == "SUN":
        data.angle = math.radians(size)
    elif kind == "AREA":
        data.size = size
    else:
        data.shadow_soft_size = size
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler = location, rotation
    return obj


def camera(location, target, lens=35.0):
    """A camera aimed at an empty by a Track To constraint: animate either (drivers)."""
    scene = bpy.context.scene
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    cam.data.lens = lens
    scene.collection.objects.link(cam)
    scene.camera = cam
    aim = bpy.data.objects.new("aim", None)
    scene.collection.objects.link(aim)
    cam.location, aim.location = location, target
    track = cam.constraints.new("TRACK_TO")
    track.target, track.track_axis, track.up_axis = aim, "TRACK_NEGATIVE_Z", "UP_Y"
    return cam, aim


def handheld(obj, amount):
    """A deterministic shake: sums of incommensurate sines, `amount` metres."""
    for axis, phase in enumerate((0.0, 1.3, 2.9)):
        drive(obj, "delta_location", axis, "%g * (sin(1.73 * frame + %g) + 0.6 * sin(4.31 * frame + %g))"
              % (amount, phase, 2 * phase))


def room(width, depth, height, window, floor_mat, wall_mat):
    """A closed room, x in [-w/2, w/2], y in [0, depth], z in [0, height]; a window
    opening (y0, y1, z0, z1) in the wall at x = +w/2. 0.1 m thick walls. The film is
    exposed a stop up, as a photographer would indoors."""
    bpy.context.scene.cycles.film_exposure = 2.0
    t, w2 = 0.1, width / 2
    box("floor", (0, depth / 2, -t / 2), (width + 2 * t, depth + 2 * t, t), floor_mat)
    box("ceiling", (0, depth / 2, height + t / 2), (width + 2 * t, depth + 2 * t, t), wall_mat)
    box("back", (0, depth + t / 2, height / 2), (width, t, height), wall_mat)
    box("front", (0, -t / 2, height / 2), (width, t, height), wall_mat)
    box("left", (-w2 - t / 2, depth / 2, height / 2), (t, depth, height), wall_mat)
    y0, y1, z0, z1 = window
    for name, (ya, yb, za, zb) in {"below": (0, depth, 0, z0), "above": (0, depth, z1, height),
                                  "side0": (0, y0, z0, z1), "side1": (y1, depth, z0, z1)}.items():
        box("window_" + name, (w2 + t / 2, (ya + yb) / 2, (za + zb) / 2), (t, yb - ya, zb - za), wall_mat)


def sun_through_window(energy=10.0, elevation=35.0, azimuth=200.0):
    """The sun outside the +x wall, shining in and down, a blue sky behind it."""
    world_colour((0.35, 0.5, 0.8), 2.0)
    return light("SUN", "sun", (8, 2, 6), energy, size=1.0,
                 rotation=(math.radians(90 - elevation), 0, math.radians(azimuth) - math.pi / 2))


# ---------------------------------------------------------------- the shots

def room_dolly():
    """Interior lit by the sun through a window; the camera pushes in on a chair and a sofa."""
    room(6, 7, 3, (1.0, 6.0, 0.3, 2.7), material("oak", (0.55, 0.35, 0.2), 0.4, "wood", 3.0),
         material("plaster", (0.8, 0.78, 0.72), 0.9))
    sun_through_window(10.0, 30.0, 195.0)
    model("GlamVelvetSofa", 2.2, (-1.6, 4.5, 0), math.pi / 2)
    model("SheenChair", 0.9, (0.6, 3.6, 0), -0.6)
    cam, aim = camera((0.3, 0.4, 1.5), (-0.5, 5.0, 0.7), 24)
    drive(cam, "location", 1, "0.4 + 0.16 * frame")
    drive(cam, "location", 0, "0.3 - 0.04 * frame")


def room_pan():
    """Another interior (long room, low sun, a rug); the camera pans from the window across the room."""
    room(5, 8, 2.8, (1.0, 7.0, 0.3, 2.5), material("tiles", (0.75, 0.72, 0.65), 0.3, "checker", 14.0),
         material("paint", (0.6, 0.7, 0.62), 0.85))
    sun_through_window(12.0, 20.0, 215.0)
    box("rug", (-0.6, 4.2, 0.005), (2.0, 3.0, 0.01), material("rug", (0.6, 0.15, 0.1), 0.9, "noise", 40.0))
    model("SheenChair", 0.9, (-1.2, 3.0, 0), 0.9)
    model("GlamVelvetSofa", 2.0, (-1.9, 6.0, 0), math.pi / 2)
    model("DamagedHelmet", 0.35, (1.6, 6.8, 0.0), -2.5)
    cam, aim = camera((0.0, 0.8, 1.6), (2.0, 4.5, 1.0), 28)
    drive(aim, "location", 0, "2.0 - 0.45 * frame")


def room_still():
    """A locked-off interior, nothing moving: sun through window slats onto a helmet on a table."""
    room(4, 5, 2.6, (0.4, 4.6, 0.3, 2.4), material("boards", (0.5, 0.4, 0.3), 0.5, "wood", 5.0),
         material("plaster", (0.85, 0.82, 0.78), 0.9))
    for i in range(6):  # horizontal slats in the window
        box("slat%d" % i, (2.05, 2.5, 1.2 + 0.2 * i), (0.02, 4.2, 0.05), material("slat", (0.9, 0.9, 0.9), 0.5))
    sun_through_window(10.0, 40.0, 205.0)
    box("table", (0.2, 2.8, 0.375), (1.2, 0.8, 0.75), material("table", (0.3, 0.2, 0.15), 0.25))
    model("DamagedHelmet", 0.4, (0.2, 2.8, 0.75), -2.2)
    model("SheenChair", 0.85, (-1.0, 2.6, 0), 1.2)
    camera((-1.2, 0.4, 1.5), (0.4, 3.0, 0.8), 28)


def fox_walk():
    """A skinned fox walking across a sunlit room; the camera pans to follow it."""
    room(6, 6, 2.8, (0.5, 5.5, 0.2, 2.6), material("floor", (0.6, 0.55, 0.45), 0.6, "brick", 6.0),
         material("wall", (0.75, 0.7, 0.6), 0.9))
    sun_through_window(10.0, 35.0, 200.0)
    fox = model("Fox", 1.0, (-2.2, 3.0, 0), -math.pi / 2)
    play("Walk")
    drive(fox, "location", 0, "-2.2 + 0.08 * frame")  # about a walking pace
    model("SheenChair", 0.9, (1.2, 4.2, 0), -2.4)
    cam, aim = camera((-0.6, 1.0, 1.0), (-1.9, 3.0, 0.35), 30)
    drive(aim, "location", 0, "-1.9 + 0.07 * frame")


def helmet_orbit():
    """A glossy, finely textured helmet on a stone plinth outdoors (courtyard HDRI, sun); an orbit."""
    world_hdri("courtyard", 1.0, 0.6)
    light("SUN", "sun", (0, 0, 10), 3.0, 2.0, (math.radians(45), 0, math.radians(30)))
    box("ground", (0, 0, -0.05), (12, 12, 0.1), material("paving", (0.55, 0.5, 0.45), 0.7, "brick", 4.0))
    box("plinth", (0, 0, 0.4), (0.6, 0.6, 0.8), material("stone", (0.6, 0.58, 0.55), 0.6, "noise", 30.0))
    model("DamagedHelmet", 0.5, (0, 0, 0.8), 0.4)
    cam, aim = camera((0, -2.2, 1.4), (0, 0, 1.0), 45)
    drive(cam, "location", 0, "2.2 * sin(0.05 * frame)")
    drive(cam, "location", 1, "-2.2 * cos(0.05 * frame)")


def vase_handheld():
    """Glass vase with flowers on a garden table (forest HDRI, sun); a handheld close-up (portrait)."""
    world_hdri("forest", 1.0, 2.0)
    light("SUN", "sun", (0, 0, 10), 4.0, 1.0, (math.radians(50), 0, math.radians(-40)))
    box("ground", (0, 0, -0.05), (10, 10, 0.1), material("grass", (0.2, 0.35, 0.1), 0.9, "noise", 60.0))
    box("table", (0, 0, 0.37), (1.0, 0.7, 0.04), material("teak", (0.45, 0.28, 0.15), 0.35, "wood", 6.0))
    for x in (-0.45, 0.45):
        for y in (-0.3, 0.3):
            box("leg", (x, y, 0.175), (0.04, 0.04, 0.35), material("leg", (0.3, 0.2, 0.1), 0.5))
    model("GlassVaseFlowers", 0.45, (0, 0, 0.39), 0.3)
    cam, aim = camera((0.25, -1.0, 0.75), (0, 0, 0.6), 40)
    handheld(cam, 0.006)
    handheld(aim, 0.004)


def toycar_pass():
    """A toy car rolling across a sunlit table (city HDRI): disocclusion and a moving shadow; handheld."""
    world_hdri("city", 1.0, 1.0)
    light("SUN", "sun", (0, 0, 10), 4.0, 1.0, (math.radians(40), 0, math.radians(70)))
    box("table", (0, 0, -0.02), (3, 2, 0.04), material("table", (0.6, 0.45, 0.3), 0.3, "wood", 12.0))
    box("book", (0.05, 0.25, 0.04), (0.22, 0.3, 0.08), material("book", (0.15, 0.25, 0.5), 0.6))
    car = model("ToyCar", 0.3, (-0.55, 0.05, 0), 0.0, drop=("Fabric",))
    drive(car, "location", 0, "-0.55 + 0.12 * frame")
    cam, aim = camera((0.1, -0.9, 0.45), (0.0, 0.1, 0.05), 35)
    handheld(cam, 0.003)


def truck_track():
    """A milk truck driving past posts on a road at sunset; the camera pans to track it."""
    world_hdri("sunset", 1.2, 0.0)
    light("SUN", "sun", (0, 0, 10), 3.0, 1.0, (math.radians(75), 0, math.radians(-60)))
    box("road", (0, 0, -0.05), (40, 6, 0.1), material("asphalt", (0.2, 0.2, 0.2), 0.8, "noise", 80.0))
    box("verge", (0, 8, -0.06), (40, 10, 0.1), material("grass", (0.25, 0.35, 0.12), 0.9, "noise", 30.0))
    for i in range(8):
        box("post%d" % i, (-7 + 2 * i, 3.5, 0.6), (0.15, 0.15, 1.2), material("post", (0.8, 0.8, 0.75), 0.5))
    truck = model("CesiumMilkTruck", 4.5, (-5.0, 0, 0), 0.0)
    drive(truck, "location", 0, "-5.0 + 0.7 * frame")
    cam, aim = camera((0.0, -9.0, 1.6), (-4.5, 0, 1.0), 35)
    drive(aim, "location", 0, "-4.5 + 0.7 * frame")  # (the model's own wheel spin plays too)


def lamp_swing():
    """Night interior: a hanging lamp swinging over a table with a vase and a chair (moving light, shadows)."""
    room(5, 5, 2.8, (1.5, 3.5, 1.0, 2.0), material("floor", (0.5, 0.45, 0.4), 0.5, "checker", 10.0),
         material("wall", (0.7, 0.68, 0.62), 0.9))
    world_colour((0.01, 0.015, 0.04), 1.0)
    box("table", (0, 2.8, 0.375), (1.2, 0.9, 0.75), material("table", (0.35, 0.22, 0.12), 0.3, "wood", 5.0))
    model("GlassVaseFlowers", 0.4, (0.2, 2.8, 0.75), 0.0)
    model("SheenChair", 0.85, (-0.9, 2.2, 0), 0.6)
    lamp = light("POINT", "lamp", (0, 2.8, 1.9), 40.0, 0.06, colour=(1.0, 0.85, 0.6))
    drive(lamp, "location", 0, "0.6 * sin(0.35 * frame)")
    drive(lamp, "location", 2, "1.9 + 0.15 * (1 - cos(0.35 * frame))")
    camera((-1.6, 0.3, 1.6), (0.1, 2.8, 0.9), 26)


def sun_sweep():
    """Outdoors, the sun moving fast (a time lapse) over a sofa and a helmet; a slow orbit."""
    world_hdri("sunrise", 0.6, 0.0)
    sun = light("SUN", "sun", (0, 0, 10), 5.0, 1.5)
    drive(sun, "rotation_euler", 0, "0.9 + 0.04 * frame")
    drive(sun, "rotation_euler", 2, "-0.5 + 0.12 * frame")
    box("deck", (0, 0, -0.05), (10, 10, 0.1), material("deck", (0.5, 0.4, 0.3), 0.5, "wood", 2.0))
    model("GlamVelvetSofa", 2.0, (0, 0.6, 0), 0.0)
    model("DamagedHelmet", 0.5, (0.9, -0.6, 0), 0.5)
    cam, aim = camera((0, -3.0, 1.4), (0, 0.2, 0.4), 35)
    drive(cam, "location", 0, "3.0 * sin(0.02 * frame)")
    drive(cam, "location", 1, "-3.0 * cos(0.02 * frame)")


def glass_turntable():
    """Glass and metal on a turntable in a studio (studio HDRI), a locked-off camera."""
    world_hdri("studio", 1.0, 0.0)
    light("AREA", "softbox", (1.5, -1.5, 2.5), 150.0, 1.2, (math.radians(45), 0, math.radians(45)))
    box("sweep", (0, 0, -0.05), (8, 8, 0.1), material("grey", (0.5, 0.5, 0.5), 0.6))
    table = bpy.data.objects.new("turntable", None)
    bpy.context.scene.collection.objects.link(table)
    drive(table, "rotation_euler", 2, "0.12 * frame")
    disc = box("disc", (0, 0, 0.02), (1.4, 1.4, 0.04), material("disc", (0.2, 0.2, 0.22), 0.2, "checker", 20.0))
    parts = [disc, sphere("glass", (0.35, 0, 0.2), 0.16, material("glass", (1, 1, 1), 0.0, transmission=1.0)),
             sphere("chrome", (-0.3, 0.2, 0.14), 0.1, material("chrome", (0.9, 0.9, 0.9), 0.08, metallic=1.0)),
             model("DamagedHelmet", 0.4, (-0.1, 0.35, 0.04), 0.0)]
    for part in parts:
        part.parent = table
    camera((0, -1.9, 0.9), (0, 0.1, 0.2), 40)


def texture_dolly():
    """Fine textures at a grazing angle (brick and tiles under sunrise light, a toy car); a dolly along the floor."""
    world_hdri("sunrise", 1.0, 2.5)
    light("SUN", "sun", (0, 0, 10), 3.0, 0.5, (math.radians(70), 0, math.radians(120)))
    box("floor", (0, 4, -0.05), (6, 12, 0.1), material("tiles", (0.7, 0.65, 0.55), 0.35, "brick", 12.0))
    box("wall", (-1.5, 4, 0.6), (0.1, 12, 1.2), material("bricks", (0.6, 0.3, 0.2), 0.8, "brick", 8.0))
    model("ToyCar", 0.5, (0.25, 2.2, 0), 2.4, drop=("Fabric",))
    model("Fox", 0.9, (-0.6, 4.0, 0), -0.8)
    cam, aim = camera((0.2, -0.5, 0.35), (0.0, 4.0, 0.1), 30)
    drive(cam, "location", 1, "-0.5 + 0.15 * frame")
    drive(aim, "location", 1, "4.0 + 0.15 * frame")


def fox_yard():
    """A fox running across a gravel yard under a low sun (city HDRI): a long moving
    shadow over fine texture, a low brick wall and bollards; the camera pans to follow it.
    Added to the tuning half after the set was first scored (SPLIT.md)."""
    world_hdri("city", 0.5, 2.2)
    light("SUN", "sun", (0, 0, 10), 2.5, 1.0, (math.radians(72), 0, math.radians(-140)))
    box("yard", (0, 2, -0.05), (30, 16, 0.1), material("gravel", (0.25, 0.23, 0.21), 0.85, "noise", 60.0))
    box("wall", (0, 5.0, 0.4), (30, 0.3, 0.8), material("wall", (0.55, 0.35, 0.25), 0.8, "brick", 6.0))
    for i in range(7):
        box("bollard%d" % i, (-4.5 + 1.5 * i, 2.6, 0.35), (0.12, 0.12, 0.7), material("bollard", (0.3, 0.3, 0.32), 0.4))
    fox = model("Fox", 1.3, (-3.0, 1.0, 0), -math.pi / 2)
    play("Run")
    drive(fox, "location", 0, "-3.0 + 0.35 * frame")
    cam, aim = camera((0.5, -4.5, 1.2), (-2.6, 1.0, 0.4), 35)
    drive(aim, "location", 0, "-2.6 + 0.35 * frame")


def attic_still():
    """A locked-off attic lit mostly by bounce: the sun through a small high window
    falls on the floor beside a sofa and a toy car on a crate. Nothing moves.
    Added to the tuning half after the set was scored (SPLIT.md)."""
    room(5, 6, 2.4, (2.0, 4.5, 0.9, 2.2), material("planks", (0.45, 0.35, 0.25), 0.6, "wood", 4.0),
         material("lime", (0.85, 0.83, 0.8), 0.95))
    sun_through_window(14.0, 40.0, 200.0)
    model("GlamVelvetSofa", 2.0, (-1.5, 4.2, 0), math.pi / 2)
    box("crate", (0.7, 4.4, 0.25), (0.6, 0.6, 0.5), material("crate", (0.5, 0.4, 0.3), 0.7, "wood", 6.0))
    model("ToyCar", 0.45, (0.7, 4.4, 0.5), 0.7, drop=("Fabric",))
    camera((0.9, 1.6, 1.3), (-0.7, 4.3, 0.5), 24)


def porch_still():
    """A locked-off porch outdoors (courtyard HDRI, sun): a chrome and a glass sphere
    and a toy car on a bench before a brick wall, hard shadows. Nothing moves.
    Added to the tuning half after the set was scored (SPLIT.md)."""
    world_hdri("courtyard", 0.6, 1.0)
    light("SUN", "sun", (0, 0, 10), 2.5, 1.0, (math.radians(55), 0, math.radians(-35)))
    box("deck", (0, 1, -0.05), (8, 6, 0.1), material("deck", (0.4, 0.3, 0.22), 0.5, "wood", 10.0))
    box("wall", (0, 2.2, 1.0), (8, 0.2, 2.0), material("bricks", (0.45, 0.22, 0.16), 0.8, "brick", 4.0))
    box("bench", (0, 1.5, 0.22), (1.6, 0.45, 0.44), material("bench", (0.35, 0.22, 0.12), 0.5, "wood", 6.0))
    sphere("chrome", (-0.5, 1.5, 0.56), 0.12, material("chrome", (0.9, 0.9, 0.9), 0.08, metallic=1.0))
    sphere("glass", (-0.15, 1.45, 0.58), 0.14, material("glass", (1, 1, 1), 0.0, transmission=1.0))
    model("ToyCar", 0.45, (0.4, 1.5, 0.44), 2.6, drop=("Fabric",))
    camera((0.5, 0.2, 0.75), (0.0, 1.5, 0.5), 35)


# ---------------------------------------------------------------- rendering

def render(scene, path, samples, seed):
    if os.path.exists(path):
        return
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    tmp = path + ".tmp.exr"
    scene.render.filepath = tmp
    start, cpu = time.time(), time.process_time()
    bpy.ops.render.render(write_still=True)
    os.replace(tmp, path)
    print("shots: %s (%d spp) %.2f s, %.2f s of CPU" % (path, samples, time.time() - start,
                                                       time.process_time() - cpu), flush=True)


def main():
    args = parse_args()
    if args.list:
        for name, (res, ref_spp, moving) in SHOTS.items():
            print(name, res, ref_spp, "moving" if moving else "still", "-", globals()[name].__doc__)
        return
    res, ref_spp, moving = SHOTS[args.shot]
    res = args.res or res
    ref_spp = ref_spp if args.ref_spp < 0 else args.ref_spp
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    scene = bpy.context.scene
    configure(scene, res, args.threads)
    start = time.time()
    globals()[args.shot]()
    print("shots: %s built in %.1f s" % (args.shot, time.time() - start), flush=True)
    first, last = (int(v) for v in args.frames.split("-"))
    scene.frame_start, scene.frame_end = first, last
    checks = {int(f) for f in args.check_frames.split(",") if f}
    os.makedirs(args.out, exist_ok=True)
    for frame in range(first, last + 1):
        scene.frame_set(frame)
        for spp in args.spp:
            render(scene, os.path.join(args.out, "spp%d.%04d.exr" % (spp, frame)), spp, NOISY_SEED * spp)
        if ref_spp > 0 and (moving or frame == first):
            name = "ref.%04d.exr" % frame if moving else "ref.exr"
            render(scene, os.path.join(args.out, name), ref_spp, REF_SEED)
        if frame in checks:
            name = "ref2.%04d.exr" % frame if moving else "ref2.exr"
            render(scene, os.path.join(args.out, name), args.check_spp or ref_spp, CHECK_SEED)


if __name__ == "__main__":
    main()
