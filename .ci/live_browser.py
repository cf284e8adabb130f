"""The live preview of `throng review --live` in a real browser (docs/review.md,
"Live preview"): Debian's Chromium, headless, over the DevTools protocol.

Copies the demo shot beside it (so its relative paths hold), starts
`throng review COPY --live` (no renders folder: the live panel alone) at its
default size (a quarter of the shot's, 240x135) on `--threads 2`, loads the
page and waits for the first live image (the time is printed and must be
under FIRST_IMAGE_S), then for the preview at the shot's samples. Then it
raises lamp_1's intensity in the copy's shot.toml, as an editor saving would,
and waits for the first image after the edit (the time is printed), then for
the page to show the image at the shot's samples: read back through a
canvas, it must be brighter around the lamp than before (the pixels the
raise brightens by more than 8 codes at least MIN_CHANGED of the image, and
more than it darkens), with the cast kept. A malformed edit must show
its error in the panel, naming the key, and the page must keep answering.

usage: live_browser.py THRONG SHOT SCREENSHOT.png
"""

import os
import shutil
import sys
import tempfile
import time

import numpy as np

import browser as browser_harness
from browser import fail, get_json, launch_chromium, start_review, stop, wait_for

THRONG, SHOT, SHOT_PNG = sys.argv[1:4]
# The first image: the shot read and cast, the frame posed, one pass.
FIRST_IMAGE_S = 10.0
MIN_CHANGED = 0.002

browser_harness.NAME = "live browser"

text = open(SHOT).read()
copy = os.path.join(os.path.dirname(os.path.abspath(SHOT)), f".live_browser_{os.getpid()}.toml")
profile = tempfile.mkdtemp(prefix="throng-live-chromium-")
server = browser = None


def set_lamp_1(intensity):
    """lamp_1's `intensity = ...` line rewritten, the file written whole (an editor's save)."""
    now = open(copy).read()
    head, rest = now.split('name = "lamp_1"', 1)
    line = next(l for l in rest.splitlines() if l.startswith("intensity = "))
    with open(copy + ".tmp", "w") as f:
        f.write(head + 'name = "lamp_1"' + rest.replace(line, f"intensity = {intensity}", 1))
    os.replace(copy + ".tmp", copy)


try:
    with open(copy, "w") as f:
        f.write(text)
    started = time.time()
    server, url = start_review([THRONG, "review", copy, "--live", "--port", "0", "--threads", "2"])
    browser, cdp = launch_chromium(profile, lenient=True)
    cdp.open(url)

    def shown():
        """The live image the page shows, read back through a canvas: its number and H x W x 3 codes."""
        v = cdp.eval(
            "(() => { const i = document.getElementById('live-image'); if (!i.complete || !i.naturalWidth) return null;"
            " const c = document.createElement('canvas'); c.width = i.naturalWidth; c.height = i.naturalHeight;"
            " const x = c.getContext('2d'); x.drawImage(i, 0, 0); const d = x.getImageData(0, 0, c.width, c.height).data;"
            " const out = []; for (let k = 0; k < d.length; k += 4) out.push(d[k], d[k + 1], d[k + 2]);"
            " return [+(i.dataset.image || 0), c.width, c.height, out]; })()")
        if not v:
            return None
        n, w, h, px = v
        return n, np.array(px, dtype=np.float64).reshape(h, w, 3)

    def page_image(at_least):
        """Waits for the page to show image number `at_least` or later; (number, pixels)."""
        return wait_for(f"the page to show live image {at_least}",
                        lambda: (lambda s: s if s and s[0] >= at_least else None)(shown()), 60)

    first = wait_for("the first live image", lambda: (lambda s: s if s and s[0] >= 1 else None)(shown()),
                     FIRST_IMAGE_S + 30)
    first_s = time.time() - started
    if first_s > FIRST_IMAGE_S:
        fail(f"the first live image took {first_s:.1f} s (at most {FIRST_IMAGE_S} s)")
    if first[1].shape[:2] != (135, 240):
        fail(f"the live image is {first[1].shape[1]}x{first[1].shape[0]}, not a quarter of 960x540")
    panel = cdp.eval("document.getElementById('live-status').textContent")
    if "denoised" not in panel and "noisy" not in panel:
        fail(f"the panel does not say whether the image is denoised: {panel!r}")

    before = wait_for("the preview at the shot's samples", lambda: (lambda s: s if s["state"] == "converged" else None)(
        get_json(url + "api/live")), 180)
    n0, px0 = page_image(before["image"])

    edited = time.time()
    set_lamp_1(300.0)
    status = lambda test: (lambda s: s if test(s) else None)(get_json(url + "api/live"))
    wait_for("the first image after the edit", lambda: status(lambda s: s["image_generation"] > before["generation"]), 60)
    edit_s = time.time() - edited
    after = wait_for("the render after the edit at the shot's samples", lambda: status(
        lambda s: s["generation"] > before["generation"] and s["state"] == "converged"), 120)
    n1, px1 = page_image(after["image"])
    if after["reload"] != "cast kept":
        fail(f"an intensity edit recast the shot: {after}")
    # The same noise would cancel; the light picks changed with the lamp, so
    # compare what ten times the lamp must do: brighten, never darken, a patch.
    lum = lambda px: px @ np.array([0.2126, 0.7152, 0.0722])
    diff = lum(px1) - lum(px0)
    brighter, darker = (diff > 8).mean(), (diff < -8).mean()
    if brighter < MIN_CHANGED or brighter <= darker:
        fail(f"ten times lamp_1: {brighter * 100:.2f} % of pixels brighter by 8 codes, {darker * 100:.2f} % darker")

    # A malformed edit: the panel names the key; the page keeps answering.
    set_lamp_1('"bright"')
    err = wait_for("the error in the panel", lambda: cdp.eval(
        "(() => { const e = document.getElementById('live-error'); return e.hidden ? '' : e.textContent; })()"), 30)
    if "intensity" not in err or os.path.basename(copy) not in err:
        fail(f"the panel's error names neither the file nor the key: {err!r}")
    get_json(url + "api/shot")

    cdp.screenshot(SHOT_PNG)
    cdp.check_page_errors()
    print(f"live browser: first image {first_s:.1f} s after start ({first[1].shape[1]}x{first[1].shape[0]});"
          f" at {before['spp']} spp {'denoised' if before['denoised'] else 'noisy'}; lamp_1 x10 in the shot file:"
          f" first image {edit_s:.1f} s after the save, at {after['spp']} spp {brighter * 100:.1f} % of pixels"
          f" brighter, {darker * 100:.2f} % darker (cast kept); a malformed edit shown as: {err}")
finally:
    for p in (copy, copy + ".tmp"):
        if os.path.exists(p):
            os.remove(p)
    stop(browser)
    stop(server)
    shutil.rmtree(profile, ignore_errors=True)
