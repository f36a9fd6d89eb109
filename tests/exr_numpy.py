"""Reads the colour of a (multilayer) EXR into an HxWx3 float32 array with the
OpenEXR Python bindings: the independent path the reference checks use."""
import numpy as np
import OpenEXR


def read_rgb(path, layer=None):
    with OpenEXR.File(path, separate_channels=True) as f:
        channels = f.channels()
        names = list(channels)
        candidates = [layer] if layer else []
        candidates += [n[:-2] for n in names if n.endswith("Combined.R")] + [""]
        for prefix in candidates:
            keys = [f"{prefix}.{c}" if prefix else c for c in "RGB"]
            if all(k in channels for k in keys):
                return np.dstack([channels[k].pixels.astype(np.float32) for k in keys])
    raise ValueError(f"{path}: no RGB channels")


def write_rgb(path, rgb):
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgb[:, :, i].astype(np.float32)) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(path)
