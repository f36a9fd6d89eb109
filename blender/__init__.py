"""dndenoise for Blender: Prepare sets the passes the denoiser needs, Denoise runs
dndenoise on the rendered frames in the background and loads the result.
docs/blender.md describes it."""

import bpy

from . import operators


class DN_Preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    dndenoise_path: bpy.props.StringProperty(
        name="dndenoise", subtype="FILE_PATH",
        description="The dndenoise program; empty: the one on PATH")

    def draw(self, context):
        self.layout.prop(self, "dndenoise_path")


class DN_Settings(bpy.types.PropertyGroup):
    source: bpy.props.EnumProperty(
        name="Frames", items=[("RENDER", "Rendered", "The frames of the render output path and frame range"),
                              ("SEQUENCE", "Sequence", "A chosen EXR sequence (a frame or its folder)")])
    input_path: bpy.props.StringProperty(name="Sequence", subtype="FILE_PATH",
                                         description="A frame of the sequence, or its folder")
    output_pattern: bpy.props.StringProperty(
        name="Output", subtype="FILE_PATH",
        description="Output frames, # per digit (e.g. //denoised/shot.####.exr); empty: a 'denoised' "
                    "folder beside the input")
    quality: bpy.props.EnumProperty(
        name="Quality", default="balanced",
        items=[("fast", "Fast", "One network on the buffers as rendered"),
               ("balanced", "Balanced", "Albedo and normal denoised first (OIDN's prefilter mode)"),
               ("high", "High", "Balanced, plus the diffuse light apart where the passes exist (2.3x the time)")])
    temporal: bpy.props.BoolProperty(
        name="Temporal", default=True,
        description="Average each frame with its neighbours along the Vector pass")
    passes: bpy.props.BoolProperty(
        name="Light Passes", description="Prepare renders Cycles' light passes and Denoise writes "
                                         "them denoised, for compositing")
    device: bpy.props.EnumProperty(
        name="Device", items=[("cpu", "CPU", ""), ("cuda", "CUDA", "Needs a CUDA build of dndenoise")])
    threads: bpy.props.IntProperty(name="Threads", min=0, max=1024, description="CPU threads; 0: all")
    load_result: bpy.props.BoolProperty(name="Load Result", default=True,
                                        description="Load the denoised frames as an image sequence")
    use_compositor: bpy.props.BoolProperty(
        name="Add to Compositor", description="Put the result in an Image node named dndenoise")
    status: bpy.props.StringProperty(name="Status", description="What the last check or run said")


class DN_PT_panel(bpy.types.Panel):
    bl_label = "dndenoise"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "output"

    def draw(self, context):
        settings = context.scene.dn_denoise
        layout = self.layout
        layout.use_property_split = True
        row = layout.row(align=True)
        row.operator("dn_denoise.prepare", icon="CHECKMARK")
        row.operator("dn_denoise.check", text="", icon="VIEWZOOM")
        layout.prop(settings, "source", expand=True)
        if settings.source == "SEQUENCE":
            layout.prop(settings, "input_path")
        layout.prop(settings, "output_pattern")
        layout.prop(settings, "quality")
        layout.prop(settings, "device")
        layout.prop(settings, "threads")
        col = layout.column(heading="Use")
        col.prop(settings, "temporal")
        col.prop(settings, "passes")
        col.prop(settings, "load_result")
        col.prop(settings, "use_compositor")
        layout.operator("dn_denoise.denoise", icon="RENDER_RESULT")
        if settings.status:
            layout.label(text=settings.status)


classes = (DN_Preferences, DN_Settings, DN_PT_panel) + operators.classes


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.dn_denoise = bpy.props.PointerProperty(type=DN_Settings)


def unregister():
    del bpy.types.Scene.dn_denoise
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
