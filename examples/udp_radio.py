"""A ``ports.Radio`` over plain UDP multicast or broadcast: what robots on a shared Wi-Fi use.

Every robot (and the nest beacon) sends its radio payloads as UDP datagrams to one
multicast group (default ``239.255.77.77:47777``, TTL 1 so nothing leaves the link) or to
a broadcast address, and hears everyone else's. Each datagram is one frame:

    offset  size  field
    0       2     magic, ASCII "BN" (0x42 0x4E)
    2       1     frame version, 0x01
    3       1     L, the sender name's length in bytes, 1..64
    4       L     sender name, ASCII letters, digits, '_', '.', '-' (a robot: its id in decimal)
    4 + L   rest  the radio payload, 1..2048 bytes (protocol.encode of an OpinionPayload
                  or BeaconPayload; opaque here, validated by ports.decode_received)

so a datagram is at most ``MAX_DATAGRAM_BYTES`` = 4 + 64 + 2048 = 2116 bytes. Datagrams
that are not such a frame are dropped and counted, never raised; the radio's own
datagrams, which multicast and broadcast loop back to the sending host, are recognised by
their source address and port and skipped. ``poll`` never blocks.

Pure socket code: no Zenoh, no numpy. See docs/porting.md.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import re
import socket
import struct
import sys
from dataclasses import dataclass, replace
from types import TracebackType

from bestofn_swarm.wire import names

log = logging.getLogger(__name__)

DEFAULT_GROUP = "239.255.77.77"
DEFAULT_PORT = 47777
MAGIC = b"BN"
FRAME_VERSION = 1
HEADER_BYTES = 4
MAX_SENDER_BYTES = 64
MAX_RADIO_PAYLOAD_BYTES = 2048  # an opinion over n = 100 sites fits, with room to spare
MAX_DATAGRAM_BYTES = HEADER_BYTES + MAX_SENDER_BYTES + MAX_RADIO_PAYLOAD_BYTES
DEFAULT_MAX_PER_POLL = 1024  # bounds one poll under a flood; the rest waits for the next
RECEIVE_BUFFER_BYTES = 256 * 1024  # a burst of ~100 full datagrams at one poll
_MAX_LOGGED_SOURCES = 1000  # memory bound for "log the first bad datagram per source"

_SENDER = re.compile(names.NAME_RE.pattern.encode())  # a name, as protocol.py says


class FrameError(ValueError):
    """Bytes that are not a valid radio frame."""


class FrameTooLargeError(FrameError):
    """A frame, or the payload in it, longer than the limits allow."""


def sender_bytes(sender: str) -> bytes:
    """The sender name as it goes on the wire; FrameError if it cannot."""
    name = sender.encode("ascii", "replace")
    if not _SENDER.fullmatch(name):
        raise FrameError(
            f"sender {sender!r} must be 1..{MAX_SENDER_BYTES} ASCII letters, digits, '_.-'"
        )
    return name


def encode_frame(sender: str, payload: bytes) -> bytes:
    """The datagram that carries ``payload`` from ``sender``; FrameError if either is invalid."""
    name = sender_bytes(sender)
    if not payload:
        raise FrameError("empty payload")
    if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
        raise FrameTooLargeError(
            f"payload of {len(payload)} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}"
        )
    return MAGIC + bytes((FRAME_VERSION, len(name))) + name + bytes(payload)


def decode_frame(datagram: bytes) -> tuple[str, bytes]:
    """``(sender, payload)`` of a datagram; FrameError if it is not a valid frame."""
    if len(datagram) > MAX_DATAGRAM_BYTES:
        raise FrameTooLargeError(f"datagram of {len(datagram)} bytes exceeds {MAX_DATAGRAM_BYTES}")
    if len(datagram) < HEADER_BYTES:
        raise FrameError(f"datagram of {len(datagram)} bytes is shorter than the header")
    if datagram[:2] != MAGIC:
        raise FrameError(f"bad magic {bytes(datagram[:2])!r}")
    if datagram[2] != FRAME_VERSION:
        raise FrameError(f"frame version {datagram[2]}, expected {FRAME_VERSION}")
    length = datagram[3]
    name = bytes(datagram[HEADER_BYTES : HEADER_BYTES + length])
    if len(name) != length or not _SENDER.fullmatch(name):
        raise FrameError(f"invalid sender name {name!r} (length byte {length})")
    payload = bytes(datagram[HEADER_BYTES + length :])
    if not payload:
        raise FrameError("empty payload")
    if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
        raise FrameTooLargeError(
            f"payload of {len(payload)} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}"
        )
    return name.decode("ascii"), payload


@dataclass
class UdpRadioStats:
    """What one radio has done so far (all counts of datagrams)."""

    sent: int = 0
    send_failures: int = 0  # the OS refused to send (no route, buffer full): a lost broadcast
    received: int = 0  # valid frames handed to the controller
    own_echoes: int = 0  # our own datagrams, looped back by the host, skipped
    malformed: int = 0  # not a frame: bad magic, version, sender or empty payload
    oversize: int = 0  # longer than MAX_DATAGRAM_BYTES, or a payload over MAX_RADIO_PAYLOAD_BYTES

    @property
    def dropped(self) -> int:
        return self.malformed + self.oversize


class UdpRadio:
    """A ``ports.Radio`` on a UDP multicast group or broadcast address.

    ``address`` is a multicast group (224.0.0.0/4: multicast mode) or a broadcast
    address such as 10.77.0.255 or 255.255.255.255 (broadcast mode). ``interface``
    picks the network interface, by IPv4 address (any OS) or, in multicast mode on
    Linux, by name (``wlan0``, a veth in a network namespace); None lets the routing
    table choose. Use it as a context manager, or call ``close``.
    """

    def __init__(
        self,
        name: str,
        *,
        address: str = DEFAULT_GROUP,
        port: int = DEFAULT_PORT,
        interface: str | None = None,
        ttl: int = 1,
        max_per_poll: int = DEFAULT_MAX_PER_POLL,
    ) -> None:
        sender_bytes(name)  # the rule receivers apply
        if not 1 <= port <= 65535:
            raise ValueError(f"port must be in 1..65535, got {port}")
        if not 1 <= ttl <= 255:
            raise ValueError(f"ttl must be in 1..255, got {ttl}")
        if max_per_poll < 1:
            raise ValueError(f"max_per_poll must be at least 1, got {max_per_poll}")
        try:
            destination = ipaddress.IPv4Address(address)
        except ValueError:
            raise ValueError(f"address {address!r} is not an IPv4 address") from None
        self.name = name
        self.address = str(destination)
        self.port = port
        self.multicast = destination.is_multicast
        self._max_per_poll = max_per_poll
        self._stats = UdpRadioStats()
        self._logged_sources: set[tuple[str, int]] = set()
        self._send_failure_logged = False
        interface_address, interface_index = _resolve_interface(interface, self.multicast)

        self._rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._open_receiver(interface_address, interface_index)
            self._open_sender(interface_address, interface_index, ttl)
        except OSError as error:
            self.close()
            hint = ""
            if interface is None and self.multicast:
                hint = " (no route to it? give the interface, or add a route for 224.0.0.0/4)"
            raise OSError(
                error.errno,
                f"cannot open a UDP radio on {self.address}:{port} (interface "
                f"{interface or 'from the routing table'}): {error.strerror or error}{hint}",
            ) from None
        # Our own datagrams come back from exactly this address and port.
        self._own_source: tuple[str, int] = self._tx.getsockname()

    def _open_receiver(self, interface_address: str, interface_index: int) -> None:
        rx = self._rx
        # Several radios (robots, the beacon) may share one host or network namespace.
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        # A smaller buffer only loses more of a burst, as a radio would.
        with contextlib.suppress(OSError):
            rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        if self.multicast:
            # Bound to the group, the socket sees this group's datagrams and no others.
            try:
                rx.bind((self.address, self.port))
            except OSError:
                rx.bind(("", self.port))  # systems that cannot bind a group address
            rx.setsockopt(
                socket.IPPROTO_IP,
                socket.IP_ADD_MEMBERSHIP,
                _membership(self.address, interface_address, interface_index),
            )
        else:
            rx.bind(("", self.port))
        rx.setblocking(False)

    def _open_sender(self, interface_address: str, interface_index: int, ttl: int) -> None:
        tx = self._tx
        if self.multicast:
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, ttl)
            # Loopback stays on: other radios on this host must hear us too.
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            if interface_index:
                tx.setsockopt(
                    socket.IPPROTO_IP,
                    socket.IP_MULTICAST_IF,
                    _membership("0.0.0.0", "0.0.0.0", interface_index),
                )
            elif interface_address != "0.0.0.0":
                tx.setsockopt(
                    socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(interface_address)
                )
        else:
            tx.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_TTL, ttl)
        tx.bind((interface_address, 0))
        # Connecting fixes the source address (and fails now, not at the first send, when
        # there is no route to the destination).
        tx.connect((self.address, self.port))
        tx.setblocking(False)

    # --- the Radio port ------------------------------------------------------------

    def send(self, payload: bytes) -> None:
        """Broadcast one payload.

        A payload over 2048 bytes raises FrameTooLargeError (a ValueError): the caller's
        bug. A datagram the OS will not send (link down, buffer full) is counted in
        ``stats.send_failures`` and logged once, as radios lose messages.
        """
        datagram = encode_frame(self.name, payload)
        try:
            self._tx.send(datagram)
        except OSError as error:
            self._stats.send_failures += 1
            if not self._send_failure_logged:
                self._send_failure_logged = True
                log.warning(
                    "UDP radio %s could not send to %s:%d: %s (further failures not logged)",
                    self.name,
                    self.address,
                    self.port,
                    error,
                )
            return
        self._stats.sent += 1

    def poll(self) -> list[tuple[str, bytes]]:
        """Every valid frame received since the last poll, in arrival order; never blocks."""
        received: list[tuple[str, bytes]] = []
        stats = self._stats
        for _ in range(self._max_per_poll):
            try:
                # One byte more than the limit, so an oversize datagram shows as such
                # instead of arriving silently truncated.
                datagram, source = self._rx.recvfrom(MAX_DATAGRAM_BYTES + 1)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as error:
                # E.g. an ICMP error queued on the socket: nothing to read this time.
                log.debug("UDP radio %s: receive error %s", self.name, error)
                break
            if source == self._own_source:
                stats.own_echoes += 1
                continue
            try:
                received.append(decode_frame(datagram))
            except FrameTooLargeError as error:
                stats.oversize += 1
                self._log_bad(source, error)
            except FrameError as error:
                stats.malformed += 1
                self._log_bad(source, error)
        stats.received += len(received)
        return received

    # --- the rest ------------------------------------------------------------------

    @property
    def stats(self) -> UdpRadioStats:
        """A copy of the counts so far."""
        return replace(self._stats)

    @property
    def local_address(self) -> tuple[str, int]:
        """The (address, port) this radio's datagrams come from."""
        return self._own_source

    def fileno(self) -> int:
        """The receiving socket, for ``select``/``selectors`` in an event loop."""
        return self._rx.fileno()

    def close(self) -> None:
        self._rx.close()
        self._tx.close()

    def __enter__(self) -> UdpRadio:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def _log_bad(self, source: tuple[str, int], error: FrameError) -> None:
        if source in self._logged_sources or len(self._logged_sources) >= _MAX_LOGGED_SOURCES:
            return
        self._logged_sources.add(source)
        log.warning(
            "UDP radio %s dropped a bad datagram from %s:%d: %s (further ones not logged)",
            self.name,
            source[0],
            source[1],
            error,
        )


