"""What the browser checks (.ci/review_browser.py, .ci/mixer_browser.py,
.ci/live_browser.py) share: Debian's Chromium, headless, driven over the DevTools protocol
(PyPI websocket-client), and `throng review` started on a free port."""

import base64
import json
import os
import shutil
import subprocess
import sys
import time
import urllib.request

import websocket

NAME = "browser"  # each check names itself in its failures


def fail(msg):
    print(f"FAIL: {NAME}: {msg}")
    sys.exit(1)


def get_json(url):
    with urllib.request.urlopen(url, timeout=60) as r:
        return json.load(r)


def wait_for(what, test, timeout=60.0, soft=False):
    end = time.time() + timeout
    while time.time() < end:
        v = test()
        if v:
            return v
        time.sleep(0.1)
    if soft:
        raise TimeoutError(what)
    fail(f"timed out waiting for {what}")


class Cdp:
    """The DevTools protocol over one page's websocket: commands by id, events kept.
    `eval` fails on a page exception unless `lenient`, when it answers None."""

    def __init__(self, ws_url, lenient=False):
        self.ws = websocket.create_connection(ws_url, timeout=60, suppress_origin=True)
        self.next = 0
        self.events = []
        self.lenient = lenient

    def __call__(self, method, **params):
        self.next += 1
        me = self.next
        self.ws.send(json.dumps({"id": me, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == me:
                if "error" in msg:
                    fail(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def eval(self, expr):
        r = self("Runtime.evaluate", expression=expr, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            if self.lenient:
                return None
            fail(f"evaluating {expr!r}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def poll(self, expr):
        """`eval` for waiting loops: None while the page is between documents."""
        self.next += 1
        me = self.next
        self.ws.send(json.dumps({"id": me, "method": "Runtime.evaluate",
                                 "params": {"expression": expr, "returnByValue": True}}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == me:
                r = msg.get("result", {})
                if "error" in msg or "exceptionDetails" in r:
                    return None
                return r.get("result", {}).get("value")
            self.events.append(msg)

    def open(self, url):
        """Navigates to `url`, again if the first navigation raced the new
        tab's initial about:blank (it can be lost then)."""
        for _ in range(3):
            self("Page.navigate", url=url)
            end = time.time() + 15
            while time.time() < end:
                if (self.poll("location.href") or "").startswith(url):
                    return
                time.sleep(0.1)
        fail(f"Chromium did not open {url}")

    def screenshot(self, path):
        """Saves what the page shows, as PNG, at `path`."""
        with open(path, "wb") as f:
            f.write(base64.b64decode(self("Page.captureScreenshot", format="png")["data"]))

    def check_page_errors(self, console=False):
        """Fails if the page threw (with `console`, also if it logged an error)."""
        errors = [e for e in self.events if e.get("method") == "Runtime.exceptionThrown"]
        if console:
            errors += [
                e
                for e in self.events
                if e.get("method") == "Runtime.consoleAPICalled" and e["params"].get("type") == "error"
            ]
        if errors:
            fail(f"the page threw: {errors[:3]}")


def start_review(argv):
    """`throng review ... --port 0` started; (the process, its URL)."""
    server = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = server.stdout.readline()
    url = next((w for w in line.split() if w.startswith("http://127.0.0.1:")), None)
    if not url:
        fail(f"throng review printed no URL: {line!r} {server.stderr.read() if server.poll() is not None else ''}")
    return server, url


def stop(process):
    """Ends a process this check started (a server, the browser): asked, then killed after 10 s."""
    if process is None:
        return
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()


def launch_chromium(profile, lenient=False):
    """Headless Chromium on a 1400x1000 page with its profile in `profile`; (the process, a Cdp on its page)."""
    browser = subprocess.Popen(
        [shutil.which("chromium") or "chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--no-default-browser-check", "--remote-debugging-port=0", f"--user-data-dir={profile}",
         "--window-size=1400,1000", "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    port_file = os.path.join(profile, "DevToolsActivePort")
    wait_for("Chromium's DevTools port", lambda: os.path.exists(port_file) and open(port_file).read().strip(), 60)
    port = open(port_file).read().split()[0]
    pages = wait_for("a page target",
                     lambda: [t for t in get_json(f"http://127.0.0.1:{port}/json/list") if t.get("type") == "page"], 30)
    cdp = Cdp(pages[0]["webSocketDebuggerUrl"], lenient)
    cdp("Page.enable")
    cdp("Runtime.enable")
    cdp("Emulation.setDeviceMetricsOverride", width=1400, height=1000, deviceScaleFactor=1, mobile=False)
    return browser, cdp
