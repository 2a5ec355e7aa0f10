"""The test tiers (tests/tiers.py) cannot go stale: every test module is in exactly one,
a fast module imports nothing that starts processes or talks to a network, and the guard
that fails a fast test doing either at run time works."""

from __future__ import annotations

import ast
import multiprocessing
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh
from conftest import FastTierError
from tiers import FAST, FAST_TESTS, FULL_ONLY, PUBLISHED, SLOW, is_fast, is_published

TESTS = Path(__file__).resolve().parent
# What a fast module (or a local helper it imports) may not import: these start processes,
# use the network or open Zenoh sessions, or are the helpers that do (swarm_helpers starts
# swarms).
FORBIDDEN = (
    "zenoh",
    "subprocess",
    "multiprocessing",
    "concurrent.futures",
    "socket",
    "signal",
    "swarm_helpers",
    "netns",
    "browser",
    "deploy.launcher.processes",
    "bestofn_swarm.plumbing.zenoh_session",
)
# This module imports some of them to show that the guard refuses them.
GUARD_TEST = "test_tiers"


def _test_modules() -> set[str]:
    return {path.stem for path in TESTS.glob("test_*.py")}


def _imports(module: str) -> set[str]:
    """The modules ``tests/<module>.py`` imports (any depth in the file)."""
    tree = ast.parse((TESTS / f"{module}.py").read_text())
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _reachable_imports(module: str) -> dict[str, set[str]]:
    """``module`` and the local helpers (tests/*.py) it imports, directly or through each
    other: what each of them imports."""
    found: dict[str, set[str]] = {}
    pending = [module]
    while pending:
        current = pending.pop()
        if current in found:
            continue
        found[current] = _imports(current)
        pending += [name for name in found[current] if (TESTS / f"{name}.py").exists()]
    return found


def _forbidden(name: str) -> bool:
    return any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN)


def test_every_test_module_is_in_exactly_one_tier() -> None:
    modules = _test_modules()
    assert sorted(modules - FAST - FULL_ONLY.keys()) == [], "add them to tests/tiers.py"
    assert sorted(FAST & FULL_ONLY.keys()) == []
    assert sorted((FAST | FULL_ONLY.keys()) - modules) == [], "no such test modules"
    assert all(reason.strip() for reason in FULL_ONLY.values())


@pytest.mark.parametrize("module", sorted(FAST - {GUARD_TEST}))
def test_a_fast_module_imports_nothing_that_starts_processes_or_networks(module: str) -> None:
    offending = {
        f"{source}.py imports {name}"
        for source, names in _reachable_imports(module).items()
        for name in names
        if _forbidden(name)
    }
    assert sorted(offending) == []


def test_the_import_check_sees_a_helper_that_starts_swarms() -> None:
    """test_section5 is not fast: the check would say why (its helper, its runs)."""
    imports = _reachable_imports("test_section5")
    assert "swarm_helpers" in imports
    assert any(_forbidden(name) for names in imports.values() for name in names)


def test_every_slow_test_is_a_test_of_a_fast_module() -> None:
    for test, reason in SLOW.items():
        module, _, function = test.partition("::")
        assert module in FAST, test
        tree = ast.parse((TESTS / f"{module}.py").read_text())
        functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert function in functions, f"{test}: no such test"
        assert reason.strip()


def test_a_slow_test_is_not_fast_and_its_neighbours_are() -> None:
    for test in SLOW:
        module, _, function = test.partition("::")
        assert not is_fast(module, function)
    assert is_fast("test_controller", "test_same_seed_same_decisions_other_seed_other_decisions")
    assert not is_fast(
        "test_swarm", "test_a_small_swarm_reaches_the_right_consensus_and_leaves_nothing_behind"
    )


def test_every_fast_test_of_a_full_module_is_there() -> None:
    """FAST_TESTS names tests of FULL_ONLY modules only (a FAST module's are fast anyway),
    and each is a test function of its module."""
    for test in FAST_TESTS:
        module, _, function = test.partition("::")
        assert module in FULL_ONLY, test
        tree = ast.parse((TESTS / f"{module}.py").read_text())
        functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert function in functions, f"{test}: no such test"
        assert is_fast(module, function)


def test_every_published_check_is_a_test_that_is_there() -> None:
    for test, reason in PUBLISHED.items():
        module, _, function = test.partition("::")
        tree = ast.parse((TESTS / f"{module}.py").read_text())
        functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
        assert function in functions, f"{test}: no such test"
        assert reason.strip() and is_published(module, function)
        assert not is_fast(module, function), f"{test}: a published check is not fast"


def test_make_test_leaves_the_published_checks_out(request: pytest.FixtureRequest) -> None:
    """Without --published the session holds no published check; with it, only they."""
    held = {
        f"{item.path.stem}::{getattr(item, 'originalname', item.name)}"
        for item in request.session.items
    }
    assert request.config.getoption("--published") is False
    assert held.isdisjoint(PUBLISHED)


def test_this_module_is_fast_and_so_guarded(request: pytest.FixtureRequest) -> None:
    assert GUARD_TEST in FAST
    assert request.node.get_closest_marker("fast") is not None


def test_a_fast_test_cannot_start_a_process() -> None:
    with pytest.raises(FastTierError, match=r"test_tiers\.py.*started a process"):
        subprocess.run([sys.executable, "-c", "pass"], check=False)
    with pytest.raises(FastTierError, match="started a process"):
        multiprocessing.get_context("spawn").Process(target=print).start()
    with pytest.raises(FastTierError, match="started a process"):
        os.system("true")


def test_a_fast_test_cannot_use_the_network_or_open_a_zenoh_session() -> None:
    with pytest.raises(FastTierError, match="used the network"):
        socket.create_connection(("127.0.0.1", 9))
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))  # what a free-port finder does: allowed
        with pytest.raises(FastTierError, match="used the network"):
            server.listen()
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp,
        pytest.raises(FastTierError, match="used the network"),
    ):
        udp.sendto(b"x", ("127.0.0.1", 9))
    with pytest.raises(FastTierError, match="opened a Zenoh session"):
        zenoh.open(zenoh.Config())


def test_a_socket_pair_is_no_network() -> None:
    """Pairs of connected descriptors (asyncio's self-pipe) stay allowed."""
    first, second = socket.socketpair()
    with first, second:
        first.sendall(b"x")
        assert second.recv(1) == b"x"
