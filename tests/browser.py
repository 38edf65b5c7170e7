"""A small headless-Chromium driver for the tests: the Chrome DevTools Protocol over a pipe.

Chromium started with ``--remote-debugging-pipe`` reads commands on its file descriptor 3 and writes
replies and events on 4, each one JSON message ended by a NUL byte; no port, no websocket, no new
dependency. One :class:`Browser` is one Chromium (its own profile in a temporary folder, its own
process group) with one page, and it

* **blocks the network**: every request the page or its workers make is paused (``Fetch``), and
  anything but ``localhost``/``127.0.0.1``/``file:``/``data:``/``blob:`` is failed and recorded in
  :attr:`Browser.blocked` (a test asserts it stays empty); as a second line, every other host name is
  unresolvable and the proxy is a dead port, so a request ``Fetch`` does not see (a websocket) fails too;
* evaluates JavaScript (:meth:`Browser.evaluate`, :meth:`Browser.wait_for`);
* takes screenshots as RGB arrays (:meth:`Browser.screenshot`);
* drives the mouse (:meth:`Browser.drag`);
* collects console errors and uncaught exceptions (:attr:`Browser.errors`);
* always ends Chromium: :meth:`Browser.close` (a ``with`` block, a timeout, an error, exit) kills
  the whole process group.

:func:`chromium_or_skip` finds the browser, or skips the test saying what to install, except under CI
(``CI=true``), where ``.ci/run`` installs it and a missing browser fails the test.
"""

from __future__ import annotations

import atexit
import base64
import fcntl
import json
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import pytest

__all__ = ["Browser", "BrowserError", "chromium_or_skip", "find_chromium", "is_local", "screenshot_dir"]

LOCAL_HOSTS = {"localhost", "127.0.0.1", "[::1]", "::1"}
LOCAL_SCHEMES = {"file", "data", "blob", "about", "chrome", "devtools", "chrome-extension"}


class BrowserError(RuntimeError):
    """Chromium died, did not answer in time, or a command or a page's script failed."""


def find_chromium() -> str | None:
    """The Chromium (or Chrome) on PATH, or None."""
    return next(
        (shutil.which(c) for c in ("chromium", "chromium-browser", "google-chrome") if shutil.which(c)), None
    )


def chromium_or_skip() -> str:
    """The browser's path; skip the test when there is none, but fail under CI (``.ci/run`` installs it)."""
    path = find_chromium()
    if path is None:
        why = "no chromium on PATH to drive headless (apt-get install chromium)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"CI=true and {why}; .ci/run installs it")
        pytest.skip(why)
    return path


def screenshot_dir() -> Path:
    """Where the tests keep their screenshots: ``LAB_TEST_SCREENSHOTS``, else ``out/test-screenshots``
    in the checkout (``out/`` is not committed)."""
    return Path(
        os.environ.get("LAB_TEST_SCREENSHOTS")
        or Path(__file__).resolve().parent.parent / "out" / "test-screenshots"
    )


def is_local(url: str) -> bool:
    """Whether ``url`` stays on this machine (the only requests the test browser lets through)."""
    parts = urlsplit(url)
    return parts.scheme in LOCAL_SCHEMES or (parts.hostname or "") in LOCAL_HOSTS


