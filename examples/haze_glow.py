#!/usr/bin/env python3
"""The lamps' glow in a hazy render against the same render in clear air.

Reads two throng layer EXRs written with `--compression none` (pure Python:
no OpenEXR module needed), finds the lamps as the brightest spots of the
clear render, and prints, per lamp, the mean luminance (Rec.709 weights) of
a ring around it (inner and outer radius in pixels: the lamp's own pixels
left out) in both renders and their ratio; then the same for the whole
frame; and each ring's contrast, its mean over that of the ring around it
(from the outer radius to twice it), in both: a halo is a contrast the
clear render does not have; with an `atmosphere` pass in the hazy file,
the air's glow in each ring over its median over the frame.
docs/render.md, "Atmosphere" ("Demo"), has
the commands.

    python3 examples/haze_glow.py HAZY.exr CLEAR.exr [--lamps 4] [--ring 3 12]
"""

import argparse
import struct
import sys


def read_exr(path):
    """(width, height, {channel: [floats, row-major]}) of an uncompressed scanline EXR."""
    data = open(path, "rb").read()
    if data[:4] != b"\x76\x2f\x31\x01":
        sys.exit(f"{path}: not an OpenEXR file")
    pos = 8
    channels, window, compression = [], None, None
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        pos = end + 1
        end = data.index(b"\0", pos)
        kind = data[pos:end].decode()
        pos = end + 1
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        value = data[pos : pos + size]
        pos += size
        if name == "channels":
            q = 0
            while value[q] != 0:
                e = value.index(b"\0", q)
                cname = value[q:e].decode()
                (ptype,) = struct.unpack_from("<i", value, e + 1)
                channels.append((cname, ptype))
                q = e + 1 + 16
        elif name == "dataWindow":
            window = struct.unpack_from("<iiii", value, 0)
        elif name == "compression":
            compression = value[0]
        del kind
    pos += 1
    if compression != 0:
        sys.exit(f"{path}: compressed (render with --compression none)")
    x0, y0, x1, y1 = window
    w, h = x1 - x0 + 1, y1 - y0 + 1
    pos += 8 * h  # the offset table: one line per block, uncompressed
    out = {c: [] for c, _ in channels}
    for _ in range(h):
        pos += 8  # y, data size
        for c, ptype in channels:
            fmt, n = {1: ("e", 2), 2: ("f", 4), 0: ("I", 4)}[ptype]
            out[c].extend(struct.unpack_from(f"<{w}{fmt}", data, pos))
            pos += w * n
    return w, h, out


def luminance(img, layer=""):
    _, _, c = img
    p = f"{layer}." if layer else ""
    return [0.2126 * r + 0.7152 * g + 0.0722 * b for r, g, b in zip(c[p + "R"], c[p + "G"], c[p + "B"])]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("hazy")
    ap.add_argument("clear")
    ap.add_argument("--lamps", type=int, default=4)
    ap.add_argument("--ring", type=float, nargs=2, default=(3.0, 12.0), metavar=("INNER", "OUTER"))
    a = ap.parse_args()
    hazy, clear = read_exr(a.hazy), read_exr(a.clear)
    w, h, _ = clear
    if hazy[:2] != clear[:2]:
        sys.exit("the two images differ in size")
    lh, lc = luminance(hazy), luminance(clear)
    # The lamps: the brightest pixels of the clear render, each at least the
    # ring's outer radius from the ones found before.
    order = sorted(range(w * h), key=lambda i: -lc[i])
    lamps = []
    for i in order:
        x, y = i % w, i // w
        if all((x - u) ** 2 + (y - v) ** 2 > a.ring[1] ** 2 for u, v in lamps):
            lamps.append((x, y))
        if len(lamps) == a.lamps:
            break
    def ring(u, v, inner, outer):
        return [
            y * w + x
            for y in range(max(0, int(v - outer)), min(h, int(v + outer) + 1))
            for x in range(max(0, int(u - outer)), min(w, int(u + outer) + 1))
            if inner**2 <= (x - u) ** 2 + (y - v) ** 2 <= outer**2
        ]

    def mean(values, pixels):
        return sum(values[i] for i in pixels) / len(pixels)

    # The glow's contrast: the ring against the ring around it, as wide again.
    inner, outer = a.ring
    # With an atmosphere pass: the air's glow in the ring over its median in the frame.
    glow = luminance(hazy, "atmosphere") if "atmosphere.R" in hazy[2] else None
    median = sorted(glow)[len(glow) // 2] if glow else 0.0
    head = f"{'lamp (x, y)':>14} {'hazy':>9} {'clear':>9} {'ratio':>7} {'contrast hazy':>14} {'clear':>7}"
    print(head + (f" {'air glow / median':>18}" if glow else ""))
    for u, v in sorted(lamps):
        near, far = ring(u, v, inner, outer), ring(u, v, outer, 2 * outer)
        mh, mc = mean(lh, near), mean(lc, near)
        ch, cc = mh / mean(lh, far), mc / mean(lc, far)
        line = f"{f'({u}, {v})':>14} {mh:9.4f} {mc:9.4f} {mh / mc:7.2f} {ch:14.2f} {cc:7.2f}"
        print(line + (f" {mean(glow, near) / median:18.2f}" if glow else ""))
    mh, mc = sum(lh) / len(lh), sum(lc) / len(lc)
    print(f"{'whole frame':>14} {mh:9.4f} {mc:9.4f} {mh / mc:7.2f}")


if __name__ == "__main__":
    main()
