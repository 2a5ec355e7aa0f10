"""The children's log lines, echoed with ``--verbose`` and published on ``log/<process>``
so that the recorder keeps them.

Lines come from the process group's pump threads. Until the recorder listens they are
held back (with a recording), so that the recording has them too; the relay publishes
only between ``attach`` and ``detach``, under one lock, so that no line goes out on a
session that is closing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import zenoh

from bestofn_swarm.wire import auth, keyspace, names, protocol

MAX_LINE = 4096  # characters of a line that are published


class LogRelay:
    """Passes each child's lines on: to ``echo``, and to the run's ``log/<process>``."""

    def __init__(
        self, keys: keyspace.Keys, echo: Callable[[str, str], None] | None, hold: bool
    ) -> None:
        self.keys = keys
        self.echo = echo
        self._held: list[protocol.LogLine] | None = [] if hold else None
        self._session: zenoh.Session | None = None
        self._keyring: auth.Keyring | None = None
        self._lock = threading.Lock()

    def line(self, process: str, line: str) -> None:
        """A child's line (called from its pump thread)."""
        if self.echo is not None:
            self.echo(process, line)
        if not line:
            return
        message = protocol.LogLine(
            v=protocol.VERSION, process=process, wall_time=time.time(), line=line[:MAX_LINE]
        )
        with self._lock:
            if self._held is not None:
                self._held.append(message)
            else:
                self._publish(message)

    def attach(self, session: zenoh.Session, keyring: auth.Keyring | None) -> None:
        """Publish from now on (the lines held back wait for ``release``)."""
        with self._lock:
            self._session, self._keyring = session, keyring

    def release(self) -> None:
        """The recorder listens: publish the lines held back, in their order, then every
        line as it comes."""
        with self._lock:  # so that no newer line overtakes them
            held, self._held = self._held or [], None
            for message in held:
                self._publish(message)

    def detach(self) -> None:
        """Publish no more: the session is about to close. Lines are still echoed."""
        with self._lock:
            self._session = None

    def _publish(self, message: protocol.LogLine) -> None:
        if self._session is None:
            return
        key, payload = self.keys.of(keyspace.LOG, message.process), protocol.encode(message)
        attachment = auth.seal(self._keyring, names.LAUNCHER, key, payload)
        self._session.put(key, payload, attachment=attachment)
