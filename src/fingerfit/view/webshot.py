"""A PNG of Rerun's web viewer (``fingerfit view --web``) in headless Chromium.

Used by ``bench/view_screenshots.py`` (the pictures of ``docs/view.md``) and by the test
that the web viewer renders. Chromium is driven over its DevTools protocol on a pipe
(``--remote-debugging-pipe``: JSON messages, each ending in a NUL byte, read on the
browser's file descriptor 3 and written on its 4), so no package beyond the standard
library is needed. Its host resolver maps every name but ``localhost`` to nothing, so
the page can reach this machine only: what Rerun's web viewer would fetch elsewhere (its
usage reports, the examples list, the release check, web fonts) fails at once.

WebGL in a headless browser without a GPU comes from SwiftShader, Chromium's software
renderer (``--use-angle=swiftshader --enable-unsafe-swiftshader``);
:meth:`HeadlessChromium.webgl` says whether a page gets a WebGL 2 context.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .webserve import free_port

#: Chromium's switches: headless, the software WebGL, nothing fetched but this machine.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--ignore-gpu-blocklist",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-features=Translate,OptimizationHints,MediaRouter",
    "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE localhost , EXCLUDE 127.0.0.1",
)

#: Puts the pipe's two ends on file descriptors 3 and 4 of the browser, then runs it.
_LAUNCH = (
    "import fcntl, os, sys\n"
    "ends = [fcntl.fcntl(int(fd), fcntl.F_DUPFD, 10) for fd in sys.argv[1:3]]\n"
    "os.dup2(ends[0], 3)\n"
    "os.dup2(ends[1], 4)\n"
    "os.execv(sys.argv[3], sys.argv[3:])\n"
)


#: The line ``fingerfit view --web`` prints: the address to open.
_OPEN = re.compile(r"open (http://\S+)")


@contextlib.contextmanager
def served_view(args: list[str]) -> Iterator[str]:
    """Run ``fingerfit view ARGS --web`` (on free ports) until the block ends.

    Parameters
    ----------
    args : list of str
        ``fingerfit view``'s arguments (the model, the recording, ``--robot`` ...), without
        ``--web`` and its ports.

    Yields
    ------
    str
        The address it prints to open (its web viewer, connected to its data).

    Raises
    ------
    RuntimeError
        The command ended before printing the address (its output in the message).
    """
    fingerfit = str(Path(sys.executable).with_name("fingerfit"))
    ports = ["--web-port", str(free_port()), "--grpc-port", str(free_port())]
    proc = subprocess.Popen(
        [fingerfit, "view", *args, "--web", *ports],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        lines = []
        for line in proc.stdout:  # ends when the command does
            lines.append(line)
            found = _OPEN.search(line)
            if found:
                break
        else:
            raise RuntimeError("fingerfit view --web ended:\n" + "".join(lines))
        yield found.group(1)
    finally:
        proc.terminate()  # it serves until stopped; it writes nothing
        proc.wait()
        proc.stdout.close()


def find_chromium() -> str | None:
    """The path of a Chromium binary (``chromium``, ``chromium-browser``), or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


