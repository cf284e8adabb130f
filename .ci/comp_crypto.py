"""CI check of the comp's Cryptomatte with a third-party decoder
(cryptomatte-api; pixels through PyPI's OpenEXR).

`throng comp` stacks the layers' mattes (docs/compositing.md, "Cryptomatte in
the comp"): per pixel an object's coverage in a layer times (1 - A) of every
layer in front of it, coverages of one id added, the 6 highest kept, the
manifests merged. This script decodes the comp and checks that:

1. cryptomatte-api loads CryptoAgent, CryptoPart and CryptoMaterial from it;
2. every manifest entry's id is MurmurHash3_32 of its name with the spec's
   uint32_to_float32 (no mis-named matte), and the comp's manifest of each
   type is the union of the layers' manifests: every agent visible in any
   layer (by agent.id or by matte) is named, nothing else is;
3. ranks are sorted by coverage, highest first, unused ranks are (0, 0), and
   per pixel the coverage summed over ranks is the same in all three types
   (each is the fraction of samples that hit something) and at most alpha;
4. for the agents covering the most pixels (the top ones overall and in every
   crowd layer, so a layer whose mattes were dropped fails), the decoded
   CryptoAgent matte agrees with the comp's agent.id pixels, its CryptoPart
   mattes add up to it, and it is its own layer's matte times what lies in
   front (never more);
5. the set objects' mattes (`set/...`) together agree with the pixels whose
   agent.id is 0 and that hit something.

Why agreement is not exact, and the tolerances: agent.id is the one sample
nearest the pixel centre, from the layer whose Z is nearest; the matte counts
every sample of the pixel (a Gaussian filter 1.5 px wide) and is stacked in
layer order. So edge pixels carry partial coverage (some covered pixels have
another id, some id pixels a matte below 1), and where an agent of a "far"
layer stands in front of one of a "near" layer (layers are split at a
reference frame; agents move) agent.id names the nearer agent while the over
puts the near layer's agent on top. Recall (id pixels with matte > 0) is
exact but for those crossings and for pixels with more than 6 ids; precision
(pixels of matte >= 0.99 whose id is the agent) loses only crossings; the
area (matte summed) and the id pixel count differ by the edge pixels, about
the perimeter / spp. At 240x135 and 4 spp the demo's largest agents cover a
few hundred pixels; measured margins are in docs/cryptomatte.md.

Self-test: with --negative the script also writes three broken copies of the
comp (ranks reversed, one agent renamed, one crowd layer's ids dropped) and
requires that each fails.

With --oiiotool, the docs' oiiotool recipe (.ci/oiio_matte.sh) extracts the
largest agent and set object of each type and each must equal
cryptomatte-api's mask.

Usage: python comp_crypto.py COMP.exr LAYER_DIR [--negative] [--oiiotool]
"""
import glob
import json
import os
import struct
import sys
import tempfile

import numpy as np
import OpenEXR
import cryptomatte_api

TYPES = ["CryptoAgent", "CryptoMaterial", "CryptoPart"]
RANKS = 6

# Tolerances (see the docstring; measured figures in docs/cryptomatte.md).
RECALL = 0.98  # agent.id pixels of the agent with matte > 0
PRECISION = 0.97  # pixels of matte >= 0.99 whose agent.id is the agent
AREA = 0.2  # |matte area / id pixels - 1|
MIN_PIXELS = 50  # smaller agents are edge pixels mostly: a single crossing is 2% there
SUM_AGREE = 0.99  # pixels where the three types' coverage sums agree
SET_AGREE = 0.95  # set pixels (id 0, Z finite) with a set matte, and the converse


def mmh3_32(data, seed=0):
    """MurmurHash3_x86_32."""
    c1, c2 = 0xCC9E2D51, 0x1B873593
    h = seed
    n = len(data) // 4 * 4
    for i in range(0, n, 4):
        k = int.from_bytes(data[i : i + 4], "little")
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
        h = ((h << 13) | (h >> 19)) & 0xFFFFFFFF
        h = (h * 5 + 0xE6546B64) & 0xFFFFFFFF
    k = 0
    tail = data[n:]
    if len(tail) >= 3:
        k ^= tail[2] << 16
    if len(tail) >= 2:
        k ^= tail[1] << 8
    if len(tail) >= 1:
        k ^= tail[0]
        k = (k * c1) & 0xFFFFFFFF
        k = ((k << 15) | (k >> 17)) & 0xFFFFFFFF
        k = (k * c2) & 0xFFFFFFFF
        h ^= k
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & 0xFFFFFFFF
    h ^= h >> 16
    return h


