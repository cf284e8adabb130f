"""Times `throng review --live` (docs/review.md, "Live preview"; figures in
docs/benchmarks.md, "Live preview"): from the start of the server to its
first preview image, and from a save of the shot file to the first preview
image rendered after it, on a copy of a shot written beside it.

Starts `throng review COPY --live --port 0 --threads T [--live-resolution R]`,
polls `/api/live` every 10 ms, and prints one line per measurement and a
JSON summary: start to first image and to the shot's samples; then EDITS
saves of lamp_1's intensity (alternately x3 and back, each after the last
preview reached the shot's samples: a lights edit keeps the cast), each
from the save (the file written whole and renamed, as editors do) to the
first image of the start it caused, to its first denoised image, and to
its image at the shot's samples; then one edit of `seed` (casting anew)
the same way.

usage: live_bench.py THRONG SHOT [--edits N] [--threads T] [--live-resolution WxH]
"""

import argparse
import json
import os
import statistics
import subprocess
import time
import urllib.request

p = argparse.ArgumentParser()
p.add_argument("throng")
p.add_argument("shot")
p.add_argument("--edits", type=int, default=6)
p.add_argument("--threads", type=int, default=2)
p.add_argument("--live-resolution")
a = p.parse_args()

copy = os.path.join(os.path.dirname(os.path.abspath(a.shot)), f".live_bench_{os.getpid()}.toml")


def status(url):
    with urllib.request.urlopen(url + "api/live", timeout=60) as r:
        return json.load(r)


denoised_at = {}  # start (generation) -> when its first denoised image was seen


def until(url, test, timeout=600):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        s = status(url)
        now = time.monotonic()
        if s["denoised"] and s["image_generation"] == s["generation"]:
            denoised_at.setdefault(s["generation"], now)
        if test(s):
            return s, now
        time.sleep(0.01)
    raise SystemExit(f"timed out; last status {s}")


def save(rewrite):
    """The copy rewritten by `rewrite(text)`, written whole under a temporary name and renamed."""
    text = rewrite(open(copy).read())
    with open(copy + ".tmp", "w") as f:
        f.write(text)
    os.replace(copy + ".tmp", copy)


def lamp_1(intensity):
    def rewrite(text):
        head, rest = text.split('name = "lamp_1"', 1)
        line = next(l for l in rest.splitlines() if l.startswith("intensity = "))
        return head + 'name = "lamp_1"' + rest.replace(line, f"intensity = {intensity}", 1)
    return rewrite


def seed(text):
    line = next(l for l in text.splitlines() if l.startswith("seed = "))
    return text.replace(line, f"seed = {int(line.split('=')[1]) + 1}", 1)


def edit(url, rewrite):
    """Seconds from the save to the first image of the start it caused, to its first denoised
    image (None without a denoiser), and to its image at the samples; the first image's status."""
    before, _ = until(url, lambda s: s["state"] == "converged")
    t0 = time.monotonic()
    save(rewrite)
    first, t1 = until(url, lambda s: s["image_generation"] > before["generation"])
    gen = first["image_generation"]
    done, t3 = until(url, lambda s: s["generation"] == gen and s["state"] == "converged")
    t2 = None
    if done["denoised"]:
        # Polled on the way: the denoised image came at or before the end.
        t2 = denoised_at.get(gen, t3)
    return t1 - t0, (t2 - t0) if t2 else None, t3 - t0, first


server = None
try:
    with open(copy, "w") as f:
        f.write(open(a.shot).read())
    argv = [a.throng, "--threads", str(a.threads), "review", copy, "--live", "--port", "0"]
    if a.live_resolution:
        argv += ["--live-resolution", a.live_resolution]
    t0 = time.monotonic()
    server = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    url = next(w for w in server.stdout.readline().split() if w.startswith("http://"))
    first, t1 = until(url, lambda s: s["image"] >= 1)
    done, t2 = until(url, lambda s: s["state"] == "converged")
    print(f"start: first image {t1 - t0:.2f} s ({first['width']}x{first['height']}, {first['spp']} spp),"
          f" {done['spp']} spp at {t2 - t0:.2f} s (denoised {done['denoised']})")
    fmt = lambda x: "-" if x is None else f"{x:.3f} s"
    lights = []
    for i in range(a.edits):
        f, d, c, s = edit(url, lamp_1(90.0 if i % 2 == 0 else 30.0))
        lights.append((f, d, c))
        print(f"lamp_1 edit {i + 1}: first image {fmt(f)}, first denoised {fmt(d)}, {done['spp']} spp {fmt(c)}"
              f" ({s['reload']})")
    f, d, c, s = edit(url, seed)
    print(f"seed edit: first image {fmt(f)}, first denoised {fmt(d)}, {done['spp']} spp {fmt(c)} ({s['reload']})")
    print(json.dumps({
        "start_first_image_s": t1 - t0, "start_converged_s": t2 - t0,
        "size": [first["width"], first["height"]], "spp": done["spp"], "denoised": done["denoised"],
        "lights_first_image_s": [x[0] for x in lights], "lights_first_denoised_s": [x[1] for x in lights],
        "lights_converged_s": [x[2] for x in lights],
        "lights_first_image_median_s": statistics.median(x[0] for x in lights),
        "recast_first_image_s": f, "recast_first_denoised_s": d, "recast_converged_s": c,
    }))
finally:
    for path in (copy, copy + ".tmp"):
        if os.path.exists(path):
            os.remove(path)
    if server is not None:
        server.terminate()
        server.wait(timeout=30)
