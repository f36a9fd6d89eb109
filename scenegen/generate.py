"""Random-scene generator for denoiser training data (Blender 3.4 .. 5.x Cycles).

Run inside Blender, or under a Python with the bpy module (PyPI bpy 5):
  blender -b --factory-startup --python scenegen/generate.py -- \
      --seed 7 --scene-dir OUT/train/scene_000007 --res 128 --spp 4 --stacks 16 \
      --gt-spp 256 --frames 2 --threads 1
  /work/venv-bpy/bin/python scenegen/generate.py --jobs JOBS.json --res 128 ...

Builds each scene deterministically from its seed (one --seed, or every entry of
--jobs: [{seed, scene_dir, frames}]), then renders the requested frames of its
camera move: --stacks independent low-spp renders and two independent
ground-truth renders, each a multilayer EXR with all feature passes. All scenes
of a job list render in this one process (Cycles keeps a scene with persistent
data across its renders), so Blender's start-up is paid once per batch.
Every file is written under a temporary name and renamed when complete; a frame
is complete when its meta.json exists (written last). See docs/dataset.md.
"""

import argparse
import hashlib
import json
import math
import os
import random
import sys
import time

import bpy  # first: with the bpy module (Blender 5 from PyPI) bmesh and mathutils come with it
import bmesh  # noqa: I100
from mathutils import Euler, Matrix, Vector

GENERATOR_VERSION = "2.1.0"

WORLD_HDRI_DIR = "/usr/share/blender/datafiles/studiolights/world"
HDRI_NAMES = ["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"]
# Peak radiance of each studio-light HDRI (oiiotool --stats); bounds the brightest visible value.
HDRI_PEAK = {"city": 34000.0, "courtyard": 56.0, "forest": 1011.0, "interior": 34000.0,
             "night": 7200.0, "studio": 119.0, "sunrise": 33700.0, "sunset": 6520.0}
# Photographs shipped by Debian's mate-backgrounds package.
PHOTO_DIR = "/usr/share/backgrounds/mate"
PHOTO_NAMES = ["nature/Aqua.jpg", "nature/Blinds.jpg", "nature/Dune.jpg", "nature/FreshFlower.jpg",
               "nature/Garden.jpg", "nature/GreenMeadow.jpg", "nature/LadyBird.jpg",
               "nature/RainDrops.jpg", "nature/Storm.jpg", "nature/TwoWings.jpg", "nature/Wood.jpg",
               "nature/YellowFlower.jpg", "abstract/Elephants.jpg", "desktop/GreenTraditional.jpg"]

# Half floats overflow at 65504; keep every directly visible emitter below this after exposure.
MAX_EMITTER_RADIANCE = 30000.0
AOV_NAMES = ("roughness", "metallic", "transmission")


def script_argv():
    """Arguments after '--' under Blender; all of them when run by a Python with the bpy module."""
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:] if os.path.basename(sys.argv[0]) == "generate.py" else []


def parse_args():
    argv = script_argv()
    p = argparse.ArgumentParser(prog="generate.py")
    p.add_argument("--seed", type=int, help="one scene (with --scene-dir)")
    p.add_argument("--scene-dir")
    p.add_argument("--jobs", help="JSON file: a list of {seed, scene_dir, frames}, rendered in this one process")
    p.add_argument("--describe", metavar="FILE",
                   help="render nothing: build each job's scene and write [{seed, archetype, lighting}] to FILE")
    p.add_argument("--profile", action="store_true",
                   help="also time one extra EXR write per frame (meta.json: exr_write_seconds)")
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--stacks", type=int, default=16)
    p.add_argument("--gt-spp", type=int, default=1024)
    p.add_argument("--gt-depth", choices=["16", "32"], default="16")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--only-frames", default="", help="comma list of frame indices (default: all)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--codec", choices=["PXR24", "ZIP"], default="PXR24",
                   help="EXR compression; PXR24 is lossless for half channels, 24-bit for float ones")
    p.add_argument("--gt-count", type=int, choices=[0, 1, 2], default=2,
                   help="ground-truth renders per frame (2 for the data set)")
    p.add_argument("--seed-tag", default="",
                   help="mixed into every Cycles render seed (not the scene or exposure): a reference "
                        "rendered with a tag has noise independent of the data set's renders")
    args = p.parse_args(argv)
    if args.jobs is None and (args.seed is None or args.scene_dir is None):
        p.error("give --seed and --scene-dir, or --jobs")
    return args


def job_list(args):
    """[(seed, scene folder, frame indices)] from --jobs or --seed/--scene-dir/--only-frames."""
    if args.jobs is None:
        frames = [int(x) for x in args.only_frames.split(",") if x != ""] or list(range(args.frames))
        return [(args.seed, args.scene_dir, frames)]
    with open(args.jobs) as f:
        return [(int(j["seed"]), j["scene_dir"], [int(k) for k in j["frames"]]) for j in json.load(f)]


def derived_seed(*parts):
    """Stable 31-bit seed from any labelled tuple (independent of Python's hash salt)."""
    digest = hashlib.sha256(":".join(str(x) for x in parts).encode()).hexdigest()
    return int(digest[:8], 16) & 0x7FFFFFFF


# --------------------------------------------------------------------------- Blender 3.4 .. 5.x

def inp(node, *names):
    """The first of names that node has as an input (Principled inputs were renamed in 4.0)."""
    for name in names:
        if name in node.inputs:
            return node.inputs[name]
    raise KeyError("%s has none of the inputs %s" % (node.bl_idname, ", ".join(names)))


def set_enum(owner, prop, *values):
    """Sets the first of values that this Blender accepts for an enum property."""
    allowed = {item.identifier for item in owner.bl_rna.properties[prop].enum_items}
    for value in values:
        if value in allowed:
            setattr(owner, prop, value)
            return
    raise KeyError("%s.%s accepts none of %s" % (owner.bl_rna.identifier, prop, ", ".join(values)))


