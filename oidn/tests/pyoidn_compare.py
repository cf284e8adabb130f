#!/usr/bin/env python3
"""Compare throng-oidn's output with the official Python binding (pyoidn, numpy).

    pyoidn_compare.py WIDTH HEIGHT COLOR ALBEDO NORMAL DENOISED TOLERANCE

COLOR, ALBEDO, NORMAL: the raw (noisy) inputs; DENOISED: throng-oidn's result; all raw
little-endian f32, interleaved RGB, row-major (oidn_synthetic example writes them). pyoidn
prefilters ALBEDO and NORMAL (RT filter, quality high) and runs
pyoidn.denoise(color, albedo_d, normal_d, hdr=True, clean_aux=True). Prints the max and mean
relative difference |ours - py| / max(|py|, 1e-6) and exits 1 when the max exceeds TOLERANCE
(0 asks for bit-identical). Same machine, same OIDN: expect 0; across CPU ISAs expect small
differences (see the crate docs).
"""
import sys

import numpy as np
import pyoidn
from pyoidn import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_HIGH, Device, Filter


def main(argv):
    if len(argv) != 8:
        sys.exit(__doc__)
    w, h = int(argv[1]), int(argv[2])
    tol = float(argv[7])

    def load(path):
        a = np.fromfile(path, dtype="<f4")
        if a.size != w * h * 3:
            sys.exit(f"{path}: {a.size} floats, a {w}x{h} RGB plane needs {w * h * 3}")
        return a.reshape(h, w, 3)

    color, albedo, normal, ours = (load(p) for p in argv[3:7])
    dev = Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
    dev.commit()

    def prefilter(name, img):
        out = np.zeros_like(img)
        f = Filter(dev, "RT")
        f.set_image(name, img, OIDN_FORMAT_FLOAT3)
        f.set_image("output", out, OIDN_FORMAT_FLOAT3)
        f.set_quality(OIDN_QUALITY_HIGH)
        f.commit()
        f.execute()
        err = dev.get_error()
        if err is not None:
            sys.exit(f"pyoidn {name} prefilter failed: {err}")
        return out

    albedo_d, normal_d = prefilter("albedo", albedo), prefilter("normal", normal)
    py = pyoidn.denoise(color, albedo_d, normal_d, hdr=True, clean_aux=True, quality="high")
    rel = np.abs(ours - py) / np.maximum(np.abs(py), 1e-6)
    identical = np.array_equal(ours.view(np.uint32), py.view(np.uint32))
    print(f"{w}x{h}: max_rel={rel.max():.3g} mean_rel={rel.mean():.3g} max_abs={np.abs(ours - py).max():.3g} "
          f"bit_identical={identical} tolerance={tol:g}")
    if not identical and not rel.max() <= tol:
        print("FAIL: throng-oidn differs from pyoidn beyond the tolerance")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
