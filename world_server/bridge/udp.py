"""The bridge's UDP socket: one address for every robot it serves over UDP.

A datagram is one link frame (wire/link.py); the robot id in its header says whose link it
is, and the robot's link key, checked by its ``LinkPeer``, says whether it is true. The
socket listens on loopback unless ``swarm run --link`` names another address; it never
blocks, and takes at most ``MAX_DATAGRAMS_PER_RECEIVE`` datagrams per call so that a flood
cannot starve the rest of the loop.
"""

from __future__ import annotations

import socket
from collections.abc import Hashable
from typing import Any, cast

from wire import link

RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
MAX_DATAGRAMS_PER_RECEIVE = 512


class UdpServer:
    def __init__(self, host: str, port: int) -> None:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM, flags=socket.AI_PASSIVE)
        family, _, _, _, address = infos[0]
        self.socket = socket.socket(family, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        self.socket.bind(address)
        self.socket.setblocking(False)
        self.send_failures = 0

    @property
    def port(self) -> int:
        return int(self.socket.getsockname()[1])

    def fileno(self) -> int:
        return self.socket.fileno()

    def receive(self) -> list[tuple[bytes, Hashable]]:
        """The datagrams waiting, with where each came from."""
        found: list[tuple[bytes, Hashable]] = []
        for _ in range(MAX_DATAGRAMS_PER_RECEIVE):
            try:
                data, source = self.socket.recvfrom(link.MAX_FRAME_BYTES + 1)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # an ICMP error of an earlier send: nothing to read after all
                continue
            found.append((data, source))
        return found

    def send(self, frame: bytes, target: Hashable) -> None:
        try:
            self.socket.sendto(frame, cast(tuple[Any, ...], target))
        except OSError:  # a full buffer, or the robot's address gone: a lost datagram
            self.send_failures += 1

    def close(self) -> None:
        self.socket.close()