def set_file_format(image_settings, file_format):
    """Blender 5 picks the media type (single or multilayer image) before the format."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "MULTI_LAYER_IMAGE" if file_format == "OPEN_EXR_MULTILAYER" else "IMAGE"
    image_settings.file_format = file_format


def set_any(owner, props, value):
    """Sets the first of props that owner has; the value is drawn either way (same scene on every Blender)."""
    for prop in props:
        if hasattr(owner, prop):
            setattr(owner, prop, value)
            return


# --------------------------------------------------------------------------- render setup

def configure_render(scene, args):
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.use_preview_denoising = False
    cyc.sample_clamp_direct = 0.0  # 0 disables clamping: fireflies stay in the data
    cyc.sample_clamp_indirect = 0.0
    cyc.use_animated_seed = False
    cyc.max_bounces = 12
    cyc.transparent_max_bounces = 8
    scene.render.resolution_x = args.res
    scene.render.resolution_y = args.res
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    scene.render.use_persistent_data = True
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.film_transparent = False
    scene.render.use_motion_blur = False
    scene.render.use_file_extension = False
    set_file_format(scene.render.image_settings, "OPEN_EXR_MULTILAYER")
    scene.render.image_settings.exr_codec = args.codec
    scene.render.image_settings.color_depth = "16"

    layer = scene.view_layers[0]
    layer.name = "ViewLayer"
    layer.use_pass_combined = True
    layer.use_pass_z = True
    layer.use_pass_normal = True
    for kind in ("diffuse", "glossy", "transmission"):
        for part in ("direct", "indirect", "color"):
            setattr(layer, "use_pass_%s_%s" % (kind, part), True)
    layer.use_pass_emit = True
    layer.use_pass_environment = True
    layer.cycles.use_pass_volume_direct = True
    layer.cycles.use_pass_volume_indirect = True
    layer.cycles.denoising_store_passes = True
    for name in AOV_NAMES:
        aov = layer.aovs.add()
        aov.name = name
        aov.type = "VALUE"


# --------------------------------------------------------------------------- materials

class MaterialFactory:
    def __init__(self, rng, photos):
        self.rng = rng
        self.photos = photos
        self.count = 0
        self.max_emission = 0.0  # brightest emissive surface radiance, for the half-float bound
        self.log = []
        self.photo_all = False  # the "photo" archetype: every surface gets a photograph

    def random_color(self, sat=(0.0, 0.9), val=(0.05, 0.9)):
        import colorsys
        h = self.rng.random()
        s = self.rng.uniform(*sat)
        v = self.rng.uniform(*val)
        return (*colorsys.hsv_to_rgb(h, s, v), 1.0)

    def _coords(self, nt, scale):
        tc = nt.nodes.new("ShaderNodeTexCoord")
        mp = nt.nodes.new("ShaderNodeMapping")
        mp.inputs["Scale"].default_value = (scale, scale, scale)
        mp.inputs["Rotation"].default_value = (self.rng.uniform(0, 6.28), self.rng.uniform(0, 6.28),
                                               self.rng.uniform(0, 6.28))
        mp.inputs["Location"].default_value = (self.rng.uniform(-5, 5), self.rng.uniform(-5, 5), 0)
        nt.links.new(tc.outputs["Object"], mp.inputs["Vector"])
        return mp.outputs["Vector"]

    def _ramp(self, nt, fac_socket, colors):
        ramp = nt.nodes.new("ShaderNodeValToRGB")
        els = ramp.color_ramp.elements
        els[0].color = colors[0]
        els[1].color = colors[1]
        els[0].position = self.rng.uniform(0.0, 0.45)
        els[1].position = self.rng.uniform(0.55, 1.0)
        if len(colors) > 2:
            mid = els.new(self.rng.uniform(els[0].position, els[1].position))
            mid.color = colors[2]
        nt.links.new(fac_socket, ramp.inputs["Fac"])
        return ramp.outputs["Color"]

    def _procedural(self, nt, vec):
        """A random procedural texture; returns (colour-ish output, scalar output, label)."""
        kind = self.rng.choice(["noise", "voronoi", "wave", "checker", "brick", "magic", "musgrave"])
        if kind == "noise":
            t = nt.nodes.new("ShaderNodeTexNoise")
            t.inputs["Scale"].default_value = self.rng.uniform(1, 12)
            t.inputs["Detail"].default_value = self.rng.uniform(0, 10)
            t.inputs["Distortion"].default_value = self.rng.uniform(0, 2)
            fac = t.outputs["Fac"]
        elif kind == "voronoi":
            t = nt.nodes.new("ShaderNodeTexVoronoi")
            t.feature = self.rng.choice(["F1", "F2", "DISTANCE_TO_EDGE"])
            t.inputs["Scale"].default_value = self.rng.uniform(2, 20)
            fac = t.outputs["Distance"]
        elif kind == "wave":
            t = nt.nodes.new("ShaderNodeTexWave")
            t.wave_type = self.rng.choice(["BANDS", "RINGS"])
            t.inputs["Scale"].default_value = self.rng.uniform(1, 8)
            t.inputs["Distortion"].default_value = self.rng.uniform(0, 10)
            fac = t.outputs["Fac"]
        elif kind == "checker":
            t = nt.nodes.new("ShaderNodeTexChecker")
            t.inputs["Scale"].default_value = self.rng.uniform(2, 16)
            t.inputs["Color1"].default_value = (1, 1, 1, 1)
            t.inputs["Color2"].default_value = (0, 0, 0, 1)
            fac = t.outputs["Fac"]
        elif kind == "brick":
            t = nt.nodes.new("ShaderNodeTexBrick")
            t.inputs["Scale"].default_value = self.rng.uniform(2, 10)
            t.inputs["Mortar Size"].default_value = self.rng.uniform(0.005, 0.04)
            t.inputs["Color1"].default_value = (1, 1, 1, 1)
            t.inputs["Color2"].default_value = (0.6, 0.6, 0.6, 1)
            t.inputs["Mortar"].default_value = (0, 0, 0, 1)
            fac = t.outputs["Color"]
        elif kind == "magic":
            t = nt.nodes.new("ShaderNodeTexMagic")
            t.turbulence_depth = self.rng.randint(1, 4)
            t.inputs["Scale"].default_value = self.rng.uniform(1, 6)
            fac = t.outputs["Fac"]
        else:
            fractal = self.rng.choice(["FBM", "RIDGED_MULTIFRACTAL", "HETERO_TERRAIN"])
            if hasattr(bpy.types, "ShaderNodeTexMusgrave"):
                t = nt.nodes.new("ShaderNodeTexMusgrave")
                t.musgrave_type = fractal
            else:  # Blender 4.1+ merged Musgrave into Noise
                t = nt.nodes.new("ShaderNodeTexNoise")
                t.noise_type = fractal
            t.inputs["Scale"].default_value = self.rng.uniform(1, 10)
            fac = t.outputs["Fac"]
        nt.links.new(vec, t.inputs["Vector"])
        if fac.type == "RGBA":
            bw = nt.nodes.new("ShaderNodeRGBToBW")
            nt.links.new(fac, bw.inputs["Color"])
            fac = bw.outputs["Val"]
        colors = [self.random_color() for _ in range(self.rng.choice([2, 2, 3]))]
        return self._ramp(nt, fac, colors), fac, kind

    def _photo(self, nt, scale):
        path = self.rng.choice(self.photos)
        img = bpy.data.images.load(path, check_existing=True)
        t = nt.nodes.new("ShaderNodeTexImage")
        t.image = img
        t.projection = "BOX"
        t.projection_blend = self.rng.uniform(0.05, 0.3)
        t.interpolation = "Cubic"
        nt.links.new(self._coords(nt, scale), t.inputs["Vector"])
        bw = nt.nodes.new("ShaderNodeRGBToBW")
        nt.links.new(t.outputs["Color"], bw.inputs["Color"])
        return t.outputs["Color"], bw.outputs["Val"], os.path.basename(path)

    def _map_range(self, nt, socket, lo, hi):
        mr = nt.nodes.new("ShaderNodeMapRange")
        mr.inputs["To Min"].default_value = lo
        mr.inputs["To Max"].default_value = hi
        nt.links.new(socket, mr.inputs["Value"])
        return mr.outputs["Result"]

    def _value(self, nt, v):
        n = nt.nodes.new("ShaderNodeValue")
        n.outputs[0].default_value = v
        return n.outputs[0]

    def _write_aovs(self, nt, sockets):
        for name in AOV_NAMES:
            node = nt.nodes.new("ShaderNodeOutputAOV")
            if hasattr(node, "aov_name"):  # Blender 4+
                node.aov_name = name
            else:  # Blender 3.x: on this node type 'name' is the AOV it writes to
                node.name = name
            nt.links.new(sockets[name], node.inputs["Value"])

    def make(self, kind=None, scale=None, rough=None):
        """Principled-BSDF material of a random kind; AOV outputs carry its parameters.

        rough=(lo, hi) overrides the kind's roughness range (polished metals)."""
        rng = self.rng
        kind = kind or rng.choices(
            ["diffuse", "plastic", "metal", "glass", "rough_glass", "emissive", "subsurface",
             "coated", "rusty"],
            weights=[22, 20, 16, 10, 5, 4, 6, 7, 5])[0]
        self.count += 1
        mat = bpy.data.materials.new("mat_%03d_%s" % (self.count, kind))
        mat.use_nodes = True
        nt = mat.node_tree
        bsdf = nt.nodes["Principled BSDF"]
        scale = scale if scale is not None else rng.uniform(0.5, 4.0)
        vec = self._coords(nt, scale)
        info = {"kind": kind}

        # Base colour: constant, procedural, or photograph.
        src = rng.choices(["const", "proc", "photo"], weights=[3, 4, 3])[0]
        if kind in ("glass", "rough_glass") and src == "photo":
            src = "const"
        if self.photo_all:
            src = "photo"
        if src == "const":
            color_out, scalar_out = None, None
            bsdf.inputs["Base Color"].default_value = self.random_color()
            info["color"] = "const"
        elif src == "proc":
            color_out, scalar_out, label = self._procedural(nt, vec)
            nt.links.new(color_out, bsdf.inputs["Base Color"])
            info["color"] = label
        else:
            color_out, scalar_out, label = self._photo(nt, scale * rng.uniform(0.3, 1.0))
            nt.links.new(color_out, bsdf.inputs["Base Color"])
            info["color"] = "photo:" + label

        # Roughness: constant, or driven by the colour texture or an independent texture.
        r_lo, r_hi = rough or {"diffuse": (0.5, 1.0), "plastic": (0.05, 0.5), "metal": (0.0, 0.45),
                               "glass": (0.0, 0.05), "rough_glass": (0.1, 0.4), "emissive": (0.3, 0.8),
                               "subsurface": (0.2, 0.7), "coated": (0.2, 0.8), "rusty": (0.2, 0.9)}[kind]
        mode = rng.choice(["const", "const", "texture"])
        if mode == "texture" and kind not in ("glass",):
            driver = scalar_out if (scalar_out is not None and rng.random() < 0.5) else \
                self._procedural(nt, self._coords(nt, rng.uniform(1, 6)))[1]
            rough = self._map_range(nt, driver, r_lo, r_hi)
            info["roughness"] = "texture"
        else:
            rough = self._value(nt, rng.uniform(r_lo, r_hi))
            info["roughness"] = round(rough.default_value, 3)
        nt.links.new(rough, bsdf.inputs["Roughness"])

        metallic = self._value(nt, 0.0)
        transmission = self._value(nt, 0.0)
        if kind == "metal":
            metallic.default_value = 1.0
            if src == "const":
                bsdf.inputs["Base Color"].default_value = rng.choice(
                    [(0.95, 0.64, 0.54, 1), (1.0, 0.78, 0.34, 1), (0.91, 0.92, 0.92, 1),
                     (0.55, 0.56, 0.55, 1), (0.96, 0.96, 0.97, 1), self.random_color((0, 0.6), (0.4, 1))])
        elif kind == "rusty":
            # Metal with a procedural mask of rough dielectric rust: metallic varies per pixel.
            mask = self._procedural(nt, self._coords(nt, rng.uniform(1, 5)))[1]
            metallic = self._map_range(nt, mask, 0.0, 1.0)
            metallic.node.clamp = True
            metallic.node.inputs["From Min"].default_value = 0.45
            metallic.node.inputs["From Max"].default_value = 0.55
        elif kind in ("glass", "rough_glass"):
            transmission.default_value = 1.0
            bsdf.inputs["IOR"].default_value = rng.uniform(1.33, 1.7)
            tint = self.random_color((0.0, 0.35), (0.85, 1.0))
            bsdf.inputs["Base Color"].default_value = tint
        elif kind == "subsurface":
            inp(bsdf, "Subsurface Weight", "Subsurface").default_value = rng.uniform(0.3, 1.0)
            bsdf.inputs["Subsurface Radius"].default_value = (rng.uniform(0.2, 1.0), rng.uniform(0.1, 0.6),
                                                              rng.uniform(0.05, 0.3))
            bsdf.subsurface_method = "RANDOM_WALK"
            if src == "const" and "Subsurface Color" in bsdf.inputs:  # gone in Blender 4
                bsdf.inputs["Subsurface Color"].default_value = bsdf.inputs["Base Color"].default_value
        elif kind == "coated":
            inp(bsdf, "Coat Weight", "Clearcoat").default_value = rng.uniform(0.5, 1.0)
            inp(bsdf, "Coat Roughness", "Clearcoat Roughness").default_value = rng.uniform(0.0, 0.1)
            inp(bsdf, "Sheen Weight", "Sheen").default_value = rng.uniform(0.0, 0.5)
        elif kind == "emissive":
            strength = rng.uniform(2.0, 40.0)
            color = self.random_color((0.0, 0.7), (0.8, 1.0))
            inp(bsdf, "Emission Color", "Emission").default_value = color
            if src == "photo":  # a lit screen or poster
                nt.links.new(color_out, inp(bsdf, "Emission Color", "Emission"))
                color = (1.0, 1.0, 1.0)
            bsdf.inputs["Emission Strength"].default_value = strength
            self.max_emission = max(self.max_emission, strength * max(color[:3]))
            info["emission"] = round(strength, 2)
        nt.links.new(metallic, bsdf.inputs["Metallic"])
        nt.links.new(transmission, inp(bsdf, "Transmission Weight", "Transmission"))
        self._write_aovs(nt, {"roughness": rough, "metallic": metallic, "transmission": transmission})
        self.log.append(info)
        return mat

    def foliage(self):
        """Leaf cards: a photograph or a green ramp, cut out by a thresholded noise or Voronoi alpha."""
        rng = self.rng
        self.count += 1
        mat = bpy.data.materials.new("mat_%03d_foliage" % self.count)
        mat.use_nodes = True
        mat.blend_method = "CLIP"  # EEVEE only; Cycles always uses the alpha
        nt = mat.node_tree
        bsdf = nt.nodes["Principled BSDF"]
        vec = self._coords(nt, rng.uniform(2.0, 8.0))
        if self.photo_all or rng.random() < 0.5:
            color_out, _, label = self._photo(nt, rng.uniform(0.5, 2.0))
            label = "photo:" + label
        else:
            greens = [self.random_color((0.5, 0.9), (0.05, 0.5)) for _ in range(2)]
            greens = [(c[0] * 0.5, c[1], c[2] * 0.4, 1.0) for c in greens]
            noise = nt.nodes.new("ShaderNodeTexNoise")
            noise.inputs["Scale"].default_value = rng.uniform(4, 20)
            nt.links.new(vec, noise.inputs["Vector"])
            color_out, label = self._ramp(nt, noise.outputs["Fac"], greens), "green"
        nt.links.new(color_out, bsdf.inputs["Base Color"])
        # Leaves: discs (or diamonds) around Voronoi points, 8-33 cm apart in the card's own
        # space, covering 13-50% of it, so a bush is seen through.
        cut = nt.nodes.new("ShaderNodeTexVoronoi")
        cut.distance = "EUCLIDEAN" if rng.random() < 0.5 else "MANHATTAN"
        cut.inputs["Scale"].default_value = rng.uniform(3, 12)
        nt.links.new(nt.nodes.new("ShaderNodeTexCoord").outputs["Object"], cut.inputs["Vector"])
        alpha = self._map_range(nt, cut.outputs["Distance"], 0.0, 1.0)
        alpha.node.clamp = True
        edge = rng.uniform(0.35, 0.55) - 0.15
        alpha.node.inputs["From Min"].default_value = edge + 0.02
        alpha.node.inputs["From Max"].default_value = edge  # inverted: near the cell centre is leaf
        nt.links.new(alpha, bsdf.inputs["Alpha"])
        rough = self._value(nt, rng.uniform(0.4, 0.9))
        nt.links.new(rough, bsdf.inputs["Roughness"])
        self._write_aovs(nt, {"roughness": rough, "metallic": self._value(nt, 0.0),
                              "transmission": self._value(nt, 0.0)})
        self.log.append({"kind": "foliage", "color": label})
        return mat


