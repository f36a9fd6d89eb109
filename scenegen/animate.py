"""Animated random scenes for learning the temporal filter's trust (Blender 5 Cycles).

  /work/venv-bpy/bin/python scenegen/animate.py --seeds 0-23 --out DATA/anim --frames 7 --target-spp 32

Each seed builds a scene of generate.py (its archetypes, materials and lights)
and animates it the way shots fail a temporal filter: one to three objects
slide and turn (most given metal, plastic or coated surfaces, whose
reflections do not follow their motion), a sun swings or a lamp moves (shadows
sweeping still surfaces) or a light dims, and the camera follows its move or
stands still. With --locked-off and --light-only, that share of the scenes
has nothing moving but the noise, or only its light changing. A longer lens on some scenes frames a crop of a wider shot, so
that motion and detail come at the scale of 1080p pixels.

Per frame 1..FRAMES, with the Vector pass and the feature passes, the noise
seed animated:
  SEED/spp4.NNNN.exr, SEED/spp16.NNNN.exr   the inputs
  SEED/target.NNNN.exr                      --target-spp, seeds of its own: an
                                            independent estimate (Noise2Noise)
No reference: the trust is fitted against the independent render, whose noise
adds the same to every candidate's error. Files are written under a temporary
name and renamed, and existing ones are kept, so the same command finishes
what is missing. SEED/scene.json describes the scene and its animation.
"""

import argparse
import json
import math
import os
import random
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import generate as gen  # noqa: E402  (imports bpy)
import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(prog="animate.py")
    p.add_argument("--seeds", default="0-23", help="first-last, inclusive")
    p.add_argument("--out", required=True)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--spp", default="4,16", help="the inputs' samples per pixel")
    p.add_argument("--target-spp", type=int, default=64)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--locked-off", type=float, default=0.0,
                   help="the share of scenes where nothing moves but the noise (0.25 in the trust tried with them)")
    p.add_argument("--light-only", type=float, default=0.0,
                   help="the share of scenes where only the light changes (0.10 beside --locked-off 0.25)")
    args = p.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
    first, last = (int(v) for v in args.seeds.split("-"))
    args.seed_list = list(range(first, last + 1))
    args.spp_list = [int(v) for v in args.spp.split(",")]
    return args


def keyframe_linear(obj):
    if obj.animation_data and obj.animation_data.action:
        for fcurve in getattr(obj.animation_data.action, "fcurves", []):
            for point in fcurve.keyframe_points:
                point.interpolation = "LINEAR"


def animate_camera(cam, target, path, frames, still):
    """Keyframes on frames 0..frames+1 (the Vector pass reads both sides of a frame)."""
    for k in range(frames + 2):
        gen.set_camera_frame(cam, target, path, 0 if still else k - 1, frames)
        cam.keyframe_insert("location", frame=k)
        target.keyframe_insert("location", frame=k)
    keyframe_linear(cam)
    keyframe_linear(target)


def movable_objects(description):
    names = [o["name"] for o in description["objects"] if o["geometry"] not in ("foliage", "wires")]
    return [bpy.data.objects[n] for n in names if n in bpy.data.objects]


def animate_objects(rng, mats, objects, frames, extent):
    """One to three objects slide and turn, most with a glossy or metal surface."""
    moved = []
    for obj in rng.sample(objects, min(len(objects), rng.randint(1, 3))):
        kind = rng.choices(["metal", "plastic", "coated", None], weights=[45, 20, 15, 20])[0]
        if kind and obj.type == "MESH":
            obj.data.materials.clear()
            rough = (0.0, rng.choice([0.03, 0.1, 0.25])) if kind == "metal" else None
            obj.data.materials.append(mats.make(kind, rough=rough))
        heading = rng.uniform(0, 2 * math.pi)
        speed = rng.uniform(0.01, 0.08) * max(extent, 0.5)  # metres a frame
        step = Vector((math.cos(heading), math.sin(heading), 0.0)) * speed
        spin = math.radians(rng.uniform(-12, 12))  # about z, a frame
        tilt = math.radians(rng.uniform(-6, 6)) if rng.random() < 0.3 else 0.0
        start, rotation = obj.location.copy(), obj.rotation_euler.copy()
        for k in range(frames + 2):
            obj.location = start + step * (k - 1)
            obj.rotation_euler = (rotation.x + tilt * (k - 1), rotation.y, rotation.z + spin * (k - 1))
            obj.keyframe_insert("location", frame=k)
            obj.keyframe_insert("rotation_euler", frame=k)
        keyframe_linear(obj)
        moved.append({"name": obj.name, "material": kind, "metres_per_frame": round(speed, 4),
                      "spin_degrees": round(math.degrees(spin), 2), "tilt_degrees": round(math.degrees(tilt), 2)})
    return moved


