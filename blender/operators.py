"""The Prepare, Check and Denoise operators."""

import os

import bpy

from . import prepare as prep
from . import runner


def _preferences(context):
    # Installed as an extension the preferences live under the package's full name
    # (bl_ext.<repo>.dn_denoise); imported as a plain package there are none.
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon else None


def _status(context, line):
    context.scene.dn_denoise.status = line


class DN_OT_prepare(bpy.types.Operator):
    """Set the passes, seed and output format dndenoise needs, and report what changed"""
    bl_idname = "dn_denoise.prepare"
    bl_label = "Prepare for dndenoise"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene = context.scene
        try:
            changes, warnings = prep.prepare(scene, scene.dn_denoise.passes, scene.dn_denoise.temporal)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for line in warnings:
            self.report({"WARNING"}, line)
        for line in changes:
            self.report({"INFO"}, line)
        summary = f"prepared: {len(changes) + len(warnings)} settings changed" if changes or warnings \
            else "already prepared: nothing changed"
        _status(context, summary)
        self.report({"INFO"}, summary)
        return {"FINISHED"}


class DN_OT_check(bpy.types.Operator):
    """Report what the scene lacks for dndenoise, before rendering; changes nothing"""
    bl_idname = "dn_denoise.check"
    bl_label = "Check for dndenoise"

    def execute(self, context):
        settings = context.scene.dn_denoise
        problems = prep.check(context.scene, settings.passes, settings.temporal)
        for line in problems:
            self.report({"WARNING"}, line)
        _status(context, "; ".join(problems) if problems else "ready for dndenoise")
        if not problems:
            self.report({"INFO"}, "ready for dndenoise")
        return {"FINISHED"}


def _render_sequence(scene):
    """The rendered frames, as the scene's output path and frame range name them."""
    frames = list(range(scene.frame_start, scene.frame_end + 1, scene.frame_step))
    path_a = bpy.path.abspath(scene.render.frame_path(frame=frames[0]))
    path_b = bpy.path.abspath(scene.render.frame_path(frame=frames[0] + 1))
    seq = runner.sequence_from_paths(path_a, frames[0], path_b, frames)
    if not seq.suffix.lower().endswith(".exr"):
        raise runner.DenoiseError(f"{path_a}: the render output is not EXR; press Prepare and render again")
    return seq


def _plan(context):
    """(command, output Sequence) from the scene's settings; DenoiseError with one line."""
    scene = context.scene
    settings = scene.dn_denoise
    prefs = _preferences(context)
    exe = runner.find_dndenoise(bpy.path.abspath(prefs.dndenoise_path) if prefs and prefs.dndenoise_path else "")
    runner.check_version(exe)
    if settings.source == "RENDER":
        source = _render_sequence(scene)
    else:
        if not settings.input_path:
            raise runner.DenoiseError("choose a frame or folder of the sequence to denoise")
        source = runner.sequence_of(bpy.path.abspath(settings.input_path))
    missing = [f for f in source.frames if not os.path.isfile(source.path(f))]
    if missing:
        raise runner.DenoiseError(f"{source.path(missing[0])}: missing frame {missing[0]}"
                                  + (" (render the animation first)" if settings.source == "RENDER" else ""))
    if settings.output_pattern:
        output = runner.output_sequence(bpy.path.abspath(settings.output_pattern), source.frames)
    else:
        folder, name = os.path.split(source.prefix)
        output = runner.Sequence(os.path.join(folder, "denoised", name), source.width, source.suffix,
                                 source.frames)
    used = [layer.name for layer in scene.view_layers if layer.use]
    view_layer = context.view_layer.name if settings.source == "RENDER" and len(used) > 1 else ""
    cmd = runner.command(exe, source, output, settings.quality, settings.temporal, settings.passes,
                         settings.device, settings.threads, view_layer)
    return cmd, output