# --------------------------------------------------------------------------- geometry

def new_object(name, mesh_or_curve):
    obj = bpy.data.objects.new(name, mesh_or_curve)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def mesh_from_bmesh(name, bm, smooth=False):
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    if smooth:
        me.polygons.foreach_set("use_smooth", [True] * len(me.polygons))
    return new_object(name, me)


def set_smooth(obj):
    me = obj.data
    me.polygons.foreach_set("use_smooth", [True] * len(me.polygons))


def primitive(rng, name):
    kind = rng.choice(["cube", "uv_sphere", "ico_sphere", "cylinder", "cone", "torus", "monkey"])
    ops = bpy.ops.mesh
    if kind == "cube":
        ops.primitive_cube_add(size=1.0)
    elif kind == "uv_sphere":
        ops.primitive_uv_sphere_add(radius=0.5, segments=48, ring_count=24)
    elif kind == "ico_sphere":
        ops.primitive_ico_sphere_add(radius=0.5, subdivisions=rng.choice([1, 2, 4]))
    elif kind == "cylinder":
        ops.primitive_cylinder_add(radius=0.5, depth=1.0, vertices=48)
    elif kind == "cone":
        ops.primitive_cone_add(radius1=0.5, radius2=rng.choice([0.0, 0.2]), depth=1.0, vertices=48)
    elif kind == "torus":
        ops.primitive_torus_add(major_radius=0.4, minor_radius=rng.uniform(0.04, 0.15),
                                major_segments=64, minor_segments=24)
    else:
        ops.primitive_monkey_add(size=1.0)
    obj = bpy.context.active_object
    obj.name = name
    if kind in ("uv_sphere", "cylinder", "cone", "torus", "monkey") or (kind == "ico_sphere" and rng.random() < 0.5):
        set_smooth(obj)
    if kind == "monkey":
        obj.modifiers.new("subd", "SUBSURF").levels = 2
    return obj, kind


def displaced_blob(rng, name):
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.5, subdivisions=5)
    obj = bpy.context.active_object
    obj.name = name
    set_smooth(obj)
    tex = bpy.data.textures.new(name + "_tex", rng.choice(["CLOUDS", "VORONOI", "MUSGRAVE", "DISTORTED_NOISE"]))
    tex.noise_scale = rng.uniform(0.2, 0.8)
    mod = obj.modifiers.new("disp", "DISPLACE")
    mod.texture = tex
    mod.texture_coords = "LOCAL"
    mod.strength = rng.uniform(0.08, 0.35)
    mod.mid_level = 0.5
    return obj, "displaced_" + tex.type.lower()


def bevelled_box(rng, name):
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (rng.uniform(0.4, 1.6), rng.uniform(0.4, 1.6), rng.uniform(0.3, 1.4))
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    mod = obj.modifiers.new("bevel", "BEVEL")
    mod.width = rng.uniform(0.02, 0.15)
    mod.segments = rng.randint(1, 5)
    mod.limit_method = "ANGLE"
    if rng.random() < 0.5:
        obj.modifiers.new("subd", "SUBSURF").levels = 1
    set_smooth(obj)
    mod.harden_normals = False
    return obj, "bevelled_box"


