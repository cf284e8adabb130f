"""The review page's samples view of deep renders in a real browser
(docs/review.md): Debian's Chromium, headless, over the DevTools protocol.

Starts `throng review SHOT --renders DIR` on a folder of deep renders, picks
LAYER, and asks for the view the layer's `deep` entry names: the page must
offer it, draw the server's heat map (`/api/deep.png`) at the layer's size,
show the legend up to the layer's most samples per pixel (as `/api/layers`
gives it, read from the deep file's header), hide the legend again on
another view, and throw nothing.

usage: deep_view_browser.py THRONG SHOT RENDERS FRAME LAYER SCREENSHOT.png
"""

import shutil
import sys
import tempfile
import time

import browser as browser_harness
from browser import fail, get_json, launch_chromium, start_review, stop, wait_for

THRONG, SHOT, RENDERS, FRAME, LAYER, SHOT_PNG = sys.argv[1:7]
browser_harness.NAME = "deep view browser"


def choose(select, value):
    """Sets a <select> as a user would (its change event fires)."""
    cdp.eval(
        f"(() => {{ const s = document.getElementById('{select}'); s.value = '{value}';"
        " s.dispatchEvent(new Event('change')); })()"
    )


server = browser = None
profile = tempfile.mkdtemp(prefix="throng-deep-view-chromium-")
try:
    server, url = start_review([THRONG, "review", SHOT, "--renders", RENDERS, "--port", "0", "--frame", FRAME])
    layers = get_json(url + f"api/layers?frame={FRAME}")["layers"]
    layer = next((l for l in layers if l["name"] == LAYER), None)
    if not layer or not layer.get("deep"):
        fail(f"/api/layers gives layer {LAYER} no deep entry: {layers}")
    view, most = layer["deep"]["view"], layer["deep"]["max"]
    if not 1 <= most <= 256:
        fail(f"the layer's most samples per pixel is {most}")

    browser, cdp = launch_chromium(profile)
    cdp.open(url)
    wait_for("the page's layer list", lambda: cdp.poll(
        f"[...document.getElementById('layer').options].some(o => o.value === '{LAYER}')"), 30)
    choose("layer", LAYER)
    wait_for(f"the view list to offer `{view}`", lambda: cdp.poll(
        f"[...document.getElementById('view').options].some(o => o.value === '{view}')"), 30)
    choose("view", view)
    wait_for("the heat map to load", lambda: cdp.poll(
        "(() => { const i = document.getElementById('image');"
        " return i.complete && i.naturalWidth > 0 && i.src.includes('/api/deep.png'); })()"), 30)
    size = cdp.eval("[document.getElementById('image').naturalWidth, document.getElementById('image').naturalHeight]")
    if size != [layer["width"], layer["height"]]:
        fail(f"the heat map is {size}, the layer {layer['width']}x{layer['height']}")
    legend = cdp.eval("(() => { const l = document.getElementById('deep-legend'); return l && !l.hidden ? l.innerText : null; })()")
    if not legend or f"{most} (the most" not in legend:
        fail(f"the legend does not give the layer's most ({most}): {legend!r}")
    cdp.screenshot(SHOT_PNG)
    choose("view", "beauty")
    wait_for("the legend to hide on the beauty view",
             lambda: cdp.poll("document.getElementById('deep-legend').hidden") is True, 30)
    cdp.check_page_errors(console=True)
    print(f"deep view browser: {LAYER}'s samples view drawn at {size[0]}x{size[1]}, legend up to {most}"
          " samples a pixel, hidden again on beauty")
finally:
    stop(server)
    stop(browser)
    time.sleep(0.2)
    shutil.rmtree(profile, ignore_errors=True)
