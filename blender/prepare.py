"""What a scene must render for dndenoise, as data: check() lists what is missing,
prepare() sets it and says what it changed. Both act on every view layer that
renders, since a multilayer EXR holds them all."""

# Cycles' light passes that dndenoise --passes denoises (docs/dndenoise.md,
# "Light passes for compositing"); the volume passes live on view_layer.cycles.
LIGHT_PASSES = [f"use_pass_{kind}_{part}" for kind in ("diffuse", "glossy", "transmission")
                for part in ("direct", "indirect", "color")] + ["use_pass_emit", "use_pass_environment"]
CYCLES_LIGHT_PASSES = ["use_pass_volume_direct", "use_pass_volume_indirect"]
# Reflected and refracted light: the temporal filter takes it from a neighbour
# only where the surface stood still, and tells it by these passes.
VIEW_DEPENDENT_PASSES = [f"use_pass_{kind}_{part}" for kind in ("glossy", "transmission")
                         for part in ("direct", "indirect", "color")]


def _label(prop):
    return prop[len("use_pass_"):].replace("_", " ").title() + " pass"


def _settings(scene, light_passes, temporal):
    """(owner, property, wanted value, label, why) for everything dndenoise wants."""
    wanted = [
        (scene.render, "use_motion_blur", False, "Motion blur",
         "Cycles writes the Vector pass only without motion blur"),
        (scene.cycles, "use_denoising", False, "Cycles render denoising",
         "dndenoise needs the noisy render"),
        (scene.cycles, "use_animated_seed", True, "Animated seed",
         "with a fixed seed a still camera repeats its noise and the neighbours add nothing"),
    ]
    for layer in scene.view_layers:
        if not layer.use:
            continue
        prefix = f"{layer.name}: " if len(scene.view_layers) > 1 else ""
        wanted += [(layer, "use_pass_vector", True, prefix + "Vector pass", "motion for the temporal filter"),
                   (layer.cycles, "denoising_store_passes", True, prefix + "Denoising Data pass",
                    "albedo and normal guide the denoiser")]
        if light_passes:
            wanted += [(owner, p, True, prefix + _label(p), "light passes for --passes")
                       for owner, props in ((layer, LIGHT_PASSES), (layer.cycles, CYCLES_LIGHT_PASSES))
                       for p in props]
        elif temporal:
            wanted += [(layer, p, True, prefix + _label(p),
                        "reflections move with the view: the temporal filter tells them from the surface")
                       for p in VIEW_DEPENDENT_PASSES]
    return wanted


def _multilayer(scene):
    settings = scene.render.image_settings
    return settings.file_format == "OPEN_EXR_MULTILAYER"


def check(scene, light_passes=False, temporal=False):
    """One line per thing the scene lacks for dndenoise; empty when it is ready."""
    if scene.render.engine != "CYCLES":
        return [f"the scene renders with {scene.render.engine}; the denoiser's passes are Cycles'"]
    problems = [f"{label} is {'on' if not value else 'off'} ({why})"
                for owner, prop, value, label, why in _settings(scene, light_passes, temporal)
                if getattr(owner, prop) != value]
    if not _multilayer(scene):
        problems.append(f"output format is {scene.render.image_settings.file_format}, "
                        "not OpenEXR MultiLayer (the passes must be in the frames)")
    return problems


def prepare(scene, light_passes=False, temporal=False):
    """Sets what dndenoise needs. Returns (changes, warnings), one line each."""
    if scene.render.engine != "CYCLES":
        raise ValueError(f"the scene renders with {scene.render.engine}: switch to Cycles first "
                         "(Denoising Data is a Cycles pass); nothing changed")
    changes, warnings = [], []
    for owner, prop, value, label, why in _settings(scene, light_passes, temporal):
        if getattr(owner, prop) == value:
            continue
        setattr(owner, prop, value)
        line = f"{label}: {'on' if value else 'off'} ({why})"
        # Turning something off changes the look of the render: say it louder.
        (changes if value else warnings).append(line)
    settings = scene.render.image_settings
    if not _multilayer(scene):
        old = settings.file_format
        if hasattr(settings, "media_type"):  # Blender 5: the format list depends on the media type
            settings.media_type = "MULTI_LAYER_IMAGE"
        settings.file_format = "OPEN_EXR_MULTILAYER"
        if settings.color_depth not in ("16", "32"):
            settings.color_depth = "16"
        changes.append(f"Output: {old} -> OpenEXR MultiLayer, {'half' if settings.color_depth == '16' else 'full'}"
                       " float (the passes travel in each frame)")
    return changes, warnings