def subdivided_shape(rng, name):
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    # Random extrusions before subdivision give lumpy organic shapes.
    for _ in range(rng.randint(1, 4)):
        bm.faces.ensure_lookup_table()
        face = bm.faces[rng.randrange(len(bm.faces))]
        res = bmesh.ops.extrude_discrete_faces(bm, faces=[face])
        nf = res["faces"][0]
        offset = nf.normal * rng.uniform(0.2, 0.7)
        bmesh.ops.translate(bm, verts=nf.verts, vec=offset)
        bmesh.ops.scale(bm, verts=nf.verts, vec=Vector([rng.uniform(0.4, 1.0)] * 3),
                        space=Matrix.Translation(-nf.calc_center_median()))
    obj = mesh_from_bmesh(name, bm, smooth=True)
    obj.modifiers.new("subd", "SUBSURF").levels = rng.choice([2, 3])
    return obj, "subdivided"


def lathe(rng, name):
    """Vase, cup or bowl: a random profile spun around Z (glass versions make caustics)."""
    bm = bmesh.new()
    n = rng.randint(5, 9)
    height = rng.uniform(0.4, 1.3)
    radii = [rng.uniform(0.1, 0.45) for _ in range(n)]
    radii[0] = max(radii[0], 0.15)
    wall = rng.uniform(0.015, 0.05)
    outer = [(radii[i], 0.0, height * i / (n - 1)) for i in range(n)]
    inner = [(max(r - wall, 0.01), 0.0, z) for (r, _, z) in reversed(outer)]
    inner[-1] = (0.0, 0.0, wall)
    pts = [(0.0, 0.0, 0.0)] + outer + inner
    verts = [bm.verts.new(p) for p in pts]
    edges = [bm.edges.new((verts[i], verts[i + 1])) for i in range(len(verts) - 1)]
    bmesh.ops.spin(bm, geom=verts + edges, cent=(0, 0, 0), axis=(0, 0, 1), angle=2 * math.pi,
                   steps=48, use_merge=True)
    bmesh.ops.remove_doubles(bm, verts=bm.verts, dist=1e-5)
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
    obj = mesh_from_bmesh(name, bm, smooth=True)
    obj.modifiers.new("subd", "SUBSURF").levels = 1
    return obj, "lathe"


def text_object(rng, name):
    curve = bpy.data.curves.new(name, "FONT")
    letters = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijkmnopqrstuvwxyz0123456789&?#@"
    curve.body = "".join(rng.choice(letters) for _ in range(rng.randint(1, 5)))
    curve.extrude = rng.uniform(0.03, 0.15)
    curve.bevel_depth = rng.uniform(0.0, 0.02)
    curve.align_x = "CENTER"
    curve.size = rng.uniform(0.5, 1.0)
    obj = new_object(name, curve)
    obj.rotation_euler = (math.pi / 2, 0, 0)
    return obj, "text"


def railing(rng, name):
    """Thin posts and rails: sub-pixel geometry and thin shadows."""
    bm = bmesh.new()
    length = rng.uniform(1.5, 3.5)
    height = rng.uniform(0.5, 1.1)
    posts = rng.randint(5, 16)
    r = rng.uniform(0.006, 0.025)
    for i in range(posts):
        x = -length / 2 + length * i / (posts - 1)
        bmesh.ops.create_cone(bm, cap_ends=True, segments=8, radius1=r, radius2=r, depth=height,
                              matrix=Matrix.Translation((x, 0, height / 2)))
    rot = Matrix.Rotation(math.pi / 2, 4, "Y")
    for h in ([height] + ([height * 0.5] if rng.random() < 0.6 else [])):
        bmesh.ops.create_cone(bm, cap_ends=True, segments=8, radius1=r * 1.5, radius2=r * 1.5,
                              depth=length, matrix=Matrix.Translation((0, 0, h)) @ rot)
    return mesh_from_bmesh(name, bm, smooth=True), "railing"


def wires(rng, name):
    """Sagging cables between two points: very thin curves."""
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = rng.uniform(0.002, 0.012)
    curve.bevel_resolution = 2
    span = rng.uniform(1.5, 4.0)
    for _ in range(rng.randint(1, 5)):
        sp = curve.splines.new("POLY")
        n = 24
        sp.points.add(n - 1)
        y0 = rng.uniform(-0.4, 0.4)
        z0 = rng.uniform(0.4, 1.5)
        sag = rng.uniform(0.05, 0.5)
        for i, pt in enumerate(sp.points):
            t = i / (n - 1)
            pt.co = (span * (t - 0.5), y0, z0 - sag * 4 * t * (1 - t), 1.0)
    return new_object(name, curve), "wires"


def wire_cage(rng, name):
    """Grid or sphere turned into a wireframe: fences, cages, meshes of thin bars."""
    if rng.random() < 0.5:
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=rng.randint(4, 16), y_subdivisions=rng.randint(4, 16),
                                        size=rng.uniform(1.0, 2.5))
        obj = bpy.context.active_object
        obj.rotation_euler = (math.pi / 2, 0, 0)
        label = "fence"
    else:
        bpy.ops.mesh.primitive_ico_sphere_add(radius=0.5, subdivisions=rng.randint(1, 3))
        obj = bpy.context.active_object
        label = "cage"
    obj.name = name
    mod = obj.modifiers.new("wire", "WIREFRAME")
    mod.thickness = rng.uniform(0.005, 0.03)
    return obj, label


def foliage(rng, name):
    """A bush or branch of alpha-cut leaf cards around a point: thin, semi-transparent edges."""
    bm = bmesh.new()
    radius = rng.uniform(0.2, 0.7)
    for _ in range(rng.randint(6, 24)):
        size = rng.uniform(0.15, 0.5)
        rot = Euler((rng.uniform(0, math.pi), rng.uniform(0, math.pi), rng.uniform(0, 2 * math.pi))).to_matrix()
        centre = Vector((rng.gauss(0, radius), rng.gauss(0, radius), abs(rng.gauss(0, radius)) + size / 2))
        bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=size / 2,
                              matrix=Matrix.Translation(centre) @ rot.to_4x4())
    return mesh_from_bmesh(name, bm), "foliage"


