"""Headless Chromium driven through the DevTools protocol over a pipe (`--remote-debugging-pipe`: no port, no
websocket, no package): open a page, run JavaScript in it, click, read its console errors, take a screenshot.
Debian's `chromium` only (the project's rule: never a browser a package downloads); tests skip without it."""
from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--remote-debugging-pipe")


def _above_4(fd: int) -> int:
    """`fd` moved to a number above 4 (the one given is closed)."""
    moved = fcntl.fcntl(fd, fcntl.F_DUPFD, 5)
    os.close(fd)
    return moved


class BrowserError(RuntimeError):
    """The browser said no, went away, or did not answer in time."""


class Browser:
    """One headless Chromium with one page. `with Browser() as b: b.open(path); b.eval("1 + 1")`."""

    def __init__(self, width: int = 1400, height: int = 1000, timeout_s: float = 30.0) -> None:
        if CHROMIUM is None:
            raise BrowserError("no chromium (Debian: apt-get install chromium)")
        self.timeout_s = timeout_s
        self.profile = tempfile.mkdtemp(prefix="tamp-chromium-")
        to_browser, self._write = os.pipe()
        self._read, from_browser = os.pipe()
        # above 4, so that putting one at 3 or 4 in the browser does not overwrite the other
        to_browser, from_browser = (_above_4(fd) for fd in (to_browser, from_browser))
        # the protocol's pipe is the browser's fds 3 (it reads) and 4 (it writes); bash puts them there (sh takes
        # fds up to 9 only)
        self.process = subprocess.Popen(
            ["bash", "-c", f'exec "$0" "$@" 3<&{to_browser} 4>&{from_browser}', CHROMIUM, *FLAGS,
             f"--user-data-dir={self.profile}", f"--window-size={width},{height}", "about:blank"],
            pass_fds=(to_browser, from_browser), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser)
        os.close(from_browser)
        self._buffer, self._next_id, self.events = b"", 0, []
        target = self.send("Target.createTarget", url="about:blank")["targetId"]
        self.session = self.send("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.send(f"{domain}.enable", session=True)
        self.send("Emulation.setDeviceMetricsOverride", session=True, width=width, height=height,
                  deviceScaleFactor=1, mobile=False)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def close(self) -> None:
        if self.process.poll() is None:
            try:
                self.send("Browser.close")
            except BrowserError:
                pass
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        for fd in (self._read, self._write):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self.profile, ignore_errors=True)

    def _message(self) -> dict[str, Any]:
        deadline = time.monotonic() + self.timeout_s
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._read], [], [], left)[0]:
                raise BrowserError("the browser did not answer in time")
            chunk = os.read(self._read, 1 << 20)
            if not chunk:
                raise BrowserError("the browser went away")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(line)

    def send(self, method: str, session: bool = False, **params: Any) -> dict[str, Any]:
        """Call `method` (on the page's session if `session`) and return its result; events met meanwhile are
        kept in `events`."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params}
        if session:
            message["sessionId"] = self.session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._message()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str) -> dict[str, Any]:
        """The first event `method` not yet seen (those already received first)."""
        for k, event in enumerate(self.events):
            if event.get("method") == method:
                return self.events.pop(k)
        while True:
            event = self._message()
            if event.get("method") == method:
                return event
            self.events.append(event)

    def open(self, path: Path, fragment: str = "") -> None:
        """Load the file at `path` (with `#fragment`) afresh, and wait for its load event; `errors` then counts from
        this page on."""
        # through a blank page: a URL that differs from the one open only in its fragment would not reload
        for url in ("about:blank", Path(path).resolve().as_uri() + (f"#{fragment}" if fragment else "")):
            self.events = [e for e in self.events if e.get("method") != "Page.loadEventFired"]
            self.send("Page.navigate", session=True, url=url)
            self.wait_for("Page.loadEventFired")
            if url == "about:blank":
                self.eval("0")
                self.events = []

    def eval(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (awaited if a promise); BrowserError if it throws."""
        result = self.send("Runtime.evaluate", session=True, expression=expression, returnByValue=True,
                           awaitPromise=True)
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            raise BrowserError(details.get("exception", {}).get("description") or details.get("text"))
        return result["result"].get("value")

    def click(self, selector: str) -> None:
        """A real mouse click (pressed and released) at the centre of the first element `selector` finds."""
        box = self.eval(f"(() => {{ const e = document.querySelector({json.dumps(selector)}); if (!e) return null;"
                        " e.scrollIntoView({block: 'center'}); const r = e.getBoundingClientRect();"
                        " return [r.left + r.width / 2, r.top + r.height / 2]; })()")
        if box is None:
            raise BrowserError(f"nothing to click at {selector}")
        for kind in ("mousePressed", "mouseReleased"):
            self.send("Input.dispatchMouseEvent", session=True, type=kind, x=box[0], y=box[1], button="left",
                      clickCount=1)

    def errors(self) -> list[str]:
        """The console errors and uncaught exceptions seen so far (events drained from the pipe first)."""
        self.eval("0")
        found = []
        for event in self.events:
            method, params = event.get("method"), event.get("params", {})
            if method == "Runtime.exceptionThrown":
                found.append(params["exceptionDetails"].get("exception", {}).get("description") or "exception")
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                found.append(" ".join(str(a.get("value", a.get("description"))) for a in params.get("args", [])))
            elif method == "Log.entryAdded" and params["entry"].get("level") == "error":
                found.append(params["entry"].get("text", ""))
        return found

    def screenshot(self, out: Path, clip_selector: str | None = None) -> Path:
        """A PNG of the page (of the element `clip_selector` finds, when given) at `out`."""
        params: dict[str, Any] = {"format": "png"}
        if clip_selector is not None:
            rect = self.eval(f"(() => {{ const r = document.querySelector({json.dumps(clip_selector)})"
                             ".getBoundingClientRect();"
                             " return [r.left + scrollX, r.top + scrollY, r.width, r.height]; })()")
            params["clip"] = {"x": rect[0], "y": rect[1], "width": rect[2], "height": rect[3], "scale": 1}
            params["captureBeyondViewport"] = True
        data = self.send("Page.captureScreenshot", session=True, **params)["data"]
        out.write_bytes(base64.b64decode(data))
        return out