def _compositor(scene):
    """The scene's compositing nodes, made as Blender makes them where there are none:
    the render passes straight through, so that adding the result changes no render."""
    if not hasattr(scene, "compositing_node_group"):  # Blender 4: use_nodes makes that tree
        scene.use_nodes = True
        return scene.node_tree
    if scene.compositing_node_group is None:  # Blender 5: a node group, empty when new
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        tree.interface.new_socket(name="Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        layers, output = tree.nodes.new("CompositorNodeRLayers"), tree.nodes.new("NodeGroupOutput")
        output.location.x = 400
        tree.links.new(layers.outputs["Image"], output.inputs["Image"])
        scene.compositing_node_group = tree
    return scene.compositing_node_group


def _load(context, output):
    """The result as an image sequence, and optionally an Image node in the compositor."""
    scene, frames = context.scene, output.frames
    image = bpy.data.images.load(output.path(frames[0]), check_existing=True)
    image.source = "SEQUENCE"
    image.reload()  # a sequence loaded before holds the last result's pixels
    if not scene.dn_denoise.use_compositor:
        return image
    tree = _compositor(scene)
    node = tree.nodes.get("dndenoise") or tree.nodes.new("CompositorNodeImage")
    node.name = node.label = "dndenoise"
    node.image = image
    node.frame_start, node.frame_duration = frames[0], frames[-1] - frames[0] + 1
    node.frame_offset = frames[0] - 1  # scene frame N shows file frame N
    node.location.y = -400
    return image


class DN_OT_denoise(bpy.types.Operator):
    """Denoise the rendered frames (or a chosen sequence) with dndenoise, in the background"""
    bl_idname = "dn_denoise.denoise"
    bl_label = "Denoise with dndenoise"

    wait: bpy.props.BoolProperty(
        name="Wait", description="Block until dndenoise is done (always so without a window)")

    _job = None
    _timer = None

    def _start(self, context):
        try:
            cmd, self._output = _plan(context)
            os.makedirs(os.path.dirname(self._output.path(self._output.frames[0])), exist_ok=True)
            self._job = runner.Job(cmd, len(self._output.frames))
        except runner.DenoiseError as e:
            _status(context, str(e))
            self.report({"ERROR"}, str(e))
            return False
        _status(context, f"denoising {len(self._output.frames)} frames")
        return True

    def _finish(self, context):
        job = self._job
        for line in job.warnings:
            self.report({"WARNING"}, line)
        error = job.error()
        if error:
            _status(context, error)
            self.report({"ERROR"}, error)
            return {"CANCELLED"}
        image = _load(context, self._output) if context.scene.dn_denoise.load_result else None
        done = f"denoised {len(self._output.frames)} frames into {self._output.blender_pattern()}"
        _status(context, (job.warnings[0] + "; " if job.warnings else "") + done)
        self.report({"INFO"}, done + (f" (image '{image.name}')" if image else ""))
        return {"FINISHED"}

    def execute(self, context):
        if not self._start(context):
            return {"CANCELLED"}
        # Headless there is no event loop for a timer to run in.
        self._job.wait(on_progress=lambda f: print(f"dndenoise: {100 * f:.0f}%", flush=True))
        return self._finish(context)

    def invoke(self, context, event):
        if self.wait or bpy.app.background:
            return self.execute(context)
        if not self._start(context):
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.25, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()  # the timer sees it end
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        done = self._job.poll()
        wm = context.window_manager
        wm.progress_update(int(100 * self._job.fraction))
        context.workspace.status_text_set(
            f"dndenoise: {100 * self._job.fraction:.0f}% of {len(self._output.frames)} frames (Esc cancels)")
        if not done:
            return {"RUNNING_MODAL"}
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        return self._finish(context)

    def cancel(self, context):
        # Blender is closing the window or file: do not leave dndenoise running.
        if self._job:
            self._job.cancel()
        if self._timer:
            context.window_manager.event_timer_remove(self._timer)
            context.window_manager.progress_end()


classes = (DN_OT_prepare, DN_OT_check, DN_OT_denoise)