def glass_pane(rng, name):
    """A thin upright slab: emitters behind it are seen refracted and doubled."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (rng.uniform(0.6, 1.6), rng.uniform(0.01, 0.04), rng.uniform(0.5, 1.2))
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    return obj, "glass_pane"


GEOMETRY = [(primitive, 30), (displaced_blob, 10), (bevelled_box, 10), (subdivided_shape, 8),
            (lathe, 10), (text_object, 7), (railing, 7), (wires, 5), (wire_cage, 6), (foliage, 4)]
# Mostly thin geometry: wires, railings, fences and cages, leaf cards.
THIN_GEOMETRY = [(railing, 10), (wires, 8), (wire_cage, 8), (foliage, 10), (primitive, 4)]
# Solid shapes that show reflections well.
SOLID_GEOMETRY = [(primitive, 30), (displaced_blob, 10), (bevelled_box, 10), (subdivided_shape, 8),
                  (lathe, 12), (text_object, 4)]
GLASS_GEOMETRY = [(lathe, 10), (primitive, 6), (glass_pane, 6)]


def evaluated_bounds(obj):
    bpy.context.view_layer.update()
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    corners = [obj.matrix_world @ Vector(c) for c in ev.bound_box]
    lo = Vector([min(c[i] for c in corners) for i in range(3)])
    hi = Vector([max(c[i] for c in corners) for i in range(3)])
    return lo, hi


def place_on(obj, x, y, floor_z):
    lo, _ = evaluated_bounds(obj)
    obj.location.x += x
    obj.location.y += y
    obj.location.z += floor_z - lo.z


# --------------------------------------------------------------------------- lights and world

class Lighting:
    def __init__(self, rng):
        self.rng = rng
        self.max_radiance = 0.0  # brightest directly visible emitter radiance (W/m^2/sr)
        self.log = []

    def _add(self, kind, energy, location, target=None, **extra):
        light = bpy.data.lights.new("light_%d" % len(self.log), kind)
        light.energy = energy
        obj = new_object(light.name, light)
        obj.location = location
        if target is not None:
            direction = Vector(target) - Vector(location)
            obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
        for k, v in extra.items():
            setattr(light, k, v)
        light.color = self.random_color((0.0, 0.35), (1.0, 1.0))[:3]
        self.log.append({"type": kind, "energy": round(energy, 2), "location": [round(c, 3) for c in location]})
        return light

    def random_color(self, sat, val):
        import colorsys
        return (*colorsys.hsv_to_rgb(self.rng.random(), self.rng.uniform(*sat), self.rng.uniform(*val)), 1.0)

    def area(self, location, target, power_scale=1.0):
        size = self.rng.uniform(0.2, 2.0)
        d = (Vector(location) - Vector(target)).length
        energy = self.rng.uniform(20, 150) * d * d * power_scale
        light = self._add("AREA", energy, location, target, size=size,
                          shape=self.rng.choice(["SQUARE", "DISK", "RECTANGLE"]))
        light.size_y = size * self.rng.uniform(0.2, 1.0)
        self.max_radiance = max(self.max_radiance, energy / (math.pi * size * light.size_y))

    def spot(self, location, target):
        d = (Vector(location) - Vector(target)).length
        radius = self.rng.uniform(0.005, 0.2)
        energy = self.rng.uniform(50, 400) * d * d
        self._add("SPOT", energy, location, target, spot_size=self.rng.uniform(0.3, 1.5),
                  spot_blend=self.rng.uniform(0.0, 0.5), shadow_soft_size=radius)
        self.max_radiance = max(self.max_radiance, energy / (4 * math.pi * math.pi * radius * radius))

    def point(self, location, small=False):
        radius = self.rng.uniform(0.003, 0.03) if small else self.rng.uniform(0.02, 0.3)
        d = max(Vector(location).length, 1.0)
        energy = self.rng.uniform(20, 300) * d
        self._add("POINT", energy, location, shadow_soft_size=radius)
        self.max_radiance = max(self.max_radiance, energy / (4 * math.pi * math.pi * radius * radius))

    def sun(self, elevation, azimuth, strength=None):
        angle = math.radians(self.rng.uniform(0.5, 8.0))
        strength = strength if strength is not None else self.rng.uniform(1.0, 6.0)
        light = self._add("SUN", strength, (0, 0, 10), angle=angle)
        bpy.data.objects[light.name].rotation_euler = Euler((math.pi / 2 - elevation, 0, azimuth + math.pi / 2))
        # Seen in a mirror the sun disc has radiance E / solid angle.
        solid_angle = math.pi * (angle / 2) ** 2
        self.max_radiance = max(self.max_radiance, strength / solid_angle)


def make_world(rng, lighting, style, hdris=HDRI_NAMES):
    world = bpy.data.worlds.new("world")
    bpy.context.scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    bg = nt.nodes["Background"]
    info = {"style": style}
    if style == "hdri":
        name = rng.choice(hdris)
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(os.path.join(WORLD_HDRI_DIR, name + ".exr"), check_existing=True)
        tc = nt.nodes.new("ShaderNodeTexCoord")
        mp = nt.nodes.new("ShaderNodeMapping")
        mp.inputs["Rotation"].default_value = (0, 0, rng.uniform(0, 2 * math.pi))
        nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
        nt.links.new(mp.outputs["Vector"], env.inputs["Vector"])
        nt.links.new(env.outputs["Color"], bg.inputs["Color"])
        strength = rng.uniform(0.3, 2.0)
        bg.inputs["Strength"].default_value = strength
        lighting.max_radiance = max(lighting.max_radiance, strength * HDRI_PEAK[name])
        info.update(hdri=name, strength=round(strength, 3))
    elif style == "sky":
        sky = nt.nodes.new("ShaderNodeTexSky")
        set_enum(sky, "sky_type", "NISHITA", "SINGLE_SCATTERING")  # renamed in Blender 5
        sky.sun_disc = False  # the sun is a separate sun lamp; the disc would overflow half floats
        elevation = math.radians(rng.uniform(3, 70))
        azimuth = rng.uniform(0, 2 * math.pi)
        sky.sun_elevation = elevation
        sky.sun_rotation = azimuth
        set_any(sky, ("air_density",), rng.uniform(0.5, 3.0))
        set_any(sky, ("dust_density", "aerosol_density"), rng.uniform(0.0, 4.0))
        nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
        strength = rng.uniform(0.05, 0.25)
        bg.inputs["Strength"].default_value = strength
        lighting.sun(elevation, azimuth, strength=rng.uniform(2.0, 6.0) * math.sin(elevation) ** 0.5)
        info.update(sun_elevation_deg=round(math.degrees(elevation), 1), strength=round(strength, 3))
    elif style == "color":
        color = lighting.random_color((0.0, 0.5), (0.1, 1.0))
        bg.inputs["Color"].default_value = color
        strength = rng.uniform(0.1, 1.0)
        bg.inputs["Strength"].default_value = strength
        info.update(strength=round(strength, 3))
    elif style == "night":  # a faint blue sky glow; lamps do the rest
        bg.inputs["Color"].default_value = (0.02, 0.03, 0.08, 1.0)
        strength = rng.uniform(0.02, 0.3)
        bg.inputs["Strength"].default_value = strength
        info.update(strength=round(strength, 3))
    else:  # dark: lights only
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0
    return info


# --------------------------------------------------------------------------- scene

def add_volume(rng, mats_log, half_extent, height):
    """Participating media: thin fog filling the set, or a dense noisy cloud."""
    mat = bpy.data.materials.new("volume")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    vol = nt.nodes.new("ShaderNodeVolumePrincipled")
    out = nt.nodes["Material Output"]
    nt.links.new(vol.outputs["Volume"], out.inputs["Volume"])
    vol.inputs["Anisotropy"].default_value = rng.uniform(-0.3, 0.7)
    vol.inputs["Color"].default_value = (*[rng.uniform(0.6, 1.0) for _ in range(3)], 1.0)
    if rng.random() < 0.5:
        bpy.ops.mesh.primitive_cube_add(size=2.0)
        obj = bpy.context.active_object
        obj.scale = (half_extent, half_extent, height / 2)
        obj.location = (0, 0, height / 2 - 0.01)
        vol.inputs["Density"].default_value = rng.uniform(0.01, 0.12)
        obj["fog"] = True
        label = "fog"
    else:
        bpy.ops.mesh.primitive_ico_sphere_add(radius=rng.uniform(0.4, 1.2), subdivisions=3)
        obj = bpy.context.active_object
        obj.location = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.3, 1.2))
        noise = nt.nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = rng.uniform(1.5, 5.0)
        mr = nt.nodes.new("ShaderNodeMapRange")
        mr.inputs["From Min"].default_value = 0.45
        mr.inputs["To Max"].default_value = rng.uniform(1.0, 6.0)
        nt.links.new(noise.outputs["Fac"], mr.inputs["Value"])
        nt.links.new(mr.outputs["Result"], vol.inputs["Density"])
        label = "cloud"
    obj.name = "volume"
    obj.data.materials.append(mat)
    mats_log.append({"kind": "volume_" + label})
    return label


def build_floor(rng, mats, archetype):
    bpy.ops.mesh.primitive_plane_add(size=60.0 if archetype != "interior" else 12.0)
    floor = bpy.context.active_object
    floor.name = "floor"
    floor.data.materials.append(mats.make(rng.choice(["diffuse", "diffuse", "plastic", "coated", "metal"]),
                                          scale=rng.uniform(0.2, 1.0)))
    if archetype == "studio":
        # Backdrop wall behind the set.
        bpy.ops.mesh.primitive_plane_add(size=14.0, location=(0, 4.0, 3.0), rotation=(math.pi / 2, 0, 0))
        wall = bpy.context.active_object
        wall.name = "backdrop"
        wall.data.materials.append(floor.data.materials[0] if rng.random() < 0.5 else mats.make("diffuse"))
    return floor


def build_room(rng, mats, lighting, sun=True, lamp=True):
    """Closed box with one window: mostly indirect light, dark corners."""
    w, d, h = rng.uniform(4, 7), rng.uniform(4, 7), rng.uniform(2.5, 3.5)
    wall_mat = mats.make("diffuse", scale=rng.uniform(0.3, 1.0))
    bm = bmesh.new()
    # Window in the +Y wall: the wall is four boxes around the opening.
    win_w, win_h, win_z = rng.uniform(0.6, 2.0), rng.uniform(0.6, 1.4), rng.uniform(0.8, 1.2)
    t = 0.1

    def box(cx, cy, cz, sx, sy, sz):
        bmesh.ops.create_cube(bm, size=1.0, matrix=Matrix.Translation((cx, cy, cz)) @ Matrix.Diagonal((sx, sy, sz, 1)))

    box(0, -d / 2 - t / 2, h / 2, w + 2 * t, t, h)          # back wall
    box(-w / 2 - t / 2, 0, h / 2, t, d, h)                  # left
    box(w / 2 + t / 2, 0, h / 2, t, d, h)                   # right
    box(0, 0, h + t / 2, w + 2 * t, d + 2 * t, t)           # ceiling
    side = (w - win_w) / 2
    box(-w / 2 + side / 2, d / 2 + t / 2, h / 2, side, t, h)
    box(w / 2 - side / 2, d / 2 + t / 2, h / 2, side, t, h)
    box(0, d / 2 + t / 2, win_z / 2, win_w, t, win_z)
    box(0, d / 2 + t / 2, (win_z + win_h + h) / 2, win_w, t, h - win_z - win_h)
    room = mesh_from_bmesh("room", bm)
    room.data.materials.append(wall_mat)
    # Sun through the window lands as a sharp patch on the floor.
    elevation, azimuth = math.radians(rng.uniform(15, 45)), math.pi + rng.uniform(-0.6, 0.6)
    if sun:
        lighting.sun(elevation, azimuth)
    if lamp and rng.random() < 0.6:
        lighting.point((rng.uniform(-1, 1), rng.uniform(-1, 1), h - 0.3), small=rng.random() < 0.5)
    return (w, d, h)


def build_objects(rng, mats, archetype, extent, floor_z=0.0, geometry=GEOMETRY, material=None, count=(3, 9),
                  first_index=0):
    """count objects from the geometry table, placed on the floor apart from each other.

    material(label) makes an object's material (default: a random one; leaf cards get foliage)."""
    objs = []
    n = rng.randint(*count)
    placed = []
    for i in range(first_index, first_index + n):
        maker = rng.choices([g for g, _ in geometry], weights=[w for _, w in geometry])[0]
        obj, label = maker(rng, "obj_%02d" % i)
        s = rng.uniform(0.4, 1.3)
        obj.scale = (obj.scale[0] * s, obj.scale[1] * s, obj.scale[2] * s)
        obj.rotation_euler.z += rng.uniform(0, 2 * math.pi)
        if label in ("uv_sphere", "ico_sphere", "cube") and rng.random() < 0.2:
            obj.rotation_euler.x += rng.uniform(0, 1)
        # Reject positions too close to earlier objects (keeps them from interpenetrating much).
        for _ in range(20):
            x, y = rng.uniform(-extent, extent), rng.uniform(-extent, extent)
            if all((x - px) ** 2 + (y - py) ** 2 > (0.5 * (s + ps)) ** 2 for px, py, ps in placed):
                break
        placed.append((x, y, s))
        place_on(obj, x, y, floor_z)
        if label in ("wires", "foliage") and rng.random() < 0.5:
            obj.location.z += rng.uniform(0.0, 0.8)
        if material is not None:
            mat = material(label)
        elif label == "foliage":
            mat = mats.foliage()
        else:
            mat = mats.make()
        if obj.type == "MESH" or obj.type in ("CURVE", "FONT"):
            obj.data.materials.append(mat)
        objs.append({"name": obj.name, "geometry": label, "material": mat.name})
    return objs