def animate_light(rng, frames, weights=(35, 50, 15)):
    """A sun swings, a lamp moves, or a light dims; or nothing (None)."""
    lights = [o for o in bpy.data.objects if o.type == "LIGHT"]
    choice = rng.choices(["none", "move", "dim"], weights=weights)[0]
    if not lights or choice == "none":
        return None
    light = rng.choice(lights)
    if choice == "dim":
        rate = rng.uniform(-0.12, 0.12)
        energy = light.data.energy
        for k in range(frames + 2):
            light.data.energy = energy * math.exp(rate * (k - 1))
            light.data.keyframe_insert("energy", frame=k)
        return {"light": light.name, "dim_per_frame": round(rate, 3)}
    if light.data.type == "SUN":
        swing = math.radians(rng.uniform(1.0, 6.0)) * rng.choice([-1, 1])
        rotation = light.rotation_euler.copy()
        for k in range(frames + 2):
            light.rotation_euler = (rotation.x, rotation.y, rotation.z + swing * (k - 1))
            light.keyframe_insert("rotation_euler", frame=k)
        keyframe_linear(light)
        return {"light": light.name, "sun_degrees_per_frame": round(math.degrees(swing), 2)}
    heading = rng.uniform(0, 2 * math.pi)
    step = Vector((math.cos(heading), math.sin(heading), rng.uniform(-0.2, 0.2))) * rng.uniform(0.03, 0.2)
    start = light.location.copy()
    for k in range(frames + 2):
        light.location = start + step * (k - 1)
        light.keyframe_insert("location", frame=k)
    keyframe_linear(light)
    return {"light": light.name, "metres_per_frame": round(step.length, 3)}


def configure(scene, args):
    gen.configure_render(scene, argparse.Namespace(res=args.res, threads=args.threads, codec="ZIP"))
    scene.view_layers[0].use_pass_vector = True
    scene.cycles.use_animated_seed = False  # each render's seed is set below


def render(scene, path, samples, seed):
    if os.path.exists(path):
        return
    gen.render_to(path, scene, samples, seed, "16")


def shot_kind(seed, args):
    """"locked" (nothing moves but the noise), "light" (only the light changes)
    or "moving", for --locked-off and --light-only shares of the seeds. Drawn
    apart from the rest, so that a moving scene's animation does not depend
    on the shares."""
    r = random.Random(gen.derived_seed("stillness", seed)).random()
    return "locked" if r < args.locked_off else "light" if r < args.locked_off + args.light_only else "moving"


def animate_scene(args, seed, photos):
    folder = os.path.join(args.out, "scene_%04d" % seed)
    names = ["spp%d.%04d.exr" % (s, k) for k in range(1, args.frames + 1) for s in args.spp_list]
    names += ["target.%04d.exr" % k for k in range(1, args.frames + 1)]
    if all(os.path.exists(os.path.join(folder, n)) for n in names):
        return
    start = time.time()
    cam, target, path, lighting, description, rng = gen.build_scene(seed, photos)
    scene = bpy.context.scene
    configure(scene, args)
    description["exposure"] = gen.choose_exposure(scene, seed, rng, lighting, path, cam, target, args.frames)
    arng = random.Random(gen.derived_seed("animate", seed))
    zoom = math.exp(arng.uniform(0.0, math.log(5.0)))  # a crop of a frame up to 5x as wide
    cam.data.lens *= zoom
    still = arng.random() < 0.4
    stillness = shot_kind(seed, args)
    still = still or stillness != "moving"
    animate_camera(cam, target, path, args.frames, still)
    extent = max((o.location.length for o in movable_objects(description)), default=1.0)
    mats = gen.MaterialFactory(arng, photos)
    animation = {"zoom": round(zoom, 3), "camera": "still" if still else path[4], "kind": stillness}
    if stillness == "moving":
        animation["objects"] = animate_objects(arng, mats, movable_objects(description), args.frames, extent)
        animation["light"] = animate_light(arng, args.frames)
    elif stillness == "light":
        animation["light"] = animate_light(arng, args.frames, weights=(0, 75, 25))
    scene.frame_start, scene.frame_end = 1, args.frames
    os.makedirs(folder, exist_ok=True)
    gen.write_json(os.path.join(folder, "scene.json"),
                   {"seed": seed, "blender_version": bpy.app.version_string, "description": description,
                    "animation": animation})
    for k in range(1, args.frames + 1):
        scene.frame_set(k)
        for spp in args.spp_list:
            render(scene, os.path.join(folder, "spp%d.%04d.exr" % (spp, k)), spp,
                   gen.derived_seed("input", seed, spp, k))
        render(scene, os.path.join(folder, "target.%04d.exr" % k), args.target_spp,
               gen.derived_seed("target", seed, k))
    print("animate: scene %d (%s, %s) in %.1f s" % (seed, description["archetype"], animation["camera"],
                                                    time.time() - start), flush=True)


def main():
    args = parse_args()
    photos = [os.path.join(gen.PHOTO_DIR, p) for p in gen.PHOTO_NAMES]
    for seed in args.seed_list:
        animate_scene(args, seed, photos)


if __name__ == "__main__":
    main()
