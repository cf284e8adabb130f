"""The light mixer of `throng review` in a real browser (docs/review.md,
"The mixer"): Debian's Chromium, headless, over the DevTools protocol.

Renders the demo's `full` layer with light-group passes (an edited copy of
the shot beside it, indirect clamp off: the clamp is not linear in the
light), opens `throng review` on it, and with real mouse events moves
lamp_1's gain slider and mutes the dome; after each change the image the
page shows (read back from the page through a canvas) must be the sum of
gain x each group's pass of the file (read with PyPI's OpenEXR) tone-mapped
as the server does, within one 8-bit code. Then "Save as shot" writes a new
shot beside it (a second save under the same name is refused), whose render
must match the regraded image within noise; a malformed mix gets a 400 and
the server answers the next request.

usage: mixer_browser.py THRONG SHOT WORKDIR SCREENSHOT.png
"""

import json
import os
import shutil
import subprocess
import sys
import tempfile
import urllib.error
import urllib.request

import numpy as np
import OpenEXR
import browser as browser_harness
from browser import fail, get_json, launch_chromium, start_review, stop, wait_for

THRONG, SHOT, WORK, SHOT_PNG = sys.argv[1:5]
FRAME = 1024
SIZE = (96, 54)
SPP = 32


browser_harness.NAME = "mixer browser"


def render(shot, out):
    subprocess.run(
        [THRONG, "render", shot, "--layer", "full", "--frames", str(FRAME), "--spp", str(SPP),
         "--resolution", f"{SIZE[0]}x{SIZE[1]}", "--passes", "light_groups", "--progress", "off", "--out", out],
        check=True, stdout=subprocess.DEVNULL,
    )
    return os.path.join(out, "full", f"demo.full.{FRAME:04d}.exr")