def draw_move(rng, pose, room):
    """A start pose and a small orbit / dolly / crane / pan from it."""
    start, tgt0 = pose()
    move = rng.choice(["orbit", "dolly", "crane", "pan", "mixed"])
    rel = start - tgt0
    ang = rng.uniform(-0.35, 0.35) if move in ("orbit", "mixed") else 0.0
    rot = Matrix.Rotation(ang, 3, "Z")
    end = tgt0 + rot @ rel
    if move in ("dolly", "mixed"):
        end = tgt0 + (end - tgt0) * rng.uniform(0.7, 1.25)
    if move in ("crane", "mixed"):
        end.z = max(0.2, end.z + rng.uniform(-0.6, 0.6))
    tgt1 = tgt0.copy()
    if move in ("pan", "mixed"):
        tgt1 += Vector((rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-0.2, 0.2)))
    if room is not None:
        w, d, h = room
        end.x = min(max(end.x, -w / 2 + 0.3), w / 2 - 0.3)
        end.y = min(max(end.y, -d / 2 + 0.3), d / 2 - 0.3)
        end.z = min(max(end.z, 0.3), h - 0.3)
    return start, end, tgt0, tgt1, move


def camera_obstacles():
    """Bounding boxes the camera must stay out of (set pieces it lives in are not obstacles)."""
    boxes = []
    for obj in bpy.context.scene.objects:
        if obj.type in ("MESH", "CURVE", "FONT") and obj.name not in ("floor", "backdrop", "room") \
                and not (obj.name == "volume" and obj.get("fog")):
            lo, hi = evaluated_bounds(obj)
            boxes.append((lo - Vector((0.08,) * 3), hi + Vector((0.08,) * 3)))
    return boxes


def view_is_blocked(p, target, lens):
    """True when most of the view is a surface right in front of the lens."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ahead = (target - p).normalized()
    right = ahead.cross(Vector((0, 0, 1))).normalized()
    up = right.cross(ahead)
    spread = 18.0 / lens  # tan of half the horizontal field of view (36 mm sensor)
    near = max(0.6, 0.25 * (target - p).length)
    blocked = 0
    for u in (-0.75, -0.25, 0.25, 0.75):
        for v in (-0.75, -0.25, 0.25, 0.75):
            ray = (ahead + right * (u * spread) + up * (v * spread)).normalized()
            hit, _, _, _, obj, _ = bpy.context.scene.ray_cast(depsgraph, p, ray, distance=near)
            blocked += bool(hit and not obj.get("fog"))
    return blocked > 8


def path_is_clear(start, end, tgt0, tgt1, obstacles, archetype, lens):
    for i in range(9):
        p = start.lerp(end, i / 8)
        if p.z < 0.1 or ("backdrop" in bpy.data.objects and p.y > 3.5):  # under the floor, behind the backdrop
            return False
        if any(all(lo[j] <= p[j] <= hi[j] for j in range(3)) for lo, hi in obstacles):
            return False
    return not any(view_is_blocked(start.lerp(end, t), tgt0.lerp(tgt1, t), lens) for t in (0.0, 0.5, 1.0))


def build_camera(rng, archetype, extent, room=None):
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = rng.uniform(22, 70)
    cam_data.clip_start = 0.02
    cam = new_object("camera", cam_data)
    bpy.context.scene.camera = cam
    target = new_object("camera_target", None)
    track = cam.constraints.new("TRACK_TO")
    track.target = target
    track.track_axis = "TRACK_NEGATIVE_Z"
    track.up_axis = "UP_Y"

    def pose():
        if room is not None:
            w, d, h = room
            loc = Vector((rng.uniform(-w / 2 + 0.4, w / 2 - 0.4), rng.uniform(-d / 2 + 0.4, d / 2 - 0.4),
                          rng.uniform(0.8, h - 0.4)))
            tgt = Vector((rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0.2, 1.0)))
            if (loc - tgt).length < 1.0:
                loc.y = -d / 2 + 0.4
        else:
            dist = rng.uniform(2.5, 7.0) * max(extent, 1.0) / 1.5
            az = rng.uniform(0, 2 * math.pi)
            el = math.radians(rng.uniform(4, 50))
            loc = Vector((dist * math.cos(az) * math.cos(el), dist * math.sin(az) * math.cos(el),
                          0.15 + dist * math.sin(el)))
            tgt = Vector((rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(0.1, 0.8)))
        return loc, tgt

    obstacles = camera_obstacles()
    for _ in range(200):  # redraw until no camera position of the move is inside an object
        start, end, tgt0, tgt1, move = draw_move(rng, pose, room)
        if path_is_clear(start, end, tgt0, tgt1, obstacles, archetype, cam_data.lens):
            break
    return cam, target, (start, end, tgt0, tgt1, move)


def set_camera_frame(cam, target, path, k, frames):
    start, end, tgt0, tgt1, _ = path
    t = k / max(frames - 1, 1)
    cam.location = start.lerp(end, t)
    target.location = tgt0.lerp(tgt1, t)
    bpy.context.view_layer.update()


# Layout archetypes and their share of scenes (docs/dataset.md, "What varies").
ARCHETYPES = [("open", 8), ("studio", 7), ("tabletop", 7), ("interior", 7), ("window_room", 10),
              ("glass_emitters", 10), ("exterior", 10), ("metal_hdri", 10), ("night", 10), ("photo", 10),
              ("thin", 11)]
OUTDOOR_HDRIS = ["city", "courtyard", "forest", "sunrise", "sunset"]


def add_local_lights(rng, mats, lighting, room, count, kinds):
    """count lights of kinds {kind: weight} around the set; small ones make fireflies."""
    for _ in range(count):
        az = rng.uniform(0, 2 * math.pi)
        r = rng.uniform(1.5, 4.5)
        loc = (r * math.cos(az), r * math.sin(az), rng.uniform(0.5, 4.0))
        if room is not None:
            loc = (min(max(loc[0], -room[0] / 2 + 0.3), room[0] / 2 - 0.3),
                   min(max(loc[1], -room[1] / 2 + 0.3), room[1] / 2 - 0.3), min(loc[2], room[2] - 0.2))
        tgt = (rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 0.3)
        kind = rng.choices(list(kinds), weights=list(kinds.values()))[0]
        if kind == "area":
            lighting.area(loc, tgt)
        elif kind == "spot":
            lighting.spot(loc, tgt)
        elif kind in ("point", "point_small"):
            lighting.point(loc, small=kind == "point_small")
        elif kind == "sun":
            lighting.sun(math.radians(rng.uniform(10, 70)), az)
        else:
            emissive_sphere(mats, lighting, loc, rng.uniform(0.03, 0.2))


def emissive_sphere(mats, lighting, loc, radius):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=loc)
    lamp = bpy.context.active_object
    lamp.name = "emitter_%d" % len(lighting.log)
    set_smooth(lamp)
    lamp.data.materials.append(mats.make("emissive"))
    lighting.log.append({"type": "EMISSIVE_OBJECT", "location": [round(c, 3) for c in loc]})


def plain_floor(rng, mats, size, kinds=("diffuse", "plastic", "coated")):
    bpy.ops.mesh.primitive_plane_add(size=size)
    floor = bpy.context.active_object
    floor.name = "floor"
    floor.data.materials.append(mats.make(rng.choice(kinds), scale=rng.uniform(0.2, 1.0)))
    return floor


def house(rng, mats, name, x, y):
    """A box with a pyramid roof: walls for sun shadows and sky occlusion."""
    w, d, h = rng.uniform(1.5, 3.5), rng.uniform(1.5, 3.5), rng.uniform(1.5, 4.0)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(x, y, h / 2))
    walls = bpy.context.active_object
    walls.name = name
    walls.scale = (w, d, h)
    walls.rotation_euler.z = rng.uniform(0, math.pi)
    walls.data.materials.append(mats.make(rng.choice(["diffuse", "diffuse", "coated"]), scale=rng.uniform(0.3, 1.0)))
    bpy.ops.mesh.primitive_cone_add(vertices=4, radius1=0.75 * max(w, d), depth=rng.uniform(0.6, 1.5),
                                    location=(x, y, h + 0.5))
    roof = bpy.context.active_object
    roof.name = name + "_roof"
    roof.rotation_euler.z = walls.rotation_euler.z + math.pi / 4
    roof.data.materials.append(mats.make("diffuse"))


def street_lamp(rng, mats, lighting, name, x, y):
    """A thin metal pole with a small bright point or a downward spot at its top."""
    h = rng.uniform(2.2, 4.0)
    bpy.ops.mesh.primitive_cylinder_add(radius=rng.uniform(0.03, 0.07), depth=h, location=(x, y, h / 2), vertices=12)
    pole = bpy.context.active_object
    pole.name = name
    pole.data.materials.append(mats.make("metal"))
    if rng.random() < 0.5:
        lighting.point((x, y, h + 0.1), small=rng.random() < 0.6)
    else:
        lighting.spot((x, y, h + 0.05), (x + rng.uniform(-1, 1), y + rng.uniform(-1, 1), 0.0))


def lighting_label(world_style, room, lamps):
    """The manifest's lighting class: what lights the set."""
    base = {"hdri": "hdri", "sky": "sky+sun", "color": "colour", "dark": "lamps only",
            "night": "night"}[world_style]
    if room is not None:
        base = "window"
    if lamps and base not in ("lamps only", "night"):
        base += "+lamps"
    return base


