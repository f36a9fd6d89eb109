"""EXR reading and writing for the experiment scripts (OpenEXR pip module)."""

import os
import sys

import numpy as np
import OpenEXR

# Prefixes of the colour's R, G, B channels, in the order tried: Blender's combined
# pass (any view layer), then plain RGB.
COLOR_PREFIXES = ("", "rgba.", "beauty.")


class ExrError(Exception):
    """A file that cannot be used; the message names the file and the problem."""


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def read_channels(path):
    """All channels of an EXR (every part of a multi-part file) as {full name: 2-D array}, plus the header."""
    if not os.path.isfile(path):
        raise ExrError(f"{path}: no such file")
    try:
        exr = OpenEXR.File(path, separate_channels=True)
    except Exception as error:  # the module raises plain exceptions on unreadable files
        raise ExrError(f"{path}: not a readable EXR ({error})") from error
    # Blender 4.x/5.x multilayer files hold one part per pass: the channels of every part.
    channels = {name: channel.pixels for part in exr.parts for name, channel in part.channels.items()}
    return channels, exr.parts[0].header


def color_names(channels, path="(image)"):
    """Names of the R, G, B channels of the image's colour."""
    combined = sorted(n[:-1] for n in channels if n.endswith(".Combined.R"))
    for prefix in combined + list(COLOR_PREFIXES):
        rgb = [prefix + c for c in "RGB"]
        if all(n in channels for n in rgb):
            return rgb
    raise ExrError(f"{path}: no colour channels (looked for *.Combined.R/G/B and R/G/B)")


def read_color(path):
    """The colour of an EXR as a float32 (H, W, 3) array."""
    channels, _ = read_channels(path)
    return np.stack([channels[n].astype(np.float32) for n in color_names(channels, path)], axis=-1)


def find_channels(channels, layer, suffixes, path):
    """(H, W, len(suffixes)) float32 array of channels named '<...>.<layer>.<suffix>'."""
    found = []
    for suffix in suffixes:
        matches = [n for n in channels if n.endswith(f".{layer}.{suffix}") or n == f"{layer}.{suffix}"]
        if not matches:
            raise ExrError(f"{path}: no '{layer}.{suffix}' channel")
        found.append(channels[sorted(matches)[0]].astype(np.float32))
    return np.stack(found, axis=-1)


def write_atomic(path, channels, header=None, compression=OpenEXR.ZIP_COMPRESSION):
    """Writes {name: 2-D array} to path via a temporary file in the same folder."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    out_header = {"compression": compression, "type": OpenEXR.scanlineimage}
    for key in (header or {}):
        if key in ("Camera", "Frame", "Scene", "BlenderMultiChannel") or (
                key.startswith("cycles.") and key.endswith(".samples")):  # the sample count
            out_header[key] = header[key]
    tmp = f"{path}.tmp{os.getpid()}.exr"
    try:
        OpenEXR.File(out_header, {n: np.ascontiguousarray(a) for n, a in channels.items()}).write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_rgb(path, rgb):
    """A plain float32 R, G, B image."""
    write_atomic(path, {c: rgb[..., i].astype(np.float32) for i, c in enumerate("RGB")})
