"""A real browser for tests: headless Chromium driven over the DevTools protocol.

No driver package: Chromium listens on ``--remote-debugging-port`` and the test talks to
one page over a WebSocket (the ``websockets`` client the project already depends on),
sending ``Page.navigate``, ``Runtime.evaluate`` and ``Page.captureScreenshot``. Chromium
is the distribution's package (``apt-get install chromium``; ``.ci/run`` installs it);
where none is found, ``chromium_or_skip`` skips the test and says why.
"""

from __future__ import annotations

import base64
import contextlib
import itertools
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import ClientConnection, connect

from bestofn_swarm.plumbing.tcp import free_port

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = (
    "--headless",
    "--no-sandbox",  # CI runs as root, where Chromium's sandbox refuses to start
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--mute-audio",
)


def chromium_or_skip() -> str:
    for name in CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    pytest.skip(
        "no Chromium found (looked for " + ", ".join(CANDIDATES) + "): install the "
        "distribution's package, e.g. apt-get install chromium, to run the browser tests"
    )


class Browser:
    """One headless Chromium with one page, driven over the DevTools protocol."""

    def __init__(self, executable: str, width: int = 1280, height: int = 860) -> None:
        self.profile = tempfile.mkdtemp(prefix="bestofn-chromium-")
        self.port = free_port()
        self.process = subprocess.Popen(
            [
                executable,
                *FLAGS,
                f"--remote-debugging-port={self.port}",
                f"--user-data-dir={self.profile}",
                f"--window-size={width},{height}",
                "about:blank",
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        self._ids = itertools.count(1)
        self._stack = contextlib.ExitStack()
        self.connection: ClientConnection = self._stack.enter_context(
            connect(self._page_socket(), max_size=64 * 1024 * 1024, open_timeout=10)
        )
        self.call(
            "Emulation.setDeviceMetricsOverride",
            width=width,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )

    def _page_socket(self, timeout: float = 30.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"Chromium exited with code {self.process.returncode}")
            with contextlib.suppress(OSError, ValueError):
                with urllib.request.urlopen(
                    f"http://127.0.0.1:{self.port}/json/list", timeout=1
                ) as r:
                    pages = [t for t in json.load(r) if t.get("type") == "page"]
                if pages:
                    return str(pages[0]["webSocketDebuggerUrl"])
            time.sleep(0.1)
        raise TimeoutError("Chromium's DevTools endpoint did not come up")

    def call(self, method: str, timeout: float = 20.0, **params: Any) -> dict[str, Any]:
        """Send one DevTools command and wait for its answer (events in between are skipped)."""
        ident = next(self._ids)
        self.connection.send(json.dumps({"id": ident, "method": method, "params": params}))
        deadline = time.monotonic() + timeout
        while True:
            message = json.loads(
                self.connection.recv(timeout=max(0.01, deadline - time.monotonic()))
            )
            if message.get("id") == ident:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return dict(message.get("result", {}))

    def navigate(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def evaluate(self, expression: str) -> Any:
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def canvas_data(self) -> dict[str, str]:
        """The model the page drew, as it exposes it on the canvas (data- attributes)."""
        value = self.evaluate(
            "(() => { const c = document.getElementById('arena');"
            " return c ? Object.assign({}, c.dataset) : null; })()"
        )
        return dict(value or {})

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._stack.close()
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        shutil.rmtree(self.profile, ignore_errors=True)


@contextlib.contextmanager
def browser() -> Iterator[Browser]:
    instance = Browser(chromium_or_skip())
    try:
        yield instance
    finally:
        instance.close()


def pixel_statistics(png: bytes) -> dict[str, float]:
    """What a screenshot shows, in numbers: not blank, not one colour, how busy."""
    import cv2
    import numpy as np

    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError("not a PNG image")
    pixels = image.reshape(-1, 3)
    quantised = (pixels // 16).astype(np.int32)
    keys = quantised[:, 0] * 256 + quantised[:, 1] * 16 + quantised[:, 2]
    background = np.all(pixels >= 245, axis=1)
    return {
        "width": float(image.shape[1]),
        "height": float(image.shape[0]),
        "std": float(pixels.std()),
        "colours": float(len(np.unique(keys))),
        "non_background": float(1.0 - background.mean()),
    }


def share_of_colour(png: bytes, hex_colour: str, tolerance: int = 12) -> float:
    """The share of pixels within ``tolerance`` of a colour (``#rrggbb``)."""
    import cv2
    import numpy as np

    decoded = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert decoded is not None, "not an image"
    image = decoded.astype(np.int32)
    red, green, blue = (int(hex_colour[i : i + 2], 16) for i in (1, 3, 5))
    target = np.array([blue, green, red])
    return float(np.all(np.abs(image - target) <= tolerance, axis=2).mean())


def save(png: bytes, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png)