def build_scene(seed, photos):
    rng = random.Random(derived_seed("scene", seed))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mats = MaterialFactory(rng, photos)
    lighting = Lighting(rng)
    archetype = rng.choices([a for a, _ in ARCHETYPES], weights=[w for _, w in ARCHETYPES])[0]
    extent = rng.uniform(0.6, 1.0) if archetype == "tabletop" else rng.uniform(1.0, 2.2)
    room = None
    lamp_kinds = {"area": 30, "spot": 20, "point": 15, "point_small": 15, "sun": 10, "emissive": 10}
    build = dict(geometry=GEOMETRY, material=None, count=(3, 9))
    if archetype in ("interior", "window_room"):
        # interior: sun through the window plus lamps; window_room: only what comes in the window.
        world_style = rng.choice(["sky", "hdri", "color"] if archetype == "interior" else ["sky", "hdri"])
        window_only = archetype == "window_room"
        room = build_room(rng, mats, lighting, sun=not window_only or (world_style == "hdri" and rng.random() < 0.6),
                          lamp=not window_only)
        plain_floor(rng, mats, 12.0)
        extent = min(extent, min(room[0], room[1]) / 2 - 0.6)
        n_lights = 0 if window_only else rng.randint(0, 3)
        lamp_kinds["sun"] = 0
    elif archetype == "exterior":
        world_style = "sky" if rng.random() < 0.7 else "hdri"
        plain_floor(rng, mats, 80.0, ("diffuse",))
        extent = rng.uniform(2.0, 3.5)
        for i in range(rng.randint(2, 5)):
            az, r = rng.uniform(0, 2 * math.pi), rng.uniform(extent + 2.0, extent + 9.0)
            house(rng, mats, "house_%d" % i, r * math.cos(az), r * math.sin(az))
        n_lights = 0
        build.update(geometry=[(foliage, 6), (railing, 3), (wires, 2), (primitive, 3), (bevelled_box, 3),
                               (displaced_blob, 2)], count=(3, 8))
    elif archetype == "night":
        world_style = "night"
        plain_floor(rng, mats, 60.0, ("plastic", "coated"))  # wet, glossy ground
        extent = rng.uniform(1.5, 3.0)
        for i in range(rng.randint(1, 4)):
            az, r = rng.uniform(0, 2 * math.pi), rng.uniform(1.0, extent + 2.0)
            street_lamp(rng, mats, lighting, "lamp_%d" % i, r * math.cos(az), r * math.sin(az))
        n_lights = rng.randint(0, 2)
        lamp_kinds = {"spot": 30, "point": 20, "point_small": 30, "emissive": 20}
    elif archetype == "glass_emitters":
        world_style = rng.choices(["dark", "color", "hdri"], weights=[50, 30, 20])[0]
        build_floor(rng, mats, "studio" if rng.random() < 0.5 else "open")
        extent = rng.uniform(0.8, 1.6)
        n_lights = rng.randint(0, 1)  # a fill light; the sparkles come below
        lamp_kinds = {"area": 70, "spot": 30}
        build.update(geometry=GLASS_GEOMETRY, material=lambda label: mats.make(rng.choice(["glass", "glass", "rough_glass"])),
                     count=(2, 5))
    elif archetype == "metal_hdri":
        world_style = "hdri"
        build_floor(rng, mats, rng.choice(["open", "studio"]))
        n_lights = 0
        build.update(geometry=SOLID_GEOMETRY,
                     material=lambda label: mats.make("metal", rough=(0.0, rng.choice([0.02, 0.08, 0.15]))))
    else:  # open, studio, tabletop, photo, thin
        layout = rng.choice(["open", "studio", "tabletop"]) if archetype in ("photo", "thin") else archetype
        mats.photo_all = archetype == "photo"
        build_floor(rng, mats, layout)
        world_style = rng.choices(["hdri", "sky", "color", "dark"], weights=[40, 20, 15, 25])[0]
        n_lights = rng.randint(1 if world_style == "dark" else 0, 4)
        if archetype == "thin":
            build.update(geometry=THIN_GEOMETRY, count=(4, 10))
    world_info = make_world(rng, lighting, world_style,
                            hdris=OUTDOOR_HDRIS if archetype in ("exterior", "window_room") else HDRI_NAMES)
    objects = build_objects(rng, mats, archetype, extent, **build)
    if archetype == "glass_emitters":
        objects += build_objects(rng, mats, archetype, extent, count=(1, 3), first_index=len(objects))
        add_sparkles(rng, mats, lighting, extent)
    add_local_lights(rng, mats, lighting, room, n_lights, lamp_kinds)
    lighting.max_radiance = max(lighting.max_radiance, mats.max_emission)

    volume = None
    if archetype not in ("glass_emitters", "metal_hdri") and rng.random() < 0.15:
        volume = add_volume(rng, mats.log, extent + 3.0 if room is None else room[0] / 2, 4.0 if room is None else room[2])

    cam, target, path = build_camera(rng, archetype, extent, room)
    lamps = any(light["type"] in ("AREA", "SPOT", "POINT", "EMISSIVE_OBJECT") for light in lighting.log)
    description = {"archetype": archetype, "lighting": lighting_label(world_style, room, lamps),
                   "world": world_info, "objects": objects, "materials": mats.log,
                   "lights": lighting.log, "volume": volume, "camera_move": path[4],
                   "lens_mm": round(cam.data.lens, 2)}
    return cam, target, path, lighting, description, rng


def add_sparkles(rng, mats, lighting, extent):
    """Tiny bright emitters among and inside the glass objects: seen through glass they sparkle."""
    glass = [o for o in bpy.context.scene.objects if o.type == "MESH" and o.data.materials
             and "glass" in o.data.materials[0].name]
    for _ in range(rng.randint(2, 6)):
        if glass and rng.random() < 0.6:
            lo, hi = evaluated_bounds(rng.choice(glass))
            loc = tuple(rng.uniform(lo[i], hi[i]) for i in range(3))
        else:
            loc = (rng.uniform(-extent, extent), rng.uniform(-extent, extent), rng.uniform(0.05, 1.2))
        if rng.random() < 0.6:
            lighting.point(loc, small=True)
        else:
            emissive_sphere(mats, lighting, loc, rng.uniform(0.005, 0.03))


# --------------------------------------------------------------------------- rendering

