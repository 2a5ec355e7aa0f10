"""What the compiled cores (``bestofn_swarm/plumbing/cores.py``) need said in the source: mypyc's
class attributes. Where mypy is not installed nothing is compiled, and the decorator does
nothing."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__all__ = ["mypyc_attr"]

if TYPE_CHECKING:
    from mypy_extensions import mypyc_attr
else:
    try:
        from mypy_extensions import mypyc_attr
    except ImportError:  # without the `cores` extra: the source runs as it is

        def mypyc_attr(*_args: Any, **_kwargs: Any) -> Any:
            return lambda cls: cls