def name_hex(name):
    """The spec's id of a name, as manifest hex (uint32_to_float32)."""
    h = mmh3_32(name.encode("utf-8"))
    exp = (h >> 23) & 0xFF
    if exp == 0 or exp == 255:
        h ^= 1 << 23
    return f"{h:08x}"


def read(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        part = f.parts[0]
        channels = {name: np.array(c.pixels) for name, c in part.channels.items()}
        header = dict(part.header)
    return channels, header


def mattes(path):
    """{type: (api matte, {name: hex})} through cryptomatte-api."""
    out = {}
    for m in cryptomatte_api.Cryptomatte.load(path):
        md = m.metadata()
        out[md.name()] = (m, dict(md.manifest().mapping_hex()))
    return out


def ranks(channels, t):
    """ids (float32 bits as uint32) and coverages, shape (6, H, W)."""
    ids, covs = [], []
    for level in range(RANKS // 2):
        for a, b in (("R", "G"), ("B", "A")):
            ids.append(channels[f"{t}{level:02}.{a}"].astype(np.float32).view(np.uint32))
            covs.append(channels[f"{t}{level:02}.{b}"].astype(np.float32))
    return np.stack(ids), np.stack(covs)


def check_comp(comp, layer_files, quiet=False):
    """Every check above on COMP against its layers; returns the failures."""
    failures = []
    figures = []

    def check(ok, what):
        if not ok:
            failures.append(what)

    ch, _ = read(comp)
    ids = ch["agent.id"]
    alpha = ch["A"].astype(np.float32)
    z = ch["Z"].astype(np.float32)
    shape = ids.shape
    api = mattes(comp)
    check(sorted(api) == sorted(TYPES), f"cryptomatte-api finds types {sorted(api)} in the comp, want {TYPES}")
    if sorted(api) != sorted(TYPES):
        return failures, figures

    # 2. names: ids are the names' hashes; the comp's manifest is the union of the layers'.
    layers = {}
    for layer, path in layer_files.items():
        lch, _ = read(path)
        layers[layer] = (lch, mattes(path))
    for t in TYPES:
        manifest = api[t][1]
        wrong = [n for n, h in manifest.items() if name_hex(n) != h.lower()]
        check(not wrong, f"{t}: {len(wrong)} manifest ids are not their names' hashes, e.g. {wrong[:3]}")
        union = set()
        for layer, (_, lm) in layers.items():
            union |= set(lm[t][1]) if t in lm else set()
        missing = sorted(union - set(manifest))
        extra = sorted(set(manifest) - union)
        check(not missing, f"{t}: the comp's manifest lacks {len(missing)} layer names, e.g. {missing[:5]}")
        check(not extra, f"{t}: the comp's manifest names {len(extra)} names no layer has, e.g. {extra[:5]}")
        figures.append(f"{t} {len(manifest)} names")
    seen = set()
    for layer, (lch, _) in layers.items():
        seen |= {f"agent_{int(v) - 1}" for v in np.unique(lch["agent.id"]) if v > 0}
    unnamed = sorted(seen - set(api["CryptoAgent"][1]))
    check(not unnamed, f"agents visible in a layer (agent.id) but not in the comp's CryptoAgent manifest: {unnamed[:5]}")

    # 3. ranks sorted, unused ranks empty, coverage sums equal across types and <= alpha.
    sums = {}
    for t in TYPES:
        rid, cov = ranks(ch, t)
        unsorted = int((cov[1:] > cov[:-1]).any(axis=0).sum())
        check(unsorted == 0, f"{t}: {unsorted} pixels with ranks not sorted by coverage")
        dangling = int(((rid == 0) != (cov == 0)).any(axis=0).sum())
        check(dangling == 0, f"{t}: {dangling} pixels with an id without coverage or coverage without an id")
        s = cov.sum(axis=0)
        sums[t] = s
        over = int((s > alpha + 2e-3).sum())
        check(over == 0, f"{t}: {over} pixels whose coverage exceeds alpha")
    for t in TYPES[1:]:
        agree = float((np.abs(sums[t] - sums["CryptoAgent"]) <= 1e-3).mean())
        check(agree >= SUM_AGREE, f"{t}'s coverage sums equal CryptoAgent's on only {agree:.2%} of pixels")

    # 4. the largest agents, overall and per crowd layer.
    names_agent = api["CryptoAgent"][1]
    part_names = list(api["CryptoPart"][1])
    values, counts = np.unique(ids[ids > 0], return_counts=True)
    by_size = [int(v) for v, _ in sorted(zip(values, counts), key=lambda vc: -vc[1])]
    chosen = by_size[:3]
    owner = {}
    for layer, (lch, _) in layers.items():
        if not layer.startswith("crowd"):
            continue
        mine = [v for v in by_size if (lch["agent.id"] == v).any()]
        for v in mine:
            owner.setdefault(v, layer)
        check(len(mine) > 0, f"no agent of {layer} is visible in the comp")
        chosen += mine[:2]
    chosen = list(dict.fromkeys(chosen))
    for v in chosen:
        name = f"agent_{v - 1}"
        mine = ids == v
        n = int(mine.sum())
        if n < MIN_PIXELS:
            continue
        check(name in names_agent, f"{name} (agent.id {v}, {n} pixels) is not in the comp's CryptoAgent manifest")
        if name not in names_agent:
            continue
        mask = np.asarray(api["CryptoAgent"][0].mask(name), dtype=np.float32).reshape(shape)
        recall = float((mask[mine] > 0).mean())
        solid = mask >= 0.99
        precision = float((ids[solid] == v).mean()) if solid.any() else 0.0
        area = float(mask.sum()) / n
        check(recall >= RECALL, f"{name}: matte > 0 on only {recall:.2%} of its {n} agent.id pixels")
        check(precision >= PRECISION, f"{name}: agent.id is the agent on only {precision:.2%} of its solid matte")
        check(abs(area - 1) <= AREA, f"{name}: matte area {mask.sum():.1f} against {n} agent.id pixels")
        parts = [p for p in part_names if p.startswith(name + "/")]
        psum = sum(np.asarray(api["CryptoPart"][0].mask(p), dtype=np.float32).reshape(shape) for p in parts)
        pdiff = float(np.abs(psum - mask).max()) if parts else 1.0
        check(pdiff <= 0.02, f"{name}: its {len(parts)} CryptoPart mattes differ from its CryptoAgent matte by {pdiff:.3f}")
        layer = owner.get(v)
        if layer:
            lmask = np.asarray(layers[layer][1]["CryptoAgent"][0].mask(name), dtype=np.float32).reshape(shape)
            above = float((mask - lmask).max())
            check(above <= 1e-5, f"{name}: the comp's matte exceeds its {layer} matte by {above:.4f}")
            kept = float(mask.sum() / max(lmask.sum(), 1e-9))
            check(kept >= 0.5, f"{name}: the comp keeps only {kept:.0%} of its {layer} matte")
        figures.append(
            f"{name} ({layer}) {n} px: recall {recall:.1%}, precision {precision:.1%}, area {area:.3f}, "
            f"parts {pdiff:.1e}"
        )

    # 5. the set as a whole.
    set_names = [s for s in names_agent if s.startswith("set/") or s == "set"]
    check(len(set_names) > 0, "the comp's CryptoAgent manifest names no set object")
    if set_names:
        sm = sum(np.asarray(api["CryptoAgent"][0].mask(s), dtype=np.float32).reshape(shape) for s in set_names)
        set_px = (ids == 0) & np.isfinite(z)
        covered = float((sm[set_px] > 0).mean()) if set_px.any() else 0.0
        solid = sm >= 0.99
        agree = float((ids[solid] == 0).mean()) if solid.any() else 0.0
        check(covered >= SET_AGREE, f"set mattes cover only {covered:.2%} of the set's agent.id-0 pixels")
        check(agree >= SET_AGREE, f"only {agree:.2%} of solid set-matte pixels have agent.id 0")
        figures.append(f"set: {len(set_names)} objects, {covered:.1%} of set pixels covered, {agree:.1%} of solid set matte id 0")
    return failures, figures


def oiio_mattes(comp):
    """The docs' oiiotool recipe (.ci/oiio_matte.sh) on the comp's largest
    agent, its largest part and material, and the largest set object: each
    must equal cryptomatte-api's mask. Returns the failures."""
    ch, _ = read(comp)
    api = mattes(comp)
    shape = ch["agent.id"].shape
    picks = []
    for t in TYPES:
        rid, cov = ranks(ch, t)
        u, inv = np.unique(rid.ravel(), return_inverse=True)
        area = np.bincount(inv, weights=cov.ravel())
        names = {int(h, 16): n for n, h in api[t][1].items()}
        best = [names[int(u[k])] for k in np.argsort(-area) if u[k] and int(u[k]) in names]
        if t == "CryptoMaterial":
            picks += [(t, n) for n in best[:2]]
        else:
            agents = [n for n in best if n.startswith("agent_")]
            sets = [n for n in best if not n.startswith("agent_")]
            picks += [(t, n) for n in (agents[:1] + sets[:1])]
    bad = 0
    tmp = tempfile.mkdtemp()
    here = os.path.dirname(os.path.abspath(__file__))
    for t, name in picks:
        out = os.path.join(tmp, "matte.exr")
        hexid = api[t][1][name]
        r = os.system(f"sh '{here}/oiio_matte.sh' '{comp}' {t} {hexid} '{out}' >/dev/null")
        if r != 0:
            print(f"FAIL: oiiotool could not extract {t} {name}")
            bad += 1
            continue
        oiio, _ = read(out)
        mine = oiio["A"].astype(np.float32)
        mask = np.asarray(api[t][0].mask(name), dtype=np.float32).reshape(shape)
        diff = float(np.abs(mine - mask).max())
        ok = diff <= 1e-6 and mask.sum() > 0
        print(f"comp-crypto: oiiotool {t} {name}: area {mine.sum():.2f}, max difference to cryptomatte-api {diff:.1e}")
        if not ok:
            print(f"FAIL: oiiotool's {t} matte of {name} differs from cryptomatte-api's by {diff}")
            bad += 1
    return bad


def write_copy(src, dst, edit):
    """A copy of SRC with EDIT(channels, header) applied."""
    with OpenEXR.File(src, separate_channels=True) as f:
        header = dict(f.parts[0].header)
        channels = {name: np.array(c.pixels) for name, c in f.parts[0].channels.items()}
    edit(channels, header)
    OpenEXR.File(header, channels).write(dst)


def main():
    comp, layer_dir = sys.argv[1], sys.argv[2]
    files = {os.path.basename(os.path.dirname(p)): p for p in sorted(glob.glob(f"{layer_dir}/*/*.exr"))}
    files = {k: v for k, v in files.items() if k == "set" or k.startswith("crowd")}
    failures, figures = check_comp(comp, files)
    for f in figures:
        print("comp-crypto:", f)
    for f in failures:
        print("FAIL:", f)
    bad = len(failures)
    if "--oiiotool" in sys.argv:
        bad += oiio_mattes(comp)
    if "--negative" in sys.argv:
        ch, header = read(comp)
        tmp = tempfile.mkdtemp()

        def reverse_ranks(c, h):
            for t in TYPES:
                rid, cov = ranks(c, t)
                rid, cov = rid[::-1], cov[::-1]
                k = 0
                for level in range(RANKS // 2):
                    for a, b in (("R", "G"), ("B", "A")):
                        c[f"{t}{level:02}.{a}"] = rid[k].view(np.float32).copy()
                        c[f"{t}{level:02}.{b}"] = cov[k].copy()
                        k += 1

        ids = ch["agent.id"]
        values, counts = np.unique(ids[ids > 0], return_counts=True)
        top = f"agent_{int(values[np.argmax(counts)]) - 1}"
        key = next(k for k in header if k.endswith("/name") and header[k] == "CryptoAgent").rsplit("/", 1)[0]

        def rename(c, h):
            m = json.loads(h[f"{key}/manifest"])
            m[top + "9"] = m.pop(top)  # the top agent's matte under another agent's name
            h[f"{key}/manifest"] = json.dumps(m, sort_keys=True)

        crowd0 = OpenEXR.File(files["crowd0"], separate_channels=True)
        c0 = {name: np.array(cc.pixels) for name, cc in crowd0.parts[0].channels.items()}
        gone = set()
        for t in ("CryptoAgent", "CryptoPart"):
            rid, _ = ranks(c0, t)
            gone |= set(np.unique(rid[rid != 0]).tolist())

        def drop_crowd0(c, h):
            # A comp that lost crowd0's agent and part mattes (materials are
            # shared with other layers): its ids gone, the rest re-ranked.
            for t in ("CryptoAgent", "CryptoPart"):
                rid, cov = ranks(c, t)
                hit = np.isin(rid, list(gone))
                rid, cov = np.where(hit, 0, rid).astype(np.uint32), np.where(hit, 0, cov).astype(np.float32)
                order = np.argsort(-cov, axis=0, kind="stable")
                rid, cov = np.take_along_axis(rid, order, 0), np.take_along_axis(cov, order, 0)
                k = 0
                for level in range(RANKS // 2):
                    for a, b in (("R", "G"), ("B", "A")):
                        c[f"{t}{level:02}.{a}"] = rid[k].view(np.float32).copy()
                        c[f"{t}{level:02}.{b}"] = cov[k].copy()
                        k += 1

        for what, edit in (("ranks reversed", reverse_ranks), (f"{top} renamed", rename), ("crowd0 dropped", drop_crowd0)):
            dst = os.path.join(tmp, what.replace(" ", "_") + ".exr")
            write_copy(comp, dst, edit)
            f, _ = check_comp(dst, files)
            ok = len(f) > 0
            print(f"comp-crypto: negative control '{what}': {'fails as it must' if ok else 'PASSES (the check is blind)'}"
                  + (f" ({len(f)} failures: {'; '.join(f[:3])})" if f else ""))
            bad += not ok
    print(f"comp-crypto: {'ok' if bad == 0 else f'{bad} failures'}")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
