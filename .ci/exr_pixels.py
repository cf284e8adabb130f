"""CI check with third-party readers (PyPI's OpenEXR and cryptomatte-api):
every channel of every EXR under DIR reads back with the right size and
type, every file has the three Cryptomatte types (CryptoAgent, CryptoPart,
CryptoMaterial) and cryptomatte-api loads them, and the Cryptomatte matte of
the agent covering the most pixels in the full render agrees with its
agent.id pixels.

Usage: python exr_pixels.py DIR
"""
import glob
import sys

import numpy as np
import OpenEXR
import cryptomatte_api

EXPECTED = {
    "R": np.float16, "G": np.float16, "B": np.float16, "A": np.float16,
    "Z": np.float32, "N.X": np.float16, "N.Y": np.float16, "N.Z": np.float16,
    "albedo.R": np.float16, "albedo.G": np.float16, "albedo.B": np.float16,
    "agent.id": np.uint32,
}

# The Cryptomatte types every layer file carries (docs/cryptomatte.md).
TYPES = ["CryptoAgent", "CryptoMaterial", "CryptoPart"]

failed = 0
passed = 0


def check(ok, what):
    global failed, passed
    if ok:
        passed += 1
    else:
        failed += 1
        print("FAIL:", what)


files = sorted(glob.glob(f"{sys.argv[1]}/*/*.exr"))
check(len(files) == 5, f"expected 5 layer files, found {len(files)}")
for path in files:
    with OpenEXR.File(path, separate_channels=True) as f:
        part = f.parts[0]
        (x0, y0), (x1, y1) = part.header["dataWindow"]
        shape = (y1 - y0 + 1, x1 - x0 + 1)
        channels = {name: c.pixels for name, c in part.channels.items()}
    for name, dtype in EXPECTED.items():
        px = channels.get(name)
        check(px is not None, f"{path}: no channel {name}")
        if px is None:
            continue
        check(px.shape == shape and px.dtype == dtype, f"{path}: {name} is {px.dtype} {px.shape}, want {dtype} {shape}")
    for name, px in channels.items():
        if name != "agent.id" and name != "Z":
            check(bool(np.isfinite(px.astype(np.float32)).all()), f"{path}: {name} has non-finite pixels")
    a = channels["A"].astype(np.float32)
    check(bool(((a >= 0) & (a <= 1.001)).all()), f"{path}: alpha outside [0, 1]")
    crypto = [n for n in channels if n.startswith("Crypto")]
    check(len(crypto) == 12 * len(TYPES), f"{path}: {len(crypto)} Cryptomatte channels, want {12 * len(TYPES)}")
    for t in TYPES:
        for level in range(3):
            for c in "RGBA":
                check(f"{t}{level:02}.{c}" in channels, f"{path}: no channel {t}{level:02}.{c}")
    loaded = {m.metadata().name(): m for m in cryptomatte_api.Cryptomatte.load(path)}
    check(sorted(loaded) == sorted(TYPES), f"{path}: cryptomatte-api finds types {sorted(loaded)}, want {TYPES}")

    if "/full/" in path:
        ids = channels["agent.id"]
        values, counts = np.unique(ids[ids > 0], return_counts=True)
        check(len(values) > 0, f"{path}: no agent pixels")
        if len(values):
            top = int(values[np.argmax(counts)])
            name = f"agent_{top - 1}"  # agent.id = cache id + 1
            mattes = {m.metadata().name(): m for m in cryptomatte_api.Cryptomatte.load(path)}
            check("CryptoAgent" in mattes, f"{path}: cryptomatte-api finds no CryptoAgent")
            mask = np.asarray(mattes["CryptoAgent"].mask(name), dtype=np.float32).reshape(shape)
            mine = ids == top
            covered = float((mask[mine] > 0).mean())
            check(covered >= 0.95, f"{path}: {name}'s matte covers {covered:.2%} of its agent.id pixels")
            solid = mask >= 0.99
            if solid.any():
                agree = float((ids[solid] == top).mean())
                check(agree >= 0.95, f"{path}: {name}'s solid matte agrees with agent.id on {agree:.2%}")
            print(f"cryptomatte-api: {name} matte over {int(mine.sum())} id pixels, {covered:.1%} covered")

print(f"exr-pixels: {passed} checks ok, {failed} failures")
sys.exit(1 if failed else 0)
