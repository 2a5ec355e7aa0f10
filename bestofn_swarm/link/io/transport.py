"""The link's transports, for both ends: link frames (``bestofn_swarm/link/core/codec.py``) over UDP
or a serial line, never blocking the loop that drives them (``hub.py``).

* ``UdpLink``: the robot's end on UDP: one datagram is one frame, sent to the bridge's
  address (the socket is connected to it, so the kernel drops datagrams from anywhere
  else; ICMP "refused", no bridge yet, is ignored).
* ``UdpServer``: the bridge's end on UDP: one address for every robot it serves; the robot
  id in a frame's header says whose link it is, and that robot's link key whether it is.
* ``SerialLine``: either end on a serial port (pyserial: a UART, a USB or Bluetooth serial
  adapter, a pseudo-terminal), 115200 baud by default, raw 8N1: frames as
  ``COBS(frame + CRC-32) 0x00``. Writes are paced at the baud rate, 10 bits a byte
  (``pacing.PacedLine``): a pseudo-terminal moves bytes at memory speed, and a byte must not
  arrive before the line could have carried it. Up to ``MAX_PENDING_BYTES`` wait; past that
  a frame is dropped (counted). ``receiving`` says a frame is under way (bytes of it read,
  its zero not yet), which the ends take as a sign of life; ``busy_until`` when what was
  written so far has all arrived.

Each has ``fileno()`` for ``select``, ``send(frame, target, now)`` (``target``: where a
UDP server sends it; the others have one peer), ``receive(now)`` (the frames that arrived,
each with where it came from; refusals of the transport's own checks are counted in
``refused``), ``flush(now)`` and ``deadline`` (when a paced write falls due), and
``close()``. A transport that cannot go on raises ``LinkClosedError`` (an OSError).
"""

from __future__ import annotations

import abc
import errno
import logging
import socket
from collections import Counter
from collections.abc import Hashable
from types import TracebackType
from typing import Any, Self, cast

import serial

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.core.pacing import PacedLine

log = logging.getLogger("link.transport")

RECEIVE_BUFFER_BYTES = 1024 * 1024
MAX_PENDING_BYTES = 256 * 1024  # paced serial output waiting to leave
MAX_DATAGRAMS_PER_RECEIVE = 256
SERVER_BUFFER_BYTES = 4 * 1024 * 1024  # the bridge's socket: every robot's datagrams
READ_BYTES = 65536


class LinkClosedError(OSError):
    """The transport is gone for good (a serial device removed, a closed descriptor)."""


