"""What a rebuilt frame is compared by: pixel digests and colour statistics (docs/dataset.md).

A file's digest is the first 12 hex digits of sha256 over its channels' names, types and
pixels as stored (headers, which hold render times and dates, are left out), so two
bit-identical renders have the same digest whatever the EXR writer put in the header.
The statistics are the mean and standard deviation of R, G, B of the frame's ground
truth (mean of its gt files) and of its input (mean of its stacks): where Cycles does
not reproduce bits (another CPU, another build), a rebuild is checked against them
within a tolerance.
"""

import hashlib
import json
import os

import numpy as np
import OpenEXR

DIGEST_HEX = 12


class CheckError(Exception):
    """A frame that cannot be checked; the message names the file."""


def read_parts(path):
    """{full channel name: array} over every part (Blender 5 writes one part per pass)."""
    try:
        exr = OpenEXR.File(path, separate_channels=True)
    except Exception as err:  # the module raises plain exceptions
        raise CheckError("%s: not a readable EXR (%s)" % (path, err)) from err
    channels = {}
    for part in exr.parts:
        prefix = part.name() if callable(getattr(part, "name", None)) else ""
        for name, channel in part.channels.items():
            full = name if (not prefix or name.startswith(prefix + ".")) else prefix + "." + name
            channels[full] = channel.pixels
    return channels


def pixel_digest(channels):
    h = hashlib.sha256()
    for name in sorted(channels):
        pixels = np.ascontiguousarray(channels[name])
        h.update(name.encode())
        h.update(str(pixels.dtype).encode())
        h.update(pixels.tobytes())
    return h.hexdigest()[:DIGEST_HEX]


def combined_rgb(channels, path):
    for suffix in ("Combined.R", "Combined.Red"):
        names = sorted(n for n in channels if n.endswith(suffix))
        if names:
            stem = names[0][:-len(suffix.split(".")[1])]
            rgb = [stem + c for c in (("R", "G", "B") if suffix.endswith("R") else ("Red", "Green", "Blue"))]
            if all(n in channels for n in rgb):
                return np.stack([channels[n].astype(np.float64) for n in rgb], axis=-1)
    if all(c in channels for c in "RGB"):  # Mitsuba's frames: plain R, G, B
        return np.stack([channels[c].astype(np.float64) for c in "RGB"], axis=-1)
    raise CheckError("%s: no Combined R, G, B channels" % path)


def mean_std(rgb):
    return [round(float(v), 6) for v in rgb.mean(axis=(0, 1))] + [round(float(v), 6) for v in rgb.std(axis=(0, 1))]


def compute(frame_dir, files):
    """{"digests": [per file, in files' order], "gt": mean+std RGB, "input": mean+std RGB}."""
    digests, gts, stacks = [], [], []
    for name in files:
        path = os.path.join(frame_dir, name)
        if not os.path.exists(path):
            raise CheckError("%s: missing" % path)
        channels = read_parts(path)
        digests.append(pixel_digest(channels))
        (gts if name.startswith("gt") else stacks).append(combined_rgb(channels, path))
    out = {"digests": digests}
    if gts:
        out["gt"] = mean_std(sum(gts) / len(gts))
    if stacks:
        out["input"] = mean_std(sum(stacks) / len(stacks))
    return out


def file_stamps(frame_dir, files):
    stamps = []
    for name in files:
        try:
            st = os.stat(os.path.join(frame_dir, name))
            stamps.append([name, st.st_size, st.st_mtime_ns])
        except OSError:
            stamps.append([name, None, None])
    return stamps


def cached(frame_dir, files):
    """compute(), kept in frame_dir/checks.json while the files' sizes and times stay the same."""
    path = os.path.join(frame_dir, "checks.json")
    stamps = file_stamps(frame_dir, files)
    try:
        with open(path) as f:
            data = json.load(f)
        if data.get("stamps") == stamps:
            return data["checks"]
    except (OSError, ValueError, KeyError):
        pass
    checks = compute(frame_dir, files)
    tmp = "%s.tmp%d" % (path, os.getpid())
    with open(tmp, "w") as f:
        json.dump({"stamps": stamps, "checks": checks}, f)
    os.replace(tmp, path)
    return checks


def compare(expected, found, rel_mean=0.03, rel_std=0.10, floor=1e-3):
    """'identical', 'close' (statistics within tolerance) or a sentence saying what differs."""
    if expected["digests"] == found["digests"]:
        return "identical"
    problems = []
    for key in ("gt", "input"):
        if key not in expected:
            continue
        if key not in found:
            return "no %s statistics" % key
        for i, (a, b) in enumerate(zip(expected[key], found[key])):
            tol = (rel_mean if i < 3 else rel_std) * max(abs(a), floor) + floor
            if abs(a - b) > tol:
                what = ("mean", "std")[i // 3] + " " + "RGB"[i % 3]
                problems.append("%s %s %.5g, expected %.5g" % (key, what, b, a))
    return "; ".join(problems) if problems else "close"
