"""Test hosts as Linux network namespaces on one bridge (root only; skipped elsewhere)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest

UDP_SUBNET = "10.77.0"


def netns_unavailable() -> str | None:
    """Why network namespaces cannot be used here, or None."""
    if not sys.platform.startswith("linux"):
        return "network namespaces need Linux"
    if os.geteuid() != 0:
        return f"creating network namespaces needs root (running as uid {os.geteuid()})"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on PATH"
    probe = subprocess.run(
        ["ip", "netns", "list"], capture_output=True, text=True, timeout=10, check=False
    )
    if probe.returncode != 0:
        return f"`ip netns` does not work here: {probe.stderr.strip()}"
    return None


def lan_address(index: int, subnet: str = UDP_SUBNET) -> str:
    return f"{subnet}.{10 + index}"


@dataclass
class Lan:
    """Host namespaces, each with an ``eth0`` (a veth) on a bridge in a hub namespace:
    <subnet>.10, .11, ... /24, with a multicast route on eth0. Addresses stay inside
    the namespaces this creates."""

    prefix: str
    size: int
    subnet: str = UDP_SUBNET
    created: list[str] = field(default_factory=list)

    @property
    def hub(self) -> str:
        return f"{self.prefix}h"

    def robot_ns(self, index: int) -> str:
        return f"{self.prefix}r{index}"

    def address(self, index: int) -> str:
        return lan_address(index, self.subnet)

    def _ip(self, *args: str) -> None:
        subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)

    def _add_namespace(self, name: str) -> None:
        self._ip("netns", "add", name)
        self.created.append(name)

    def create(self) -> None:
        self._add_namespace(self.hub)
        # Snooping off: with no IGMP querier on this LAN the bridge simply floods multicast.
        self._ip("-n", self.hub, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
        self._ip("-n", self.hub, "link", "set", "br0", "up")
        for index in range(self.size):
            ns = self.robot_ns(index)
            self._add_namespace(ns)
            port = f"veth{index}"
            self._ip(
                "-n",
                self.hub,
                "link",
                "add",
                port,
                "type",
                "veth",
                "peer",
                "name",
                "eth0",
                "netns",
                ns,
            )
            self._ip("-n", self.hub, "link", "set", port, "master", "br0", "up")
            self._ip(
                "-n", ns, "addr", "add", f"{self.address(index)}/24", "brd", "+", "dev", "eth0"
            )
            self._ip("-n", ns, "link", "set", "eth0", "up")
            self._ip("-n", ns, "link", "set", "lo", "up")
            self._ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")

    def destroy(self) -> list[str]:
        """Delete every namespace created (their veths go with them); the ones left."""
        for name in reversed(self.created):
            subprocess.run(
                ["ip", "netns", "del", name], capture_output=True, timeout=10, check=False
            )
        listing = subprocess.run(
            ["ip", "netns", "list"], capture_output=True, text=True, timeout=10, check=False
        ).stdout.split()
        return [name for name in self.created if name in listing]

    def run(self, index: int, *command: str) -> list[str]:
        return ["ip", "netns", "exec", self.robot_ns(index), *command]


@contextlib.contextmanager
def namespaces(prefix: str, size: int, subnet: str) -> Iterator[Lan]:
    """A Lan for the duration of a test (skipped where namespaces cannot be made), and a
    check afterwards that every namespace it made is gone."""
    reason = netns_unavailable()
    if reason is not None:
        pytest.skip(reason)
    network = Lan(prefix=f"{prefix}{os.getpid()}", size=size, subnet=subnet)
    try:
        try:
            network.create()
        except subprocess.CalledProcessError as error:
            # `ip netns list` worked but making namespaces or veths does not (a container
            # without CAP_SYS_ADMIN, say): the machine cannot host these tests.
            reason = (error.stderr or b"").decode(errors="replace").strip()
            pytest.skip(f"cannot build test hosts here: {' '.join(error.cmd)}: {reason}")
        yield network
    finally:
        left = network.destroy()
        assert not left, f"network namespaces left behind: {left}"