def _resolve_interface(interface: str | None, multicast: bool) -> tuple[str, int]:
    """``(IPv4 address, interface index)`` of the interface option; 0.0.0.0 / 0 = any."""
    if interface is None:
        return "0.0.0.0", 0
    try:
        return str(ipaddress.IPv4Address(interface)), 0
    except ValueError:
        pass
    if not multicast:
        raise ValueError(
            f"interface {interface!r}: in broadcast mode give the interface's IPv4 address"
        )
    if not sys.platform.startswith("linux"):
        raise ValueError(
            f"interface {interface!r}: names need Linux; give the interface's IPv4 address"
        )
    try:
        return "0.0.0.0", socket.if_nametoindex(interface)
    except OSError:
        raise ValueError(f"no network interface named {interface!r}") from None


def _membership(group: str, interface_address: str, interface_index: int) -> bytes:
    """``struct ip_mreqn`` (Linux) when an interface index is given, else ``ip_mreq``."""
    if interface_index:
        return struct.pack(
            "=4s4si",
            socket.inet_aton(group),
            socket.inet_aton(interface_address),
            interface_index,
        )
    return socket.inet_aton(group) + socket.inet_aton(interface_address)


__all__ = [
    "DEFAULT_GROUP",
    "DEFAULT_PORT",
    "MAX_DATAGRAM_BYTES",
    "MAX_RADIO_PAYLOAD_BYTES",
    "FrameError",
    "FrameTooLargeError",
    "UdpRadio",
    "UdpRadioStats",
    "decode_frame",
    "encode_frame",
    "sender_bytes",
]
