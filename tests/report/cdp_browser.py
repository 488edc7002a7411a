"""Headless Chromium over the DevTools protocol (pipe transport, no extra packages): load a page at
an emulated viewport width, collect console errors and uncaught exceptions, evaluate a script and
take a full-page screenshot.

    python tests/report/cdp_browser.py reports/pendulum/report.html 390 /tmp/p390.png
"""
from __future__ import annotations

import base64
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome", "headless_shell")


def find_chromium() -> str | None:
    """$MPGSPEC_CHROMIUM, else the first Chromium-like binary on PATH."""
    env = os.environ.get("MPGSPEC_CHROMIUM")
    if env:
        return shutil.which(env) or (env if Path(env).is_file() else None)
    return next((p for p in map(shutil.which, NAMES) if p), None)


class Browser:
    """One headless Chromium; use as a context manager."""

    def __init__(self, exe: str, timeout: float = 60.0):
        self.timeout, self._id, self._buf, self.events = timeout, 0, b"", []
        self._tmp = tempfile.TemporaryDirectory(prefix="mpgspec-chromium-")
        to_r, self._to_w = os.pipe()
        self._from_r, from_w = os.pipe()

        def fds():  # the protocol pipes as fds 3 (commands in) and 4 (answers out)
            a, b = os.dup(to_r), os.dup(from_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
             "--no-default-browser-check", "--disable-extensions", "--hide-scrollbars", "--mute-audio",
             f"--user-data-dir={self._tmp.name}", "--remote-debugging-pipe", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            preexec_fn=fds, pass_fds=(3, 4))
        os.close(to_r)
        os.close(from_w)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except Exception:  # noqa: BLE001 - the browser may be gone already
            pass
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for fd in (self._to_w, self._from_r):
            try:
                os.close(fd)
            except OSError:
                pass
        self._tmp.cleanup()

    # --------------------------------------------------------------------------- protocol
    def _read(self, deadline: float) -> dict:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._from_r], [], [], left)[0]:
                raise TimeoutError("Chromium did not answer in time")
            chunk = os.read(self._from_r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed the DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method: str, session: str | None = None, **params) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._to_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            m = self._read(deadline)
            if m.get("id") == self._id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            self.events.append(m)

    def wait_event(self, method: str, session: str) -> dict:
        for k, m in enumerate(self.events):
            if m.get("method") == method and m.get("sessionId") == session:
                return self.events.pop(k)
        deadline = time.monotonic() + self.timeout
        while True:
            m = self._read(deadline)
            if m.get("method") == method and m.get("sessionId") == session:
                return m
            self.events.append(m)

    # --------------------------------------------------------------------------- pages
    def open(self, url: str, width: int, height: int = 900, script: str = "null",
             screenshot: str | Path | None = None) -> dict:
        """Load url at the viewport width; returns {'errors': [...], 'value': <script's value>}."""
        target = self.send("Target.createTarget", url="about:blank")["targetId"]
        s = self.send("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        try:
            for domain in ("Page", "Runtime", "Log"):
                self.send(f"{domain}.enable", s)
            self.send("Emulation.setDeviceMetricsOverride", s, width=width, height=height, deviceScaleFactor=1,
                      mobile=width < 700)
            self.events = [e for e in self.events if e.get("sessionId") != s]
            self.send("Page.navigate", s, url=url)
            self.wait_event("Page.loadEventFired", s)
            value = self.send("Runtime.evaluate", s, expression=script, returnByValue=True,
                              awaitPromise=True).get("result", {}).get("value")
            if screenshot is not None:
                data = self.send("Page.captureScreenshot", s, format="png", captureBeyondViewport=True)["data"]
                Path(screenshot).write_bytes(base64.b64decode(data))
            return {"errors": self._errors(s), "value": value}
        finally:
            self.send("Target.closeTarget", targetId=target)

    def _errors(self, session: str) -> list[str]:
        out = []
        for m in self.events:
            if m.get("sessionId") != session:
                continue
            p = m.get("params", {})
            if m.get("method") == "Runtime.exceptionThrown":
                d = p.get("exceptionDetails", {})
                out.append(d.get("exception", {}).get("description") or d.get("text", "exception"))
            elif m.get("method") == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif m.get("method") == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                out.append(p["entry"].get("text", "error"))
        self.events = [m for m in self.events if m.get("sessionId") != session]
        return out


if __name__ == "__main__":
    exe = find_chromium()
    if exe is None:
        sys.exit("no Chromium binary found")
    page, width, png = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    with Browser(exe) as b:
        r = b.open(Path(page).resolve().as_uri(), width, screenshot=png,
                   script="({w: innerWidth, sw: document.documentElement.scrollWidth})")
    print(json.dumps(r))