class Closing(abc.ABC):
    """``with transport:`` closes it at the end."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the transport."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


class UdpLink(Closing):
    """The robot's UDP link to the bridge at ``address``."""

    def __init__(self, address: codec.LinkAddress) -> None:
        infos = socket.getaddrinfo(address.host, address.port, type=socket.SOCK_DGRAM)
        family, _, _, _, target = infos[0]
        self.address = address
        self.target = target
        self.socket = socket.socket(family, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        self.socket.setblocking(False)
        self.socket.connect(target)  # the kernel then drops datagrams from anywhere else
        self.refused: Counter[str] = Counter()
        self.sent = self.send_failures = 0

    def fileno(self) -> int:
        return self.socket.fileno()

    @property
    def deadline(self) -> float | None:
        return None

    def send(self, frame: bytes, target: Hashable, now: float) -> None:
        try:
            self.socket.send(frame)
            self.sent += 1
        except OSError:  # no bridge listening yet, or a full buffer: a lost datagram
            self.send_failures += 1

    def flush(self, now: float) -> None:
        """Nothing waits: a datagram leaves at once."""

    def receive(self, now: float) -> list[tuple[bytes, Hashable]]:
        frames: list[tuple[bytes, Hashable]] = []
        for _ in range(MAX_DATAGRAMS_PER_RECEIVE):
            try:
                data = self.socket.recv(codec.MAX_FRAME_BYTES + 1)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as error:  # ECONNREFUSED: an earlier datagram found no bridge
                if error.errno == errno.ECONNREFUSED:
                    continue
                raise LinkClosedError(f"UDP link to {self.address}: {error}") from None
            if len(data) > codec.MAX_FRAME_BYTES:
                self.refused[codec.Refusal.OVERSIZE] += 1
                continue
            frames.append((data, None))
        return frames

    def close(self) -> None:
        self.socket.close()


class SerialLine(Closing):
    """Link frames on one serial port, paced at its baud rate."""

    def __init__(self, path: str, baud: int = codec.DEFAULT_BAUD) -> None:
        try:
            self.port = serial.Serial(path, baudrate=baud, timeout=0, write_timeout=0)
        except (serial.SerialException, ValueError) as error:
            raise OSError(f"cannot open serial port {path}: {error}") from None
        self.path = path
        self.baud = baud
        self.line = PacedLine(baud)
        self.deframer = codec.Deframer()
        self.unwritten = b""  # what the OS did not take last time
        self.refused: Counter[str] = Counter()
        self.sent = self.send_failures = 0

    def fileno(self) -> int:
        return int(self.port.fileno())

    @property
    def deadline(self) -> float | None:
        return self.line.deadline

    @property
    def busy_until(self) -> float:
        """When the bytes written so far have all arrived at the far end."""
        return self.line.busy_until

    @property
    def receiving(self) -> bool:
        """Whether a frame is under way: bytes of it read, its closing zero not yet."""
        return self.deframer.receiving

    def discard_waiting(self, now: float) -> int:
        """Drop the frames whose first byte has not gone yet (a session that ended); how
        many."""
        return self.line.discard_waiting(now)

    def send(self, frame: bytes, target: Hashable, now: float) -> None:
        encoded = codec.serial_encode(frame)
        if self.line.held_bytes + len(encoded) > MAX_PENDING_BYTES:
            self.send_failures += 1  # the line is that far behind: the frame is lost
            return
        self.line.put(encoded, now)
        self.flush(now)

    def flush(self, now: float) -> None:
        """Write what is due (and what the OS did not take before)."""
        due, completed = self.line.take(now)
        self.unwritten += due
        self.sent += completed
        while self.unwritten:
            try:
                written = self.port.write(self.unwritten)
            except serial.SerialException as error:
                raise LinkClosedError(f"serial port {self.path}: {error}") from None
            if not written:
                return
            self.unwritten = self.unwritten[written:]

    def receive(self, now: float) -> list[tuple[bytes, Hashable]]:
        try:
            data = self.port.read(READ_BYTES)
        except serial.SerialException as error:
            raise LinkClosedError(f"serial port {self.path}: {error}") from None
        frames: list[tuple[bytes, Hashable]] = []
        for item in self.deframer.feed(bytes(data)):
            if isinstance(item, codec.LinkError):
                self.refused[item.refusal] += 1
            else:
                frames.append((item, None))
        return frames

    def close(self) -> None:
        self.port.close()


class UdpServer(Closing):
    """The bridge's UDP socket: one address for every robot it serves over UDP. It listens on
    loopback unless ``swarm run --link`` names another address, and takes at most
    ``MAX_DATAGRAMS_PER_RECEIVE`` datagrams a call, so a flood cannot starve the loop."""

    def __init__(self, host: str, port: int) -> None:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM, flags=socket.AI_PASSIVE)
        family, _, _, _, address = infos[0]
        self.socket = socket.socket(family, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SERVER_BUFFER_BYTES)
        self.socket.bind(address)
        self.socket.setblocking(False)
        self.refused: Counter[str] = Counter()
        self.sent = self.send_failures = 0

    @property
    def port(self) -> int:
        return int(self.socket.getsockname()[1])

    def fileno(self) -> int:
        return self.socket.fileno()

    @property
    def deadline(self) -> float | None:
        return None

    def receive(self, now: float) -> list[tuple[bytes, Hashable]]:
        """The datagrams waiting, with where each came from."""
        found: list[tuple[bytes, Hashable]] = []
        for _ in range(MAX_DATAGRAMS_PER_RECEIVE):
            try:
                data, source = self.socket.recvfrom(codec.MAX_FRAME_BYTES + 1)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # an ICMP error of an earlier send: nothing to read after all
                continue
            found.append((data, source))
        return found

    def send(self, frame: bytes, target: Hashable, now: float) -> None:
        try:
            self.socket.sendto(frame, cast(tuple[Any, ...], target))
            self.sent += 1
        except OSError:  # a full buffer, or the robot's address gone: a lost datagram
            self.send_failures += 1

    def flush(self, now: float) -> None:
        """Nothing waits: a datagram leaves at once."""

    def close(self) -> None:
        self.socket.close()


Transport = UdpLink | UdpServer | SerialLine


def open_transport(address: codec.LinkAddress) -> UdpLink | SerialLine:
    """The robot's end of the link at ``address``; OSError if it cannot be opened."""
    if address.transport == "udp":
        return UdpLink(address)
    return SerialLine(address.path, address.baud)