def channels(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        return {k: np.asarray(v.pixels, dtype=np.float64) for k, v in f.channels().items()}


def srgb8(linear):
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.floor(s * 255.0 + 0.5)


def regraded(ch, gains):
    """Sum over the file's groups of gain x pass (linear, H x W x 3)."""
    groups = sorted({k[3:-2] for k in ch if k.startswith("lg_") and k.endswith(".R")})
    out = np.zeros(ch["R"].shape + (3,))
    for g in groups:
        out += gains.get(g, 1.0) * np.stack([ch[f"lg_{g}.{c}"] for c in "RGB"], axis=-1)
    return out, groups


base_text = open(SHOT).read().replace("[render]\n", "[render]\nindirect_clamp = 0.0\n", 1)
edited = os.path.join(os.path.dirname(os.path.abspath(SHOT)), f".mixer_browser_{os.getpid()}.toml")
saved_name = f"mixer_browser_{os.getpid()}_look.toml"
saved = os.path.join(os.path.dirname(edited), saved_name)
with open(edited, "w") as f:
    f.write(base_text)
profile = tempfile.mkdtemp(prefix="throng-mixer-chromium-")
server = browser = None
try:
    exr = render(edited, os.path.join(WORK, "mixer_base"))
    ch = channels(exr)
    server, url = start_review(
        [THRONG, "review", edited, "--renders", os.path.join(WORK, "mixer_base"), "--port", "0", "--frame", str(FRAME)]
    )
    # A malformed mix: 400, and the server answers the next request.
    for bad in ["lamp_1:-1:1:1:1", "lamp_1:1", "nope:1:1:1:1", "lamp_1:nan:1:1:1"]:
        try:
            urllib.request.urlopen(url + f"api/mix.png?frame={FRAME}&layer=full&mix={bad}", timeout=60)
            fail(f"mix={bad} was answered 200")
        except urllib.error.HTTPError as e:
            if not 400 <= e.code < 500:
                fail(f"mix={bad}: status {e.code}")
    get_json(url + "api/frames")

    browser, cdp = launch_chromium(profile, lenient=True)
    cdp.open(url)
    try:
        wait_for("the mixer rows", lambda: cdp.eval(
            "(() => { const i = document.getElementById('image'); return i && i.complete && i.naturalWidth > 0"
            " && document.querySelectorAll('#mixer tr').length >= 6; })()"), 60, soft=True)
    except TimeoutError:
        rows = cdp.poll("document.querySelectorAll('#mixer tr').length")
        says = cdp.poll("(document.getElementById('mixer') || {}).innerText")
        fail(f"timed out waiting for the mixer rows: {cdp.poll('location.href')!r} shows {rows} rows; the mixer says {says!r}")

    def shown():
        """The page's image, read back through a canvas: H x W x 3 codes, and its URL."""
        v = cdp.eval(
            "(() => { const i = document.getElementById('image'); const c = document.createElement('canvas');"
            " c.width = i.naturalWidth; c.height = i.naturalHeight; const x = c.getContext('2d');"
            " x.drawImage(i, 0, 0); const d = x.getImageData(0, 0, c.width, c.height).data;"
            " const out = []; for (let k = 0; k < d.length; k += 4) out.push(d[k], d[k + 1], d[k + 2]);"
            " return [i.src, c.width, c.height, out]; })()")
        src, w, h, px = v
        return src, np.array(px, dtype=np.float64).reshape(h, w, 3)

    def click(selector):
        r = cdp.eval(
            f"(() => {{ const e = document.querySelector({json.dumps(selector)}); e.scrollIntoView({{block: 'center'}});"
            " const r = e.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; })()")
        return r

    def mouse(x, y):
        for kind in ["mouseMoved", "mousePressed", "mouseReleased"]:
            cdp("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left",
                buttons=1 if kind == "mousePressed" else 0, clickCount=1)

    def settled(test_src):
        return wait_for("the page's image to follow the mixer", lambda: cdp.eval(
            "(() => { const i = document.getElementById('image'); return i.complete && i.naturalWidth > 0"
            f" && ({test_src})(i.src); }})()"), 60)

    def check(gains, what):
        src, px = shown()
        want = srgb8(regraded(ch, gains)[0])
        off = np.abs(px - want)
        if off.max() > 1.0 or (off > 0).mean() > 0.05:
            fail(f"{what}: the page shows {src} off the sum of the passes by up to {off.max()} codes"
                 f" ({(off > 0).mean() * 100:.1f} % of values off)")
        return px, off

    src0, px0 = shown()
    beauty = np.stack([ch[c] for c in "RGB"], axis=-1)
    if np.abs(px0 - srgb8(beauty)).max() > 1.0:
        fail("the page's first image is not the file's beauty")
    # lamp_1's gain slider: a real click at 3/4 of its track (+4 stops).
    x, y, w, h = click('#mixer tr[data-group="lamp_1"] input.gain')
    mouse(x + 0.75 * w, y + h / 2)
    settled("s => s.includes('mix=')")
    stops = float(cdp.eval("document.querySelector('#mixer tr[data-group=\"lamp_1\"] input.gain').value"))
    if stops <= 1:
        fail(f"the slider moved to {stops} stops")
    gains = {"lamp_1": 2.0 ** stops}
    px1, off1 = check(gains, f"lamp_1 at +{stops} stops")
    changed = (np.abs(px1 - px0) > 2).any(axis=-1).mean()
    if changed < 0.01:
        fail(f"raising lamp_1 by {stops} stops changed {changed * 100:.2f} % of the pixels")
    # Mute the dome: a real click on its checkbox.
    x, y, w, h = click('#mixer tr[data-group="dome"] input.mute')
    mouse(x + w / 2, y + h / 2)
    settled("s => s.includes('dome%3A0')")
    gains["dome"] = 0.0
    px2, _ = check(gains, "dome muted")

    # Save as shot: type a name, press Save.
    x, y, w, h = click("#save-name")
    mouse(x + w / 2, y + h / 2)
    cdp("Input.insertText", text=saved_name)
    x, y, w, h = click("#save button[type=submit]")
    mouse(x + w / 2, y + h / 2)
    wait_for("the saved shot", lambda: cdp.eval("document.getElementById('save-result').dataset.file || ''"), 60)
    result = cdp.eval("document.getElementById('save-result').innerText")
    if not os.path.isfile(saved) or "throng render" not in result:
        fail(f"Save as shot: {saved} missing or no command shown: {result!r}")
    text = open(saved).read()
    if "[lights.gains]" not in text or "dome = { gain = 0.0" not in text:
        fail(f"the saved shot lacks the gains: {text[-400:]}")
    # The same name again: refused, the file untouched.
    mouse(x + w / 2, y + h / 2)
    wait_for("the second save refused", lambda: "Not saved" in (cdp.eval("document.getElementById('save-result').innerText") or ""), 30)
    if open(saved).read() != text:
        fail("a second save wrote over the saved shot")
    cdp.screenshot(SHOT_PNG)
    cdp.check_page_errors()

    # The saved shot renders to what the page showed, within noise.
    ch_saved = channels(render(saved, os.path.join(WORK, "mixer_saved")))
    got = np.stack([ch_saved[c] for c in "RGB"], axis=-1)
    want = regraded(ch, gains)[0]
    mean_off = np.abs(got.mean(axis=(0, 1)) - want.mean(axis=(0, 1))) / want.mean(axis=(0, 1))
    # Blocks on the display's scale (clipped to 0..1 as the page shows
    # them): a lamp at +4 stops throws fireflies whose linear values the
    # two renders' different light picks do not share.
    blocks = []
    bh, bw = SIZE[1] // 6, SIZE[0] // 8
    shown_got, shown_want = np.clip(got, 0, 1), np.clip(want, 0, 1)
    for by in range(6):
        for bx in range(8):
            a = shown_got[by * bh:(by + 1) * bh, bx * bw:(bx + 1) * bw].mean(axis=(0, 1))
            b = shown_want[by * bh:(by + 1) * bh, bx * bw:(bx + 1) * bw].mean(axis=(0, 1))
            blocks.append(np.abs(a - b).max())
    if mean_off.max() > 0.03 or max(blocks) > 0.05:
        fail(f"the saved shot renders off the page's image: frame mean by {mean_off.max() * 100:.2f} %,"
             f" worst block {max(blocks):.3f} on the 0..1 display scale")
    print(f"mixer browser: lamp_1 +{stops} stops and the dome muted: the page's image is the sum of the passes"
          f" (worst {off1.max():.0f} code); saved {saved_name}, whose render matches it (frame mean"
          f" {mean_off.max() * 100:.2f} %, worst of 48 blocks {max(blocks):.3f} on the 0..1 display scale); a second save refused")
finally:
    for p in (edited, saved):
        if os.path.exists(p):
            os.remove(p)
    stop(browser)
    stop(server)
    shutil.rmtree(profile, ignore_errors=True)