class HeadlessChromium:
    """A headless Chromium with one page, driven over the DevTools protocol on a pipe.

    Parameters
    ----------
    binary : str
        Chromium's executable.
    size : (int, int)
        The page's width and height (CSS pixels; the screenshots' pixels).
    profile : Path, optional
        The browser's profile folder (default: a temporary one, removed by
        :meth:`close`).
    """

    def __init__(self, binary: str, size: tuple[int, int] = (1400, 900), profile=None) -> None:
        self._tmp = None if profile is not None else tempfile.TemporaryDirectory()
        folder = Path(profile) if profile is not None else Path(self._tmp.name)
        to_browser, self._out = os.pipe()
        self._in, from_browser = os.pipe()
        cmd = [sys.executable, "-c", _LAUNCH, str(to_browser), str(from_browser), binary]
        cmd += [*CHROMIUM_FLAGS, "--remote-debugging-pipe"]
        cmd += [f"--user-data-dir={folder}", f"--window-size={size[0]},{size[1]}"]
        self.proc = subprocess.Popen(
            [*cmd, "about:blank"],
            pass_fds=(to_browser, from_browser),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        os.close(to_browser)
        os.close(from_browser)
        self._buffer = b""
        self._id = 0
        #: DevTools events kept (their method in :attr:`watch`), in order of arrival.
        self.events: list[dict] = []
        self.watch: set[str] = set()
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t["targetId"] for t in targets if t["type"] == "page")
        attached = self.call("Target.attachToTarget", targetId=page, flatten=True)
        self.session = attached["sessionId"]
        self.call("Page.enable", session=self.session)
        self.call(
            "Emulation.setDeviceMetricsOverride",
            session=self.session,
            width=size[0],
            height=size[1],
            deviceScaleFactor=1,
            mobile=False,
        )

    def call(self, method: str, session: str | None = None, **params: Any) -> dict:
        """Send one DevTools command and return its result (events in between are
        skipped); a browser error raises ``RuntimeError``."""
        self._id += 1
        message: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._out, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("method") in self.watch:
                self.events.append(reply)
            elif reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})

    def _read(self) -> dict:
        while b"\0" not in self._buffer:
            chunk = os.read(self._in, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed its DevTools pipe (it ended)")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page."""
        result = self.call(
            "Runtime.evaluate", session=self.session, expression=expression, returnByValue=True
        )
        return result.get("result", {}).get("value")

    def webgl(self) -> bool:
        """Whether the page gets a WebGL 2 context (what Rerun's web viewer draws with)."""
        probe = "!!document.createElement('canvas').getContext('webgl2')"
        return bool(self.evaluate(probe))

    def record_requests(self) -> None:
        """Keep, from now on, every request the page makes and how it failed, in
        :attr:`events`: ``Network.requestWillBeSent`` (asked for; a request a
        Content-Security-Policy refuses is asked for too, then fails),
        ``Network.loadingFailed`` (with ``blockedReason`` ``"csp"`` when the page's policy
        refused it before anything was sent) and the console's ``Log.entryAdded``
        (where Chromium reports each violation of the policy). The events are read
        with each command's reply (:meth:`requests`)."""
        self.watch |= {"Network.requestWillBeSent", "Network.loadingFailed", "Log.entryAdded"}
        self.call("Network.enable", session=self.session)
        self.call("Log.enable", session=self.session)

    def requests(self) -> list[dict]:
        """The page's requests since :meth:`record_requests`, each ``{"url", "failed",
        "blocked"}``: ``failed`` the error text (None if it did not fail), ``blocked`` the
        reason Chromium refused to send it (``"csp"``: the page's policy; None if sent)."""
        self.call("Browser.getVersion")  # reads the events that came before its reply
        found: dict[str, dict] = {}
        for e in self.events:
            p = e["params"]
            if e["method"] == "Network.requestWillBeSent":
                found[p["requestId"]] = {
                    "url": p["request"]["url"],
                    "failed": None,
                    "blocked": None,
                }
            elif e["method"] == "Network.loadingFailed" and p["requestId"] in found:
                found[p["requestId"]]["failed"] = p.get("errorText")
                found[p["requestId"]]["blocked"] = p.get("blockedReason")
        return list(found.values())

    def open(self, url: str) -> None:
        """Navigate the page to ``url``."""
        self.call("Page.navigate", session=self.session, url=url)

    def screenshot(self) -> bytes:
        """The page as it is drawn now, a PNG."""
        data = self.call("Page.captureScreenshot", session=self.session, format="png")["data"]
        return base64.b64decode(data)

    def close(self) -> None:
        """End the browser and remove its temporary profile."""
        try:
            self.call("Browser.close")
        except (RuntimeError, OSError):
            pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for fd in (self._out, self._in):
            os.close(fd)
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def png_pixels(png: bytes) -> np.ndarray:
    """A PNG's pixels, shape (height, width, 3), RGB in [0, 1]."""
    import io

    from matplotlib import image

    return np.asarray(image.imread(io.BytesIO(png), format="png"))[..., :3]


#: The 3D view's box in the default layout (``fingerfit.view.blueprint``) beside Rerun's
#: side panels: (left, top, right, bottom), fractions of the page's width and height.
SCENE_BOX = (0.16, 0.1, 0.5, 0.7)


def coloured_share(pixels: np.ndarray, box: tuple[float, float, float, float]) -> float:
    """The share of the pixels inside ``box`` that are coloured (not grey).

    Rerun's own panels, text and grid are grey, white or black; the hand's axes, tips,
    sensors and labels are coloured. So an empty view, the welcome page or a page still
    loading gives 0, and a drawn hand a few per cent.

    Parameters
    ----------
    pixels : ndarray, shape (h, w, 3)
        RGB in [0, 1] (:func:`png_pixels`).
    box : (left, top, right, bottom)
        Fractions of the width and height (:data:`SCENE_BOX`: the 3D view).

    Returns
    -------
    float
        Pixels whose channels spread by more than 0.25, as a share of the box's pixels.
    """
    h, w = pixels.shape[:2]
    left, top, right, bottom = box
    region = pixels[int(top * h) : int(bottom * h), int(left * w) : int(right * w)]
    return float(np.mean(region.max(axis=2) - region.min(axis=2) > 0.25))


def shoot(
    browser: HeadlessChromium,
    url: str,
    ready: Callable[[np.ndarray], bool],
    deadline_s: float = 180.0,
    settle_s: float = 2.0,
) -> bytes:
    """Open ``url`` and take screenshots until ``ready`` says the picture is drawn.

    Parameters
    ----------
    browser : HeadlessChromium
    url : str
    ready : callable
        Gets each screenshot's pixels (:func:`png_pixels`); True when it shows what is
        wanted.
    deadline_s : float
        Seconds after which the last screenshot is returned as it is (a slow machine:
        the caller's ``ready`` then decides).
    settle_s : float
        Seconds between screenshots, and waited once more after the first ready one
        (the viewer finishes its layout), which is then returned.

    Returns
    -------
    bytes
        A PNG.
    """
    browser.open(url)
    end = time.monotonic() + deadline_s
    while True:
        time.sleep(settle_s)
        png = browser.screenshot()
        if ready(png_pixels(png)):
            time.sleep(settle_s)
            return browser.screenshot()
        if time.monotonic() > end:
            return png
