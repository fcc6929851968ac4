"""Open a report in a real headless Chromium and measure what a reader would see (used by the browser
test and for screenshots). Talks the Chrome DevTools Protocol over ``--remote-debugging-pipe``
(fd 3 in, fd 4 out, NUL-terminated JSON messages), so it needs no Python package beyond the standard
library and no network port.

:func:`inspect_page` returns the console errors (``Runtime.consoleAPICalled`` of type error/assert,
``Runtime.exceptionThrown``, ``Log.entryAdded`` at level error, failed loads), every image's rendered
size, the elements whose right edge passes the viewport, and optionally a full-page PNG screenshot.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "chrome")

_MEASURE_JS = r"""
(() => {
  const vw = document.documentElement.clientWidth;
  const imgs = Array.from(document.images).map(i => {
    const r = i.getBoundingClientRect();
    return {alt: i.alt, width: r.width, height: r.height, natural: [i.naturalWidth, i.naturalHeight],
            complete: i.complete};
  });
  const wide = [];
  for (const el of document.querySelectorAll('body *')) {
    const r = el.getBoundingClientRect();
    if (r.width === 0 && r.height === 0) continue;
    if (r.right > vw + 0.5 || r.left < -0.5) {
      wide.push({tag: el.tagName.toLowerCase(), id: el.id, cls: el.className && String(el.className),
                 left: r.left, right: r.right, text: (el.textContent || '').slice(0, 60)});
    }
  }
  return {viewport: vw, scrollWidth: document.documentElement.scrollWidth, images: imgs, wide: wide,
          sections: Array.from(document.querySelectorAll('[id]')).map(e => e.id),
          external: Array.from(document.querySelectorAll('[src],[href]')).map(e => e.getAttribute('src') || e.getAttribute('href'))
                     .filter(u => u && !u.startsWith('data:') && !u.startsWith('#'))};
})()
"""


def find_browser() -> str | None:
    for name in BROWSERS:
        p = shutil.which(name)
        if p:
            return p
    return None


class _Pipe:
    def __init__(self, browser: str, user_dir: str):
        r_in, w_in = os.pipe()    # we write → chromium reads fd 3
        r_out, w_out = os.pipe()  # chromium writes fd 4 → we read
        args = [browser, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
                "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--hide-scrollbars",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--disable-dev-shm-usage", f"--user-data-dir={user_dir}", "about:blank"]

        def fds():  # in the child: the pipe ends become fds 3 and 4 (via fds >= 10, so none clobbers the other)
            a = fcntl.fcntl(r_in, fcntl.F_DUPFD, 10)
            b = fcntl.fcntl(w_out, fcntl.F_DUPFD, 10)
            os.dup2(a, 3)
            os.dup2(b, 4)
        self.proc = subprocess.Popen(args, preexec_fn=fds, close_fds=False,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
        os.close(r_in)
        os.close(w_out)
        self.w, self.r = w_in, r_out
        self.buf = b""
        self.next_id = 0
        self.events: list[dict] = []

    def send(self, method: str, params: dict | None = None, session: str | None = None, timeout: float = 30.0) -> dict:
        self.next_id += 1
        mid = self.next_id
        msg = {"id": mid, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            m = self._read(deadline)
            if m.get("id") == mid:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            self.events.append(m)

    def wait_event(self, method: str, timeout: float = 30.0) -> dict:
        deadline = time.monotonic() + timeout
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        while True:
            m = self._read(deadline)
            if m.get("method") == method:
                return m
            self.events.append(m)

    def _read(self, deadline: float) -> dict:
        import select
        while b"\0" not in self.buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no answer from the browser")
            ready, _, _ = select.select([self.r], [], [], left)
            if ready:
                chunk = os.read(self.r, 1 << 20)
                if not chunk:
                    raise RuntimeError("the browser closed the pipe")
                self.buf += chunk
        raw, self.buf = self.buf.split(b"\0", 1)
        return json.loads(raw)

    def close(self) -> None:
        try:
            os.write(self.w, json.dumps({"id": 10 ** 6, "method": "Browser.close"}).encode() + b"\0")
        except OSError:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for fd in (self.w, self.r):
            try:
                os.close(fd)
            except OSError:
                pass


def inspect_page(html_path: str | Path, width: int = 1400, height: int = 900, screenshot: str | Path | None = None,
                 browser: str | None = None) -> dict:
    """Load ``html_path`` at ``width`` × ``height`` CSS px and report console errors, images, overflow."""
    browser = browser or find_browser()
    if browser is None:
        raise FileNotFoundError("no Chromium found (apt-get install chromium)")
    url = Path(html_path).resolve().as_uri()
    with tempfile.TemporaryDirectory(prefix="sysid-chromium-") as user_dir:
        p = _Pipe(browser, user_dir)
        try:
            target = p.send("Target.createTarget", {"url": "about:blank"})["targetId"]
            sid = p.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
            for dom in ("Runtime.enable", "Log.enable", "Page.enable", "Network.enable"):
                p.send(dom, session=sid)
            p.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                          "mobile": False}, session=sid)
            p.send("Page.navigate", {"url": url}, session=sid)
            p.wait_event("Page.loadEventFired", timeout=60)
            time.sleep(0.3)   # let late console messages arrive
            res = p.send("Runtime.evaluate", {"expression": _MEASURE_JS, "returnByValue": True}, session=sid)
            measured = res["result"]["value"]
            if screenshot is not None:
                shot = p.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True}, session=sid,
                              timeout=60)
                Path(screenshot).parent.mkdir(parents=True, exist_ok=True)
                Path(screenshot).write_bytes(base64.b64decode(shot["data"]))
            p.send("Runtime.evaluate", {"expression": "1"}, session=sid)  # flush pending events
        finally:
            p.close()
    errors = []
    for e in p.events:
        m, prm = e.get("method"), e.get("params", {})
        if m == "Runtime.consoleAPICalled" and prm.get("type") in ("error", "assert"):
            errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in prm.get("args", [])))
        elif m == "Runtime.exceptionThrown":
            errors.append(prm.get("exceptionDetails", {}).get("text", "exception"))
        elif m == "Log.entryAdded" and prm.get("entry", {}).get("level") == "error":
            errors.append(prm["entry"].get("text", "log error"))
        elif m == "Network.loadingFailed":
            errors.append(f"load failed: {prm.get('errorText')}")
    measured["console_errors"] = errors
    return measured
