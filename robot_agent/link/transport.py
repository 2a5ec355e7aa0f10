"""The link's two transports, for the robot's end (and the serial line for the bridge's too).

Both carry link frames (wire/link.py) and never block the loop that drives them:

* ``UdpLink``: one datagram is one frame, sent to the bridge's address; what comes from any
  other address is dropped (counted).
* ``SerialLine``: frames as ``COBS(frame + CRC-32) 0x00`` on a serial port (pyserial): a
  UART, a USB or Bluetooth serial adapter, or a pseudo-terminal. Writes are paced at the
  line's baud rate (8N1): a pseudo-terminal moves bytes at memory speed, and a frame must
  not arrive before its last byte could have. What cannot be written yet waits, up to
  ``MAX_PENDING_BYTES``; past that a frame is dropped (counted).

Each has ``fileno()`` for ``select``, ``send(frame, now)``, ``receive(now)`` (the frames
that arrived; the refusals of the serial framing are counted in ``refused``),
``flush(now)`` and ``deadline`` (when a paced write falls due), and ``close()``.
"""

from __future__ import annotations

import errno
import logging
import socket
from collections import Counter, deque
from types import TracebackType

import serial

from wire import link

log = logging.getLogger("robot_agent.link")

RECEIVE_BUFFER_BYTES = 1024 * 1024
MAX_PENDING_BYTES = 256 * 1024  # paced serial output waiting to leave
MAX_DATAGRAMS_PER_RECEIVE = 256
READ_BYTES = 65536


class LinkClosedError(OSError):
    """The transport is gone for good (a serial device removed, a closed descriptor)."""


class UdpLink:
    """The robot's UDP link to the bridge at ``address``."""

    def __init__(self, address: link.LinkAddress) -> None:
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

    def send(self, frame: bytes, now: float) -> None:
        try:
            self.socket.send(frame)
            self.sent += 1
        except OSError:  # no bridge listening yet, or a full buffer: a lost datagram
            self.send_failures += 1

    def flush(self, now: float) -> None:
        """Nothing waits: a datagram leaves at once."""

    def receive(self, now: float) -> list[bytes]:
        frames: list[bytes] = []
        for _ in range(MAX_DATAGRAMS_PER_RECEIVE):
            try:
                data = self.socket.recv(link.MAX_FRAME_BYTES + 1)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as error:  # ECONNREFUSED: an earlier datagram found no bridge
                if error.errno == errno.ECONNREFUSED:
                    continue
                raise
            if len(data) > link.MAX_FRAME_BYTES:
                self.refused[link.Refusal.OVERSIZE] += 1
                continue
            frames.append(data)
        return frames

    def close(self) -> None:
        self.socket.close()

    def __enter__(self) -> UdpLink:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


class SerialLine:
    """Link frames on one serial port, paced at its baud rate."""

    def __init__(self, path: str, baud: int = link.DEFAULT_BAUD) -> None:
        try:
            self.port = serial.Serial(path, baudrate=baud, timeout=0, write_timeout=0)
        except (serial.SerialException, ValueError) as error:
            raise OSError(f"cannot open serial port {path}: {error}") from None
        self.path = path
        self.baud = baud
        self.pacer = link.LinePacer(baud)
        self.deframer = link.Deframer()
        self.queued: deque[tuple[float, bytes]] = deque()  # (when it may go, its bytes)
        self.queued_bytes = 0
        self.unwritten = b""  # what the OS did not take last time
        self.refused: Counter[str] = Counter()
        self.sent = self.send_failures = 0

    def fileno(self) -> int:
        return int(self.port.fileno())

    @property
    def deadline(self) -> float | None:
        return self.queued[0][0] if self.queued else None

    def send(self, frame: bytes, now: float) -> None:
        encoded = link.serial_encode(frame)
        if self.queued_bytes + len(encoded) > MAX_PENDING_BYTES:
            self.send_failures += 1  # the line is that far behind: the frame is lost
            return
        self.queued.append((self.pacer.done_at(len(encoded), now), encoded))
        self.queued_bytes += len(encoded)
        self.flush(now)

    def flush(self, now: float) -> None:
        """Write what is due (and what the OS did not take before)."""
        while self.queued and self.queued[0][0] <= now:
            _, encoded = self.queued.popleft()
            self.queued_bytes -= len(encoded)
            self.unwritten += encoded
            self.sent += 1
        while self.unwritten:
            try:
                written = self.port.write(self.unwritten)
            except serial.SerialException as error:
                raise LinkClosedError(f"serial port {self.path}: {error}") from None
            if not written:
                return
            self.unwritten = self.unwritten[written:]

    def receive(self, now: float) -> list[bytes]:
        try:
            data = self.port.read(READ_BYTES)
        except serial.SerialException as error:
            raise LinkClosedError(f"serial port {self.path}: {error}") from None
        frames: list[bytes] = []
        for item in self.deframer.feed(bytes(data)):
            if isinstance(item, link.LinkError):
                self.refused[item.refusal] += 1
            else:
                frames.append(item)
        return frames

    def close(self) -> None:
        self.port.close()

    def __enter__(self) -> SerialLine:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


Transport = UdpLink | SerialLine


def open_transport(address: link.LinkAddress) -> Transport:
    """The robot's end of the link at ``address``; OSError if it cannot be opened."""
    if address.transport == "udp":
        return UdpLink(address)
    return SerialLine(address.path, address.baud)
