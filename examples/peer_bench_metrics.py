"""Error of a render against its reference, as issue 52's benchmarks take it.

    python examples/peer_bench_metrics.py REFERENCE.exr TEST.exr [TEST.exr ...]
    python examples/peer_bench_metrics.py REF_SEED1.exr+REF_SEED2.exr TEST.exr ...

Prints one JSON line per test image: `rel_mse`, the mean over pixels and
channels of (x - r)^2 / (r^2 + 0.01), and `flip`, the mean FLIP
(flip-evaluator, LDR) of the linear images clipped to [0, 1]. Given two
references of independent seeds (A+B), r is their mean and `rel_mse` has
the reference's own noise taken out: (x - r)^2 - (a - b)^2 / 4 is an
unbiased estimate of x's squared error against the converged image
(`rel_mse_raw` keeps the uncorrected figure; FLIP cannot be corrected). Reads the
beauty of a throng file (R, G, B: the denoised beauty of a denoised file)
or of a Cycles / Mitsuba multilayer file (`*.Combined.R`, or `R`). Needs
numpy, OpenEXR and flip-evaluator (the peer harness's venv has them).
"""

import json
import sys

import flip_evaluator
import numpy as np
import OpenEXR


def beauty(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        ch = f.parts[0].channels
        for prefix in ("", "ViewLayer.Combined.", "RenderLayer.Combined."):
            if all(prefix + c in ch for c in "RGB"):
                return np.stack([ch[prefix + c].pixels.astype(np.float64) for c in "RGB"], axis=-1)
        combined = sorted(n[:-1] for n in ch if n.endswith("Combined.R"))
        if combined:
            return np.stack([ch[combined[0] + c].pixels.astype(np.float64) for c in "RGB"], axis=-1)
    sys.exit(f"{path}: no beauty channels (R, G, B or *.Combined.R/G/B) among {sorted(ch)[:12]}")


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    refs = [beauty(p) for p in sys.argv[1].split("+")]
    ref = sum(refs) / len(refs)
    noise = (refs[0] - refs[1]) ** 2 / 4 if len(refs) == 2 else 0.0
    ref_ldr = np.clip(ref, 0.0, 1.0).astype(np.float32)
    for path in sys.argv[2:]:
        x = beauty(path)
        if x.shape != ref.shape:
            sys.exit(f"{path}: {x.shape} against the reference's {ref.shape}")
        rel_mse_raw = float(np.mean((x - ref) ** 2 / (ref**2 + 0.01)))
        rel_mse = float(np.mean(((x - ref) ** 2 - noise) / (ref**2 + 0.01)))
        _, flip, _ = flip_evaluator.evaluate(
            ref_ldr, np.clip(x, 0.0, 1.0).astype(np.float32), "LDR", inputsRGB=False, applyMagma=False
        )
        print(json.dumps({"test": path, "reference": sys.argv[1], "rel_mse": rel_mse, "rel_mse_raw": rel_mse_raw, "flip": float(flip)}))


if __name__ == "__main__":
    main()
