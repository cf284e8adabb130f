#!/usr/bin/env python3
"""The lamps' glow in a hazy render against the same render in clear air.

Reads two throng layer EXRs written with `--compression none` (pure Python:
no OpenEXR module needed), finds the lamps as the brightest spots of the
clear render, and prints, per lamp, the mean luminance (Rec.709 weights) of
a ring around it (inner and outer radius in pixels: the lamp's own pixels
left out) in both renders and their ratio; then the same for the whole
frame. docs/render.md, "Atmosphere" ("Demo"), has the commands.

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


def luminance(img):
    _, _, c = img
    return [0.2126 * r + 0.7152 * g + 0.0722 * b for r, g, b in zip(c["R"], c["G"], c["B"])]


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
    print(f"{'lamp (x, y)':>14} {'hazy':>9} {'clear':>9} {'ratio':>7}")
    for u, v in sorted(lamps):
        ring = [
            y * w + x
            for y in range(max(0, int(v - a.ring[1])), min(h, int(v + a.ring[1]) + 1))
            for x in range(max(0, int(u - a.ring[1])), min(w, int(u + a.ring[1]) + 1))
            if a.ring[0] ** 2 <= (x - u) ** 2 + (y - v) ** 2 <= a.ring[1] ** 2
        ]
        mh = sum(lh[i] for i in ring) / len(ring)
        mc = sum(lc[i] for i in ring) / len(ring)
        print(f"{f'({u}, {v})':>14} {mh:9.4f} {mc:9.4f} {mh / mc:7.2f}")
    mh, mc = sum(lh) / len(lh), sum(lc) / len(lc)
    print(f"{'whole frame':>14} {mh:9.4f} {mc:9.4f} {mh / mc:7.2f}")


if __name__ == "__main__":
    main()