class Browser:
    """One headless Chromium with one page, driven over the DevTools pipe (see the module's docstring).

    ``timeout`` [s] bounds every command and wait unless one says otherwise; ``size`` is the window
    (width, height) in CSS pixels.
    """

    def __init__(
        self, *, size: tuple[int, int] = (1280, 900), timeout: float = 60.0, chromium: str | None = None
    ):
        exe = chromium or find_chromium()
        if exe is None:
            raise BrowserError("no chromium on PATH (apt-get install chromium)")
        self.timeout = timeout
        self.size = size
        self.blocked: list[str] = []  # external requests the page tried, all failed
        self.errors: list[str] = []  # console errors and uncaught exceptions, in order
        self.network_errors: list[str] = []  # failed loads (the blocked ones among them)
        self._profile = tempfile.mkdtemp(prefix="lab-chromium-")
        self._lock = threading.Lock()  # one writer on the pipe at a time
        self._replies: dict[int, dict] = {}
        self._arrived = threading.Condition()
        self._next_id = 0
        self._dead: str | None = None
        self._loads = 0
        self._proc = None
        cmd_r, cmd_w = os.pipe()  # we write commands, Chromium reads them on its fd 3
        out_r, out_w = os.pipe()  # Chromium writes on its fd 4, we read
        # above 2..4, so that moving them onto 3 and 4 in the child cannot overwrite one another
        child_in, child_out = (
            fcntl.fcntl(cmd_r, fcntl.F_DUPFD_CLOEXEC, 10),
            fcntl.fcntl(out_w, fcntl.F_DUPFD_CLOEXEC, 10),
        )
        for fd in (cmd_r, out_w):
            os.close(fd)

        def onto_3_and_4():  # in the child, before exec: dup2 leaves both inheritable
            os.dup2(child_in, 3)
            os.dup2(child_out, 4)

        args = [
            exe, "--headless=new", "--no-sandbox", "--remote-debugging-pipe",
            f"--user-data-dir={self._profile}",
            f"--window-size={size[0]},{size[1]}", "--no-first-run", "--no-default-browser-check",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--disable-default-apps", "--disable-extensions", "--mute-audio", "--hide-scrollbars",
            "--enable-unsafe-swiftshader", "--use-angle=swiftshader",  # WebGL without a GPU
            "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=localhost;127.0.0.1;[::1]",
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE localhost, EXCLUDE 127.0.0.1",
            "about:blank",
        ]  # fmt: skip
        try:
            self._proc = subprocess.Popen(
                args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                close_fds=False, preexec_fn=onto_3_and_4, start_new_session=True,
            )  # fmt: skip
        finally:
            os.close(child_in)
            os.close(child_out)
        atexit.register(self.close)
        self._out = os.fdopen(cmd_w, "wb", buffering=0)
        self._in = os.fdopen(out_r, "rb", buffering=0)
        self._reader = threading.Thread(target=self._read, name="chromium-pipe", daemon=True)
        self._reader.start()
        try:
            self._attach()
        except BaseException:
            self.close()
            raise

    @property
    def pid(self) -> int | None:
        """Chromium's process id, also its process group's (None once closed)."""
        return None if self._proc is None else self._proc.pid

    # -- the pipe -------------------------------------------------------------------------------

    def _read(self) -> None:
        buf = b""
        while True:
            try:
                chunk = self._in.read(1 << 16)
            except OSError:
                chunk = b""
            if not chunk:
                with self._arrived:
                    self._dead = self._dead or "chromium closed its DevTools pipe (it exited)"
                    self._arrived.notify_all()
                return
            buf += chunk
            *messages, buf = buf.split(b"\0")
            for raw in messages:
                msg = json.loads(raw)
                if "id" in msg:
                    with self._arrived:
                        self._replies[msg["id"]] = msg
                        self._arrived.notify_all()
                else:
                    self._on_event(msg)

    def _post(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        with self._lock:
            self._next_id += 1
            msg = {"id": self._next_id, "method": method, "params": params or {}}
            if session:
                msg["sessionId"] = session
            try:
                self._out.write(json.dumps(msg).encode() + b"\0")
            except OSError as e:
                raise BrowserError(f"chromium is gone ({e}); cannot send {method}") from None
            return self._next_id

    def send(
        self,
        method: str,
        params: dict | None = None,
        session: str | None = "page",
        timeout: float | None = None,
    ) -> dict:
        """Send one DevTools command (to the page unless ``session`` is None: the browser) and return its
        result; :class:`BrowserError` when it fails or no reply comes within ``timeout`` [s]."""
        sid = self._session if session == "page" else session
        mid = self._post(method, params, sid)
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        with self._arrived:
            while mid not in self._replies:
                left = deadline - time.monotonic()
                if self._dead or left <= 0:
                    raise BrowserError(
                        f"{method}: {self._dead or f'no reply within {timeout or self.timeout} s'}"
                    )
                self._arrived.wait(min(left, 0.5))
            reply = self._replies.pop(mid)
        if "error" in reply:
            raise BrowserError(
                f"{method}: {reply['error'].get('message')} ({reply['error'].get('data', '')})"
            )
        return reply.get("result", {})

    def _attach(self) -> None:
        page = next(
            t for t in self.send("Target.getTargets", session=None)["targetInfos"] if t["type"] == "page"
        )
        self._session = self.send(
            "Target.attachToTarget", {"targetId": page["targetId"], "flatten": True}, session=None
        )["sessionId"]
        self._instrument(self._session)
        self.send(
            "Emulation.setDeviceMetricsOverride",
            {"width": self.size[0], "height": self.size[1], "deviceScaleFactor": 1, "mobile": False},
        )

    def _instrument(self, session: str) -> None:
        """Network blocking, error collection and auto-attach (workers, frames) on one target."""
        for method, params in (
            ("Fetch.enable", {"patterns": [{"urlPattern": "*", "requestStage": "Request"}]}),
            ("Runtime.enable", {}),
            ("Log.enable", {}),
            ("Page.enable", {}),
            ("Target.setAutoAttach", {"autoAttach": True, "waitForDebuggerOnStart": True, "flatten": True}),
        ):
            try:
                self._post(method, params, session)  # replies are not awaited: this may run on the reader
            except BrowserError:
                return

    def _on_event(self, msg: dict) -> None:
        method, params, session = msg.get("method"), msg.get("params", {}), msg.get("sessionId")
        try:
            if method == "Fetch.requestPaused":
                url = params["request"]["url"]
                if is_local(url):
                    self._post("Fetch.continueRequest", {"requestId": params["requestId"]}, session)
                else:
                    self.blocked.append(url)
                    self._post(
                        "Fetch.failRequest",
                        {"requestId": params["requestId"], "errorReason": "BlockedByClient"},
                        session,
                    )
            elif method == "Target.attachedToTarget" and session:  # the page's worker or frame: same rules
                self._instrument(params["sessionId"])
                self._post("Runtime.runIfWaitingForDebugger", {}, params["sessionId"])
            elif method == "Runtime.exceptionThrown":
                d = params["exceptionDetails"]
                self.errors.append(f"exception: {d.get('exception', {}).get('description') or d.get('text')}")
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                text = " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", []))
                self.errors.append(f"console.{params['type']}: {text}")
            elif method == "Log.entryAdded" and params["entry"].get("level") == "error":
                e = params["entry"]
                line = f"{e.get('text')} {e.get('url', '')}".strip()
                (self.network_errors if e.get("source") == "network" else self.errors).append(line)
            elif method == "Page.javascriptDialogOpening":  # leaving JupyterLab asks; nobody to answer
                if params.get("type") != "beforeunload":
                    self.errors.append(f"dialog {params.get('type')}: {params.get('message')}")
                self._post("Page.handleJavaScriptDialog", {"accept": True}, session)
            elif method == "Page.loadEventFired" and session == getattr(self, "_session", None):
                self._loads += 1
        except BrowserError:
            pass  # chromium is exiting; the waiter hears it from the reader

    # -- what a test uses -----------------------------------------------------------------------

    def open(self, where: str | Path, timeout: float | None = None) -> None:
        """Load a URL or a local file and wait for its load event."""
        url = where.resolve().as_uri() if isinstance(where, Path) else where
        loads = self._loads
        r = self.send("Page.navigate", {"url": url})
        if r.get("errorText"):
            raise BrowserError(f"cannot open {url}: {r['errorText']}")
        deadline = time.monotonic() + (timeout or self.timeout)
        while self._loads == loads:
            if self._dead or time.monotonic() > deadline:
                raise BrowserError(f"{url} did not finish loading: {self._dead or 'timeout'}")
            time.sleep(0.05)

    def evaluate(self, expression: str, timeout: float | None = None):
        """The value of a JavaScript expression in the page (promises awaited); a thrown error is a
        :class:`BrowserError` with the page's message."""
        r = self.send(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True, "userGesture": True},
            timeout=timeout,
        )
        if "exceptionDetails" in r:
            d = r["exceptionDetails"]
            raise BrowserError(f"script failed: {d.get('exception', {}).get('description') or d.get('text')}")
        return r["result"].get("value")

    def wait_for(self, expression: str, timeout: float | None = None, what: str = "", poll: float = 0.25):
        """Poll a JavaScript expression until it is truthy and return its value; :class:`BrowserError`
        naming ``what`` (else the expression) on timeout."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            value = self.evaluate(f"(v => v instanceof Node ? true : v)({expression})")  # no DOM by value
            if value:
                return value
            if time.monotonic() > deadline:
                raise BrowserError(
                    f"timed out after {timeout or self.timeout} s waiting for {what or expression}"
                )
            time.sleep(poll)

    def screenshot(self, clip: dict | None = None, path: Path | None = None) -> np.ndarray:
        """The page as an RGB array (H, W, 3), or only ``clip`` = {x, y, width, height} [CSS px, in the
        page]; also saved as a PNG at ``path`` when one is given."""
        import cv2

        params = {"format": "png", "captureBeyondViewport": clip is not None}
        if clip is not None:
            params["clip"] = {**{k: float(clip[k]) for k in ("x", "y", "width", "height")}, "scale": 1}
        png = base64.b64decode(self.send("Page.captureScreenshot", params)["data"])
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(path.name + ".part")
            tmp.write_bytes(png)
            tmp.replace(path)
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        return img[..., ::-1].copy()

    def settled_screenshot(
        self, clip: dict | None = None, path: Path | None = None, timeout: float | None = None
    ) -> np.ndarray:
        """A screenshot once the page stops changing: two in a row, a few animation frames apart, are
        the same (a WebGL scene applying a batch of updates, text drawn by a worker); saved at ``path``."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        previous = None
        while True:
            self.frames(2)
            img = self.screenshot(clip)
            if previous is not None and np.array_equal(img, previous):
                break
            if time.monotonic() > deadline:
                raise BrowserError(f"the page kept changing for {timeout or self.timeout} s")
            previous = img
            time.sleep(0.2)
        if path is not None:
            self.screenshot(clip, path)
        return img

    def rect(self, selector: str) -> dict:
        """The bounding box {x, y, width, height} [CSS px] of the first element matching ``selector``."""
        r = self.evaluate(
            "(e => e && JSON.stringify(e.getBoundingClientRect()))"
            f"(document.querySelector({json.dumps(selector)}))"
        )
        if not r:
            raise BrowserError(f"no element matches {selector}")
        return json.loads(r)

    def drag(self, start: tuple[float, float], end: tuple[float, float], steps: int = 8) -> None:
        """Press the left mouse button at ``start``, move to ``end`` and release there [CSS px]."""

        def mouse(kind, x, y, buttons):
            self.send(
                "Input.dispatchMouseEvent",
                {"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons, "clickCount": 1},
            )

        mouse("mouseMoved", *start, 0)
        mouse("mousePressed", *start, 1)
        for i in range(1, steps + 1):
            f = i / steps
            mouse("mouseMoved", start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1]), 1)
        mouse("mouseReleased", *end, 0)

    def frames(self, n: int = 3) -> None:
        """Let the page draw ``n`` animation frames (a WebGL scene catching up with a change)."""
        self.evaluate(
            f"new Promise(r => {{ let k = {n}; const f = () => --k ? requestAnimationFrame(f) : r(1);"
            " requestAnimationFrame(f); })"
        )

    def close(self) -> None:
        """Kill Chromium's process group and remove its profile (idempotent)."""
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait(timeout=30)
            self._reader.join(timeout=10)  # the pipe's far end is closed now: the reader sees EOF
            for f in (getattr(self, "_out", None), getattr(self, "_in", None)):
                if f is not None:
                    try:
                        f.close()
                    except OSError:
                        pass
        shutil.rmtree(self._profile, ignore_errors=True)
        atexit.unregister(self.close)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
