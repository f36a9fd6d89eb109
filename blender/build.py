#!/usr/bin/env python3
"""Builds the installable extension: build/<id>-<version>.zip with the manifest
and the package at the zip's root, as Blender 4.2+ installs it (Edit >
Preferences > Get Extensions > Install from Disk). Needs no Blender.

  python3 blender/build.py [--output-dir DIR]
"""

import argparse
import os
import sys
import tomllib
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
# The manifest and every module but this script: what Blender's own
# `blender --command extension build` packs, given the manifest's paths_exclude_pattern.
FILES = ["blender_manifest.toml"] + sorted(n for n in os.listdir(HERE) if n.endswith(".py") and n != "build.py")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--output-dir", default=os.path.join(os.path.dirname(HERE), "build"))
    args = ap.parse_args()
    with open(os.path.join(HERE, "blender_manifest.toml"), "rb") as f:
        manifest = tomllib.load(f)
    os.makedirs(args.output_dir, exist_ok=True)
    path = os.path.join(args.output_dir, f"{manifest['id']}-{manifest['version']}.zip")
    tmp = path + ".tmp"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name in FILES:
            z.write(os.path.join(HERE, name), name)
    os.replace(tmp, path)  # no half-written zip under the final name
    print(path)


if __name__ == "__main__":
    sys.exit(main())
