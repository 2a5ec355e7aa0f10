"""The page's server: the static page and one WebSocket, with the ``websockets`` package.

One asyncio loop serves both. ``GET /`` (and the page's script and style sheet, shipped
in ``deploy/viewer/static/``) are answered from ``process_request``; ``/ws`` upgrades to a
WebSocket. A ticker asks the ``FrameSource`` for the current frame ``fps`` times a second
and encodes it once; every page is sent the newest frame when it is ready for one, so a
slow page skips frames and nothing queues without bound (a frame replaces the last).

The page sends small commands as JSON: ``{"op": "select", "robot": 3}`` asks for that
robot's whole opinion with every frame; pause, play and speed (live and replay) and the
replay's seeking go to the source's ``command``. After each frame a page is sent the
points of the swarm's curves it has not got yet (``series``), for its charts.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable
from http import HTTPStatus
from importlib import resources
from typing import Any, Protocol

import msgspec
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

log = logging.getLogger("viewer")

DEFAULT_FPS = 10.0
MAX_COMMAND_BYTES = 4096
STATIC_FILES = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
    "/viewer.css": ("viewer.css", "text/css; charset=utf-8"),
}
WEBSOCKET_PATH = "/ws"


class FrameSource(Protocol):
    """Where frames come from: a live run or a recording."""

    def hello(self) -> dict[str, Any]: ...

    def frame(self) -> dict[str, Any]: ...

    def opinion(self, robot: int) -> dict[str, Any]: ...

    def command(self, message: dict[str, Any]) -> None: ...

    def series_since(self, epoch: int, count: int) -> dict[str, Any] | None:
        """The chart points a page holding ``count`` of ``epoch`` lacks (None: none)."""
        ...

    def page_connected(self) -> None:
        """A page connected (a live run held for the first one goes on)."""
        ...


def static_file(name: str) -> bytes:
    return resources.files("deploy.viewer").joinpath("static", name).read_bytes()


def _response(status: HTTPStatus, body: bytes, content_type: str) -> Response:
    headers = Headers()
    headers["Content-Type"] = content_type
    headers["Content-Length"] = str(len(body))
    headers["Cache-Control"] = "no-store"  # a reload after an upgrade gets the new page
    headers["Connection"] = "close"
    return Response(status.value, status.phrase, headers, body)


class _Page:
    """One connected page: what it selected, and the newest frame it was sent."""

    def __init__(self, connection: ServerConnection) -> None:
        self.connection = connection
        self.selected: int | None = None
        self.sent = 0  # sequence number of the last frame sent
        self.series_epoch = -1  # the chart points it holds: of this epoch ...
        self.series_count = 0  # ... this many


class ViewServer:
    def __init__(self, source: FrameSource, fps: float = DEFAULT_FPS) -> None:
        self.source = source
        self.period = 1.0 / fps
        self.pages: set[_Page] = set()
        self.sequence = 0
        self.latest = b""
        self._new_frame = asyncio.Event()
        self._encoder = msgspec.json.Encoder()
        self._server: Server | None = None
        self._ticker: asyncio.Task[None] | None = None
        self.on_tick: Callable[[], Awaitable[None]] | None = None

    async def start(self, host: str, port: int) -> int:
        """Listen on ``host:port``; return the port (useful with port 0)."""
        self._server = await serve(
            self._page,
            host,
            port,
            process_request=self._http,
            max_size=MAX_COMMAND_BYTES,
            compression=None,  # frames are small and frequent: deflate costs more than it saves
        )
        self._ticker = asyncio.create_task(self._tick())
        sockets = list(self._server.sockets)
        return int(sockets[0].getsockname()[1]) if sockets else port

    async def close(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

    def _http(self, connection: ServerConnection, request: Request) -> Response | None:
        path = request.path.split("?", 1)[0]
        if path == WEBSOCKET_PATH:
            return None  # the WebSocket handshake goes on
        found = STATIC_FILES.get(path)
        if found is None:
            return _response(HTTPStatus.NOT_FOUND, b"not found\n", "text/plain; charset=utf-8")
        name, content_type = found
        return _response(HTTPStatus.OK, static_file(name), content_type)

    # --- frames ----------------------------------------------------------------------

    def publish(self) -> int:
        """Take the source's current frame now; return its sequence number."""
        self.latest = self._encoder.encode(self.source.frame())
        self.sequence += 1
        self._new_frame.set()
        self._new_frame = asyncio.Event()
        return self.sequence

    async def _tick(self) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            try:
                self.publish()
                if self.on_tick is not None:
                    await self.on_tick()
            except Exception:  # a bad frame must not end the view; the next may be fine
                log.exception("could not build a frame")
            next_at = max(next_at + self.period, loop.time())
            await asyncio.sleep(next_at - loop.time())

    async def flushed(self, sequence: int, timeout: float) -> bool:
        """Wait until every connected page was sent frame ``sequence`` (or a newer one)."""
        deadline = asyncio.get_running_loop().time() + timeout
        while any(page.sent < sequence for page in self.pages):
            if asyncio.get_running_loop().time() >= deadline:
                return False
            await asyncio.sleep(0.02)
        return True

    # --- one page ----------------------------------------------------------------------

    async def _page(self, connection: ServerConnection) -> None:
        page = _Page(connection)
        self.pages.add(page)
        log.info("a page connected from %s", connection.remote_address)
        listener = asyncio.create_task(self._listen(page))
        try:
            await connection.send(self._encoder.encode(self.source.hello()).decode())
            self.source.page_connected()
            while True:
                if page.sent == self.sequence:
                    await self._new_frame.wait()
                sequence, data = self.sequence, self.latest
                await connection.send(data.decode())  # waits while the page is slow
                page.sent = sequence
                if page.selected is not None:
                    opinion = self.source.opinion(page.selected)
                    await connection.send(self._encoder.encode(opinion).decode())
                update = self.source.series_since(page.series_epoch, page.series_count)
                if update is not None:
                    await connection.send(self._encoder.encode(update).decode())
                    page.series_epoch = update["epoch"]
                    count = len(update["points"])
                    page.series_count = count if update["reset"] else page.series_count + count
        except ConnectionClosed:
            pass
        finally:
            listener.cancel()
            self.pages.discard(page)

    async def _listen(self, page: _Page) -> None:
        with contextlib.suppress(ConnectionClosed):
            async for text in page.connection:
                try:
                    message = json.loads(text)
                    if not isinstance(message, dict):
                        raise ValueError("not an object")
                    if message.get("op") == "select":
                        robot = message.get("robot")
                        page.selected = robot if isinstance(robot, int) and robot >= 0 else None
                    else:
                        self.source.command(message)
                except (ValueError, TypeError) as error:
                    log.info("ignored a command from a page: %s", error)
