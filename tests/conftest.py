"""Hypothesis profiles, and the fast tier's marker and guard.

``make test`` (and CI) use ``repeatable``: examples are derived from each test's own
source, so the same commit passes or fails the same way every time. ``make explore``
(``HYPOTHESIS_PROFILE=explore``) draws fresh random examples (500 per test that sets no
count of its own) to hunt for new edge cases; pin any it finds as a regression test.

The tests in ``tiers.PUBLISHED`` run published runs again: they run with ``--published``
(``make check-published``), and only they; ``make test`` leaves them out.

Every test of a module in ``tiers.FAST`` but those in ``tiers.SLOW`` is marked ``fast``
(``make test-fast`` runs ``pytest -m fast``), and while it runs, starting a process, using
the network or opening a Zenoh session fails it: a module that does belongs in
``tiers.FULL_ONLY``. What a library makes once per machine by starting a process (its
caches, ``warm_caches``) is made before the first fast test, outside the guard, so that the
first run on a new machine, or with an empty HOME, passes as every later one does.
"""

from __future__ import annotations

import functools
import multiprocessing.process
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh
from hypothesis import settings
from tiers import is_fast, is_published

from bestofn_swarm.plumbing import cores

# No per-example deadline in either: timing varies on a loaded CI machine.
settings.register_profile("repeatable", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("explore", max_examples=500, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


class FastTierError(AssertionError):
    """A test of the fast tier started a process, used the network or opened Zenoh."""


def pytest_sessionstart(session: pytest.Session) -> None:
    """Stale compiled cores never run: their source does (cores_state.use_source_if_stale,
    which the packages' first import calls); the tests then test the source."""
    cores.check()


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--published",
        action="store_true",
        help="run only the checks of published runs (tests/tiers.py PUBLISHED)",
    )


# The modules with the longest runs, longest first. pytest-xdist hands modules to its
# workers in the order they are collected (``--dist loadfile``), so the long ones go first
# and the short ones fill in at the end: the workers finish together.
LONGEST_FIRST = (
    "test_outside",
    "test_viewer",
    "test_attacks",
    "test_faults",
    "test_attacks_presence",
    "test_swarm",
    "test_endings",
    "test_multihost",
    "test_conformance",
    "test_notebook",
    "test_hosts",
    "test_plugin_runs",
    "test_private_runs",
    "test_study_runner",
    "test_experiment",
    "test_fault_plugins",
    "test_recording",
    "test_compiled_cores",
    "test_flood_memory",
    "test_secure",
    "test_report",
    "test_portable_runs",
)


def _collection_rank(item: pytest.Item) -> int:
    module = item.path.stem
    return LONGEST_FIRST.index(module) if module in LONGEST_FIRST else len(LONGEST_FIRST)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=_collection_rank)  # stable: a module's tests keep their order
    published_only = bool(config.getoption("--published"))
    kept: list[pytest.Item] = []
    left_out: list[pytest.Item] = []
    for item in items:
        module, test = item.path.stem, getattr(item, "originalname", item.name)
        if is_fast(module, test):
            item.add_marker(pytest.mark.fast)
        (kept if is_published(module, test) == published_only else left_out).append(item)
    if left_out:
        config.hook.pytest_deselected(items=left_out)
        items[:] = kept


@functools.cache
def warm_caches() -> None:
    """Make what a library makes on first use by starting a process, as the first run on
    a machine would: matplotlib's font list, which it builds by asking fontconfig
    (``fc-list``) when its cache (in MPLCONFIGDIR, by default under XDG_CACHE_HOME or
    HOME) has none, and reads from that cache on every later run."""
    import matplotlib.font_manager  # noqa: F401  (importing it loads or builds the list)


@pytest.fixture(autouse=True)
def _fast_tests_start_nothing(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch
) -> Iterator[None]:
    if request.node.get_closest_marker("fast") is not None:
        warm_caches()
        refuse_processes_and_networks(monkeypatch, request.node.nodeid)
    yield


def refuse_processes_and_networks(monkeypatch: pytest.MonkeyPatch, test: str) -> None:
    """Until ``monkeypatch`` undoes it: every way the tests start a process, connect, listen
    or send on a socket, or open a Zenoh session raises ``FastTierError`` naming ``test``."""

    def refuse(what: str) -> Any:
        def refused(*args: Any, **kwargs: Any) -> Any:
            raise FastTierError(
                f"{test} is in the fast tier (tests/tiers.py FAST) but {what}: "
                "move its module to FULL_ONLY"
            )

        return refused

    monkeypatch.setattr(subprocess.Popen, "__init__", refuse("started a process"))
    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", refuse("started a process"))
    for name in ("fork", "system", "posix_spawn", "posix_spawnp"):
        monkeypatch.setattr(os, name, refuse("started a process"))
    monkeypatch.setattr(zenoh, "open", refuse("opened a Zenoh session"))
    # Making a socket is allowed (a launcher's plan asks the system for a free port by
    # binding one); talking over it is not.
    for name in ("connect", "connect_ex", "listen", "sendto", "sendmsg"):
        monkeypatch.setattr(socket.socket, name, refuse("used the network"))


@pytest.fixture
def short_tmp() -> Iterator[Path]:
    """A folder of this test's under /tmp, with a short path, for a run's temporary files
    (TMPDIR): a run's Unix socket lives there, and a socket's path holds at most 108 bytes,
    which pytest's own tmp_path (deeper still under a worker) can exceed. Removed after."""
    folder = Path(tempfile.mkdtemp(prefix="bt-", dir="/tmp"))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)
