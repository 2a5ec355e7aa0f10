"""Finding the world server of a run: every process asks ``world/info`` before it starts."""

from __future__ import annotations

import time

import zenoh

from robot_agent import protocol


def fetch_world_info(
    session: zenoh.Session, keys: protocol.Keys, timeout: float
) -> protocol.WorldInfo:
    """Ask ``world/info`` until a world server answers, or raise TimeoutError."""
    deadline = time.monotonic() + timeout
    last_error = "no reply"
    while time.monotonic() < deadline:
        for reply in session.get(keys.world_info, timeout=1.0):
            if reply.ok is None:
                last_error = str(reply.err.payload.to_bytes()) if reply.err else "error reply"
                continue
            try:
                return protocol.decode(reply.ok.payload.to_bytes(), protocol.WorldInfo)
            except protocol.ProtocolError as error:
                last_error = f"invalid world/info: {error}"
        time.sleep(0.1)
    raise TimeoutError(f"no world server answered on {keys.world_info} ({last_error})")
