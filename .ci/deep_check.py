"""Deep output checked by OpenImageIO (Debian's python3-openimageio and
oiiotool): every `*.deep.exr` under the render folder is opened as a deep
image, its samples read one by one (per pixel at most maxSamplesPerPixel,
Z <= ZBack, sorted by Z, alpha in (0, 1]), flattened front to back with
"over" here and by `oiiotool --flatten`, and both must equal the flat layer
beside it (R, G, B, A) within half-float precision. Crowd layers must hold
agent samples only (id.agent != 0).

With --compression NAME every file must be stored with that compression
(as OpenImageIO names it: zips, rle, none).

Usage: deep_check.py RENDER_DIR [--compression NAME]
       (RENDER_DIR/<layer>/<shot>.<layer>.<frame>.deep.exr, and a comp's
       X.deep.exr beside X.exr)
"""

import os
import subprocess
import sys
import tempfile

import numpy as np
import OpenImageIO as oiio


def flat_rgba(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise SystemExit(f"FAIL: OpenImageIO cannot open {path}: {oiio.geterror()}")
    spec = inp.spec()
    pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    names = list(spec.channelnames)
    return np.stack([pixels[:, :, names.index(c)] for c in "RGBA"], axis=-1)


def check(deep_path, compression):
    flat_path = deep_path[: -len(".deep.exr")] + ".exr"
    inp = oiio.ImageInput.open(deep_path)
    if inp is None:
        raise SystemExit(f"FAIL: OpenImageIO cannot open {deep_path}: {oiio.geterror()}")
    spec = inp.spec()
    problems = []
    if not spec.deep:
        problems.append("not read as deep")
    names = list(spec.channelnames)
    for c in ["R", "G", "B", "A", "Z", "ZBack", "id.agent", "id.object"]:
        if c not in names:
            problems.append(f"no channel {c}")
    if problems:
        return problems
    stored = spec.getattribute("compression")
    if compression is not None and stored != compression:
        problems.append(f"compression {stored}, expected {compression}")
    cap = spec.getattribute("openexr:maxSamplesPerPixel")
    deep = inp.read_native_deep_image(0, 0)
    inp.close()
    w, h = spec.width, spec.height
    ch = {c: names.index(c) for c in names}
    crowd = "/crowd" in deep_path
    flat = np.zeros((h, w, 4))
    samples = 0
    for i in range(w * h):
        n = deep.samples(i)
        samples += n
        if cap is not None and n > cap:
            problems.append(f"pixel {i} holds {n} samples, over maxSamplesPerPixel {cap}")
        out = np.zeros(4)
        prev_z = -np.inf
        for s in range(n):
            v = lambda c: deep.deep_value(i, ch[c], s)
            z, zb, a = v("Z"), v("ZBack"), v("A")
            if not z <= zb:
                problems.append(f"pixel {i} sample {s}: Z {z} > ZBack {zb}")
            if z < prev_z:
                problems.append(f"pixel {i}: samples not sorted by Z")
            if not 0.0 < a <= 1.0:
                problems.append(f"pixel {i} sample {s}: alpha {a}")
            if crowd and v("id.agent") == 0.0:
                problems.append(f"pixel {i} sample {s}: a crowd layer sample with no agent")
            prev_z = z
            out += (1.0 - out[3]) * np.array([v("R"), v("G"), v("B"), a])
        flat[i // w, i % w] = out
        if len(problems) > 10:
            break
    want = flat_rgba(flat_path)
    tol = 2e-3 * np.maximum(np.abs(flat), np.abs(want)) + 1e-3
    err = float(np.max(np.abs(flat - want) / tol))
    if err > 1.0:
        problems.append(f"flattened deep differs from {flat_path} ({err:.2f} of the tolerance)")
    # OpenImageIO's own flattening.
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "flat.exr")
        subprocess.run(["oiiotool", deep_path, "--flatten", "-o", out], check=True)
        theirs = flat_rgba(out)
    err_oiio = float(np.max(np.abs(theirs - want) / tol))
    if err_oiio > 1.0:
        problems.append(f"oiiotool --flatten differs from {flat_path} ({err_oiio:.2f} of the tolerance)")
    print(f"{os.path.basename(deep_path)} ({stored}): {samples} samples, {samples / (w * h):.2f} per pixel, "
          f"flattened vs flat {err:.3f}, oiiotool --flatten vs flat {err_oiio:.3f} (of the tolerance)")
    return problems


def main():
    root = sys.argv[1]
    compression = sys.argv[3] if len(sys.argv) > 3 and sys.argv[2] == "--compression" else None
    files = sorted(
        os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs if f.endswith(".deep.exr")
    )
    if not files:
        raise SystemExit(f"FAIL: no .deep.exr under {root}")
    failed = False
    for f in files:
        for p in check(f, compression):
            print(f"FAIL: {f}: {p}")
            failed = True
    if failed:
        sys.exit(1)
    print(f"deep: OpenImageIO read {len(files)} deep files; samples sorted, within the cap, flattening to the flat layers")


if __name__ == "__main__":
    main()
