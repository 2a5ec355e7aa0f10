"""The shared layers of bestofn-swarm: the wire vocabulary every process speaks (``wire``),
what every Zenoh process shares (``plumbing``) and what both ends of a hardware link share
(``link``); and the public Python API, ``from bestofn_swarm import run, sweep``
(``bestofn_swarm/api/``, imported when first asked for: the shared layers need none of it)."""

from typing import Any

# Stale compiled cores would run old code: their source runs instead (one warning line).
from bestofn_swarm.plumbing import cores_state as _cores_state

_cores_state.use_source_if_stale()

_API = ("RunResult", "run", "sweep")


def __getattr__(name: str) -> Any:
    """``run``, ``sweep`` and ``RunResult`` from ``bestofn_swarm.api``, on first use."""
    if name in _API:
        from bestofn_swarm import api

        return getattr(api, name)
    raise AttributeError(f"module 'bestofn_swarm' has no attribute {name!r}")


__all__ = list(_API)