def render_to(path, scene, samples, seed, depth):
    """Render the current frame into path atomically (temp name, then rename)."""
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    scene.render.image_settings.color_depth = depth
    tmp = path + ".tmp%d" % os.getpid()
    scene.render.filepath = tmp
    t0, c0 = time.time(), time.process_time()
    bpy.ops.render.render(write_still=True)
    if not os.path.exists(tmp):
        raise RuntimeError("Blender wrote no file for " + path)
    os.replace(tmp, path)
    return time.time() - t0, time.process_time() - c0


def luminance_probe(scene, seed, probe_res=32, samples=16):
    """Quick low-res render of Combined to choose an exposure; returns pixel luminances."""
    saved = (scene.render.resolution_x, scene.render.resolution_y, scene.render.image_settings.file_format,
             scene.render.image_settings.color_depth)
    scene.render.resolution_x = scene.render.resolution_y = probe_res
    set_file_format(scene.render.image_settings, "OPEN_EXR")
    scene.render.image_settings.color_depth = "32"
    path = os.path.join(bpy.app.tempdir, "probe_%d.exr" % seed)
    render_to(path, scene, samples, derived_seed("probe", seed), "32")
    img = bpy.data.images.load(path)
    px = list(img.pixels)
    bpy.data.images.remove(img)
    os.remove(path)
    scene.render.resolution_x, scene.render.resolution_y = saved[:2]
    set_file_format(scene.render.image_settings, saved[2])
    scene.render.image_settings.color_depth = saved[3]
    return [0.2126 * px[i] + 0.7152 * px[i + 1] + 0.0722 * px[i + 2] for i in range(0, len(px), 4)]


def exposure_for(lum, goal, ceiling=6.0):
    """Scale s with mean(min(s * lum, ceiling)) = goal: saturated lights and fireflies count once."""
    lo, hi = 1.0 / 4096.0, 4096.0
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if sum(min(mid * v, ceiling) for v in lum) / len(lum) < goal:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


def choose_exposure(scene, seed, rng, lighting, path, cam, target, frames):
    set_camera_frame(cam, target, path, frames // 2, frames)
    lum = luminance_probe(scene, seed)
    mean = sum(lum) / len(lum)
    # Target brightness varies on purpose: dim moody scenes to bright ones.
    goal = math.exp(rng.uniform(math.log(0.05), math.log(0.6)))
    scale = min(max(exposure_for(lum, goal), 1.0 / 64.0), 64.0)
    scale = min(scale, MAX_EMITTER_RADIANCE / max(lighting.max_radiance, 1e-6))
    stops = math.log2(scale)
    scene.cycles.film_exposure = scale
    return {"probe_mean_luminance": round(mean, 5), "target_mean_luminance": round(goal, 4),
            "exposure_scale": round(scale, 5), "exposure_stops": round(stops, 3),
            "max_emitter_radiance": round(lighting.max_radiance * scale, 1)}


def frame_files(stacks, spp, gt_count=2):
    names = ["spp%d_%02d.exr" % (spp, i) for i in range(stacks)]
    return names + ["gt_a.exr", "gt_b.exr"][:gt_count]


def write_json(path, data):
    tmp = path + ".tmp%d" % os.getpid()
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1, sort_keys=True)
    os.replace(tmp, path)


def render_seed(args, kind, k, index):
    """Cycles seed of one render; an empty --seed-tag keeps the data set's original seeds."""
    tag = (args.seed_tag,) if args.seed_tag else ()
    return derived_seed(kind, *tag, args.seed, k, index)


def render_frame(scene, args, k, frame_dir):
    os.makedirs(frame_dir, exist_ok=True)
    for name in os.listdir(frame_dir):  # leftovers of an interrupted run
        if ".tmp" in name:
            os.remove(os.path.join(frame_dir, name))
    times, cpu, seeds = {}, {}, {}
    jobs = [("spp%d_%02d.exr" % (args.spp, i), args.spp, render_seed(args, "stack", k, i), "16")
            for i in range(args.stacks)]
    jobs += [("gt_%s.exr" % tag, args.gt_spp, render_seed(args, "gt", k, tag), args.gt_depth)
             for tag in ("a", "b")[:args.gt_count]]
    for name, samples, seed, depth in jobs:
        seeds[name] = seed
        path = os.path.join(frame_dir, name)
        if os.path.exists(path):
            times[name] = cpu[name] = None  # rendered by an earlier, interrupted run
            continue
        wall, cpu_s = render_to(path, scene, samples, seed, depth)
        times[name], cpu[name] = round(wall, 3), round(cpu_s, 3)
    return times, cpu, seeds


def time_exr_write(scene, frame_dir):
    """Seconds to write the last render once more as a multilayer EXR (the profile's write share)."""
    tmp = os.path.join(frame_dir, "profile.tmp%d" % os.getpid())
    t0, c0 = time.time(), time.process_time()
    bpy.data.images["Render Result"].save_render(tmp, scene=scene)
    seconds, cpu = time.time() - t0, time.process_time() - c0
    os.remove(tmp)
    return round(seconds, 4), round(cpu, 4)


def render_scene(args, seed, scene_dir, frames, photos):
    t_build, c_build = time.time(), time.process_time()
    cam, target, path, lighting, description, rng = build_scene(seed, photos)
    scene = bpy.context.scene
    configure_render(scene, args)
    build_seconds, build_cpu = time.time() - t_build, time.process_time() - c_build
    t_probe, c_probe = time.time(), time.process_time()
    exposure = choose_exposure(scene, seed, rng, lighting, path, cam, target, args.frames)
    probe_seconds, probe_cpu = time.time() - t_probe, time.process_time() - c_probe
    description["exposure"] = exposure
    os.makedirs(scene_dir, exist_ok=True)
    write_json(os.path.join(scene_dir, "scene.json"),
               {"seed": seed, "generator_version": GENERATOR_VERSION, "blender_version": bpy.app.version_string,
                "description": description})
    args.seed = seed  # render_seed() reads it
    for k in frames:
        set_camera_frame(cam, target, path, k, args.frames)
        frame_dir = os.path.join(scene_dir, "frame_%d" % k)
        t0 = time.time()
        times, cpu, seeds = render_frame(scene, args, k, frame_dir)
        frame_seconds = time.time() - t0
        meta = {
            "generator_version": GENERATOR_VERSION, "blender_version": bpy.app.version_string,
            "seed": seed, "frame": k, "res": args.res, "spp": args.spp, "stacks": args.stacks,
            "gt_spp": args.gt_spp, "gt_count": args.gt_count, "gt_depth": args.gt_depth, "threads": args.threads,
            "seed_tag": args.seed_tag, "archetype": description["archetype"], "lighting": description["lighting"],
            "render_seeds": seeds, "render_seconds": times, "frame_seconds": round(frame_seconds, 3),
            "render_cpu_seconds": cpu, "scene_build_seconds": round(build_seconds, 3),
            "scene_build_cpu_seconds": round(build_cpu, 3), "probe_seconds": round(probe_seconds, 3),
            "probe_cpu_seconds": round(probe_cpu, 3),
            "camera_matrix_world": [list(map(lambda v: round(v, 6), row)) for row in cam.matrix_world],
            "camera_lens_mm": cam.data.lens, "camera_sensor_mm": cam.data.sensor_width,
            "exposure_scale": exposure["exposure_scale"],
            "files": frame_files(args.stacks, args.spp, args.gt_count),
        }
        if args.profile:
            meta["exr_write_seconds"], meta["exr_write_cpu_seconds"] = time_exr_write(scene, frame_dir)
        write_json(os.path.join(frame_dir, "meta.json"), meta)
        print("SCENEGEN frame %d %d done %.2f" % (seed, k, frame_seconds), file=sys.stderr, flush=True)


def main():
    print("SCENEGEN ready %.3f %.3f" % (time.time(), time.process_time()), file=sys.stderr, flush=True)
    args = parse_args()
    photos = [os.path.join(PHOTO_DIR, p) for p in PHOTO_NAMES]
    missing = [p for p in photos if not os.path.exists(p)]
    if missing:
        sys.exit("generate.py: photographs missing (%s); install Debian package mate-backgrounds" % missing[0])
    if args.describe:
        described = []
        for seed, _, _ in job_list(args):
            description = build_scene(seed, photos)[4]
            described.append({"seed": seed, "archetype": description["archetype"],
                              "lighting": description["lighting"]})
        write_json(args.describe, described)
        return
    for seed, scene_dir, frames in job_list(args):
        render_scene(args, seed, scene_dir, frames, photos)


if __name__ == "__main__":
    # Blender ignores script errors in background mode and exits 0; exit non-zero ourselves.
    try:
        main()
    except BaseException as err:  # noqa: B902 - includes SystemExit raised for bad input
        if isinstance(err, SystemExit) and err.code in (0, None):
            os._exit(0)
        if not isinstance(err, SystemExit):
            import traceback
            traceback.print_exc()
        else:
            print(err.code, file=sys.stderr)
        sys.stderr.flush()
        os._exit(1)
