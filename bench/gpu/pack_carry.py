#!/usr/bin/env python3
"""Packs what the GPU check needs into one xz archive small enough to travel
(the device tool carries at most 64 MiB), and unpacks it on the GPU machine.

Model files are mostly float32 weights, which xz barely shrinks as they are
(35 MB -> 33 MB for models/default.dnm). Stored byte-plane by byte-plane
(every 4th byte together: the exponents' plane is nearly constant) they
shrink to less than half. Other files go in as they are.

  python3 bench/gpu/pack_carry.py pack OUT.tar.xz FILE_OR_DIR...   # here
  python3 bench/gpu/pack_carry.py unpack OUT.tar.xz DEST            # there

Paths are kept relative to the repository root (the working directory), so
DEST=. puts models/default.dnm back where the check reads it.
"""
import argparse
import io
import os
import sys
import tarfile

import numpy as np

SHUFFLED = ".planes4"  # suffix of a byte-shuffled member


def shuffle(data: bytes) -> bytes:
    raw = np.frombuffer(data, dtype=np.uint8)
    whole = len(raw) // 4 * 4
    planes = raw[:whole].reshape(-1, 4).T.ravel()
    return planes.tobytes() + raw[whole:].tobytes()


def unshuffle(data: bytes) -> bytes:
    raw = np.frombuffer(data, dtype=np.uint8)
    whole = len(raw) // 4 * 4
    words = raw[:whole].reshape(4, -1).T.ravel()
    return words.tobytes() + raw[whole:].tobytes()


def files_of(paths):
    for path in paths:
        if os.path.isdir(path):
            for root, _, names in os.walk(path):
                for name in sorted(names):
                    yield os.path.join(root, name)
        else:
            yield path


def add_bytes(archive, name, data, mode):
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mode = mode
    archive.addfile(info, io.BytesIO(data))


def pack(out, paths):
    with tarfile.open(out, "w:xz", preset=6) as archive:
        for path in files_of(paths):
            with open(path, "rb") as f:  # follows links: models/default.dnm is one
                data = f.read()
            mode = os.stat(path).st_mode & 0o777
            if path.endswith(".dnm"):
                add_bytes(archive, path + SHUFFLED, shuffle(data), mode)
            else:
                add_bytes(archive, path, data, mode)
    print(f"pack_carry: {out}: {os.path.getsize(out) / 2**20:.1f} MiB")


def unpack(archive_path, dest):
    with tarfile.open(archive_path, "r:xz") as archive:
        for member in archive.getmembers():
            data = archive.extractfile(member).read()
            name = member.name
            if name.endswith(SHUFFLED):
                name, data = name[: -len(SHUFFLED)], unshuffle(data)
            target = os.path.join(dest, name)
            os.makedirs(os.path.dirname(target) or ".", exist_ok=True)
            if os.path.islink(target):
                os.remove(target)
            with open(target, "wb") as f:
                f.write(data)
            os.chmod(target, member.mode)
            print(f"pack_carry: {target} ({len(data)} bytes)")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="verb", required=True)
    a = sub.add_parser("pack")
    a.add_argument("archive")
    a.add_argument("paths", nargs="+")
    b = sub.add_parser("unpack")
    b.add_argument("archive")
    b.add_argument("dest")
    args = p.parse_args()
    if args.verb == "pack":
        missing = [x for x in args.paths if not os.path.exists(x)]
        if missing:
            sys.exit(f"pack_carry: {missing[0]}: no such file or folder")
        pack(args.archive, args.paths)
    else:
        unpack(args.archive, args.dest)


if __name__ == "__main__":
    main()
