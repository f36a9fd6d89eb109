#!/usr/bin/env python3
"""Writes testdata/npy/: small .npy files saved by numpy itself, the independent
reference for tests/test_npy.cpp (the reader, the writer's bytes, the refusals).
Run from the repository root: python3 tests/make_npy_fixtures.py"""
import os

import numpy as np

out = os.path.join(os.path.dirname(__file__), "..", "testdata", "npy")
os.makedirs(out, exist_ok=True)


def save(name, array, **kw):
    with open(os.path.join(out, name), "wb") as f:
        np.lib.format.write_array(f, array, allow_pickle=False, **kw)


# An image, (height, width, channels), and a one-channel (height, width) one.
save("f32_image.npy", (np.arange(2 * 3 * 4, dtype="<f4").reshape(2, 3, 4) - 7.5) * 0.25)
save("f32_gray.npy", np.linspace(-1, 1, 12, dtype="<f4").reshape(3, 4))
save("f32_vector.npy", np.array([1, 2, 3, 4, 5], dtype="<f4"))
save("f32_scalar.npy", np.array(2.5, dtype="<f4"))

# float16 rounding, from float32 sources: ties, subnormals, overflow, signs, NaN.
rng = np.random.default_rng(7)
special = [0.0, -0.0, 1.0, -2.0, 65504.0, 65519.0, 65520.0, 1e9, -1e9, np.inf, -np.inf, np.nan,
           6.1035156e-05, 6.0975552e-05, 5.9604645e-08, 2.9802322e-08, 2.9802326e-08, 8.940697e-08,
           1.0009765625, 1.00048828125, 1.00146484375, 2049.0, 2051.0, 3.14159265, 1e-10]
source = np.concatenate([np.array(special, dtype="<f4"),
                         (rng.standard_normal(231) * np.exp(rng.uniform(-20, 12, 231))).astype("<f4")])
save("half_source.npy", source.reshape(16, 16))
save("half_numpy.npy", source.astype("<f2").reshape(16, 16))
save("f16_image.npy", (rng.standard_normal((4, 5, 3)) * 10).astype("<f2"))

# Version 2.0 of the format (4-byte header length) still reads.
save("f32_v2.npy", np.arange(6, dtype="<f4").reshape(2, 3), version=(2, 0))

# What the reader refuses, each with its own one-line reason.
save("bad_big_endian.npy", np.arange(6, dtype=">f4").reshape(2, 3))
save("bad_float64.npy", np.arange(6, dtype="<f8").reshape(2, 3))
save("bad_int32.npy", np.arange(6, dtype="<i4").reshape(2, 3))
save("bad_fortran.npy", np.asfortranarray(np.arange(6, dtype="<f4").reshape(2, 3)))
save("bad_4d.npy", np.zeros((1, 2, 2, 3), dtype="<f4"))
whole = open(os.path.join(out, "f32_image.npy"), "rb").read()
open(os.path.join(out, "bad_truncated.npy"), "wb").write(whole[:-4])
open(os.path.join(out, "bad_trailing.npy"), "wb").write(whole + b"\0\0\0\0")
open(os.path.join(out, "bad_magic.npy"), "wb").write(b"PK\x03\x04" + whole[4:])
