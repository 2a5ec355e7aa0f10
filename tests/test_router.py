"""`swarm router`: a Python Zenoh router that carries traffic between clients."""

from __future__ import annotations

import signal
import subprocess
import time

import pytest
from swarm_helpers import REPO, swarm_command

from bestofn_swarm.plumbing.tcp import free_port, wait_for_port
from bestofn_swarm.plumbing.zenoh_session import open_session

pytestmark = pytest.mark.timeout(60)


def test_the_router_carries_messages_between_clients_and_stops_cleanly() -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen(
        swarm_command("router", "--listen", endpoint), cwd=REPO, stderr=subprocess.PIPE
    )
    try:
        assert wait_for_port(port, 30.0, lambda: router.poll() is None)
        received: list[bytes] = []
        with (
            open_session("client", [endpoint]) as listener,
            open_session("client", [endpoint]) as talker,
        ):
            listener.declare_subscriber("demo/**", lambda s: received.append(s.payload.to_bytes()))
            deadline = time.monotonic() + 10
            while not received and time.monotonic() < deadline:
                talker.put("demo/hello", b"through the router")
                time.sleep(0.1)
        router.send_signal(signal.SIGTERM)
        _, errors = router.communicate(timeout=10)
    finally:
        if router.poll() is None:
            router.kill()
            router.wait()
    assert received and received[0] == b"through the router"
    assert router.returncode == 0, errors.decode()
    assert b"router stopped" in errors


def test_a_bad_endpoint_is_a_usage_error() -> None:
    done = subprocess.run(
        swarm_command("router", "--listen", "nonsense"),
        capture_output=True,
        timeout=30,
        cwd=REPO,
    )
    assert done.returncode == 2
    assert "invalid Zenoh endpoint" in done.stderr.decode()
