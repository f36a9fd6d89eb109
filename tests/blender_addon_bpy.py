"""The Blender side of blender_addon_check.py, run by the bpy venv's Python:
installs the extension zip as Blender's Install from Disk does, builds a tiny
animated Cycles scene, and drives Check, Prepare, the renders and Denoise
through the operators, then the bad inputs. Writes what it saw as JSON; the
driver judges it.

  python blender_addon_bpy.py --zip ZIP --dndenoise BIN --work-dir DIR --out JSON
"""
import argparse
import hashlib
import json
import os
import time

import bpy

MODULE = "bl_ext.user_default.dn_denoise"


def build_scene(samples=4):
    """A floor, a cube and a sphere under a point lamp; the camera slides over 3 frames."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 48, 100
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    scene.frame_start, scene.frame_end = 1, 3
    bpy.ops.mesh.primitive_plane_add(size=10)
    bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.7, location=(1.8, 0.5, 0.7))
    bpy.ops.object.light_add(type="POINT", location=(2, -2, 4))
    bpy.context.object.data.energy = 800
    bpy.ops.object.camera_add(location=(6, -6, 4), rotation=(1.1, 0, 0.785))
    camera = scene.camera = bpy.context.object
    for frame in (1, 2, 3):
        camera.location.x = 5.7 + 0.3 * frame
        camera.keyframe_insert("location", frame=frame)
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.05, 0.05, 0.05)
    scene.render.use_motion_blur = True  # Prepare must turn it off, with a warning
    return scene


def render(scene, folder, samples):
    scene.cycles.samples = samples
    scene.render.filepath = os.path.join(folder, "shot.####")
    bpy.ops.render.render(animation=True)


def call(op, **kw):
    """An operator's result and its error line (bpy raises the ERROR report)."""
    try:
        return sorted(op(**kw)), ""
    except RuntimeError as e:
        return [], str(e).strip().removeprefix("Error: ")


def digest(folder):
    return {n: hashlib.sha256(open(os.path.join(folder, n), "rb").read()).hexdigest()
            for n in sorted(os.listdir(folder))}


def main():
    ap = argparse.ArgumentParser()
    for a in ("--zip", "--dndenoise", "--work-dir", "--out"):
        ap.add_argument(a, required=True)
    args = ap.parse_args()
    work = args.work_dir
    seen = {}

    scene = build_scene()
    # After the factory reset, which would also reset the preferences.
    seen["install"] = call(bpy.ops.extensions.package_install_files, filepath=args.zip,
                           repo="user_default", enable_on_install=True)
    prefs = bpy.context.preferences.addons[MODULE].preferences
    prefs.dndenoise_path = args.dndenoise
    settings = scene.dn_denoise

    call(bpy.ops.dn_denoise.check)
    seen["check_before"] = settings.status
    seen["prepare"] = call(bpy.ops.dn_denoise.prepare)
    seen["prepare_status"] = settings.status
    layer = scene.view_layers[0]
    seen["properties"] = {
        "view_layer.use_pass_vector": layer.use_pass_vector,
        "view_layer.cycles.denoising_store_passes": layer.cycles.denoising_store_passes,
        "view_layer.use_pass_glossy_direct": layer.use_pass_glossy_direct,
        "view_layer.use_pass_transmission_color": layer.use_pass_transmission_color,
        "scene.cycles.use_animated_seed": scene.cycles.use_animated_seed,
        "scene.cycles.use_denoising": scene.cycles.use_denoising,
        "scene.render.use_motion_blur": scene.render.use_motion_blur,
        "image_settings.media_type": scene.render.image_settings.media_type,
        "image_settings.file_format": scene.render.image_settings.file_format,
    }
    call(bpy.ops.dn_denoise.check)
    seen["check_after"] = settings.status
    call(bpy.ops.dn_denoise.prepare)
    seen["prepare_again"] = settings.status

    start = time.time()
    render(scene, os.path.join(work, "ref"), 256)
    render(scene, os.path.join(work, "noisy"), 4)
    seen["render_seconds"] = time.time() - start

    settings.output_pattern = os.path.join(work, "den", "shot.####.exr")
    settings.threads = 2
    settings.use_compositor = True
    start = time.time()
    seen["denoise"] = call(bpy.ops.dn_denoise.denoise)
    seen["denoise_seconds"] = time.time() - start
    seen["denoise_status"] = settings.status
    image = next((i for i in bpy.data.images if i.source == "SEQUENCE"), None)
    seen["image"] = image and {"name": image.name, "filepath": bpy.path.abspath(image.filepath),
                               "type": image.type}
    tree = scene.compositing_node_group
    node = tree and tree.nodes.get("dndenoise")
    seen["compositor_image"] = node.image.name if node and node.image else None

    # Bad inputs, each pointed at the frames just denoised: nothing may change there.
    fake = os.path.join(work, "old", "dndenoise")
    os.makedirs(os.path.dirname(fake))
    with open(fake, "w") as f:
        f.write("#!/bin/sh\necho 'dndenoise 0.0.9 (diffusion_denoise v0.0.9)'\n")
    os.chmod(fake, 0o755)
    empty = os.path.join(work, "not_a_sequence")
    os.makedirs(empty)
    open(os.path.join(empty, "notes.txt"), "w").close()
    bad = {}
    seen["den_before_bad"] = digest(os.path.join(work, "den"))
    prefs.dndenoise_path = os.path.join(work, "nowhere", "dndenoise")
    bad["no_dndenoise"] = call(bpy.ops.dn_denoise.denoise)[1]
    prefs.dndenoise_path = fake
    bad["too_old"] = call(bpy.ops.dn_denoise.denoise)[1]
    prefs.dndenoise_path = args.dndenoise
    scene.frame_end = 5
    bad["missing_frames"] = call(bpy.ops.dn_denoise.denoise)[1]
    scene.frame_end = 3
    settings.source, settings.input_path = "SEQUENCE", empty
    bad["not_a_sequence"] = call(bpy.ops.dn_denoise.denoise)[1]
    seen["bad"] = bad
    seen["den_after_bad"] = digest(os.path.join(work, "den"))

    # A scene without the Vector pass: Check says so before rendering, and
    # Denoise warns that dndenoise went frame by frame.
    layer.use_pass_vector = False
    call(bpy.ops.dn_denoise.check)
    seen["novec_check"] = settings.status
    render(scene, os.path.join(work, "novec"), 4)
    settings.input_path = os.path.join(work, "novec")  # a folder holding one sequence
    settings.output_pattern = os.path.join(work, "novec_den", "shot.####.exr")
    settings.use_compositor = False
    seen["novec_denoise"] = call(bpy.ops.dn_denoise.denoise)
    seen["novec_status"] = settings.status

    # Light passes: Prepare adds them (and the Vector pass back), Denoise --passes
    # writes them denoised.
    settings.passes = True
    call(bpy.ops.dn_denoise.prepare)
    seen["passes_prepare"] = settings.status
    scene.frame_end = 2
    render(scene, os.path.join(work, "passes"), 4)
    settings.source, settings.output_pattern = "RENDER", os.path.join(work, "passes_den", "shot.####.exr")
    seen["passes_denoise"] = call(bpy.ops.dn_denoise.denoise)

    with open(args.out, "w") as f:
        json.dump(seen, f, indent=1)


if __name__ == "__main__":
    main()
