"""CI check of throng's denoised beauty against the official binding of the
same denoiser (PyPI pyoidn): for every EXR given, read throng's noisy beauty
(noisy.R/G/B), albedo and normal guides (PyPI OpenEXR), denoise them with
pyoidn as throng does (RT filter, quality high: the guides prefiltered, then
the HDR beauty with clean guides), and compare with throng's denoised R, G,
B where the pixel has coverage. The files must be rendered without light
groups (with them, throng's beauty is the sum of the denoised groups).

The guides come from the file, stored as half floats, while throng denoised
from its float film, so the two differ by that rounding: the mean relative
difference must stay under 1 % (the issue's bound), the pixels agree to
about 1e-3 in practice.

Usage: python denoise_pyoidn.py FILE.exr...
"""
import sys

import numpy as np
import OpenEXR
import pyoidn
from pyoidn import OIDN_FORMAT_FLOAT3, OIDN_QUALITY_HIGH, Device, Filter


def planes(channels, names):
    return np.stack([np.asarray(channels[n].pixels, dtype=np.float32) for n in names], axis=-1)


def main(files):
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
        return out

    failed = 0
    for path in files:
        with OpenEXR.File(path, separate_channels=True) as f:
            denoised = "throng/denoiser" in f.header()
            ch = f.channels()
            noisy = np.ascontiguousarray(planes(ch, ["noisy.R", "noisy.G", "noisy.B"])) if denoised else None
            albedo = np.ascontiguousarray(planes(ch, ["albedo.R", "albedo.G", "albedo.B"]))
            normal = np.ascontiguousarray(planes(ch, ["N.X", "N.Y", "N.Z"]))
            ours = planes(ch, ["R", "G", "B"])
            alpha = np.asarray(ch["A"].pixels, dtype=np.float32)
        if not denoised:
            print(f"FAIL: {path}: no throng/denoiser attribute: not denoised")
            failed += 1
            continue
        py = pyoidn.denoise(noisy, prefilter("albedo", albedo), prefilter("normal", normal),
                            hdr=True, clean_aux=True, quality="high")
        py = np.where(alpha[..., None] > 0, np.maximum(py, 0), 0)
        covered = alpha > 0
        scale = np.maximum(np.abs(py), 1e-2)
        rel = (np.abs(ours - py) / scale)[covered]
        mean_rel = float(rel.mean()) if rel.size else 0.0
        ok = mean_rel < 0.01
        print(f"{'ok  ' if ok else 'FAIL'} {path}: mean relative difference {mean_rel:.4%} over "
              f"{int(covered.sum())} covered pixels (max {float(rel.max()) if rel.size else 0:.3g})")
        failed += not ok
    return 1 if failed else 0


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1:]))
