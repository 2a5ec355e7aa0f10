"""Stop signals as events: SIGINT, SIGTERM and SIGHUP end a run in order, like Ctrl-C
always did, instead of killing ``swarm run`` where it stands.

The handler only notes the first signal; ``bestofn_swarm.plumbing.stop_signals.StopSignals`` passes
it on from a thread of its own (to the launcher's event inbox, which takes locks). Nothing is
raised into the interrupted code: the main loop sees the signal at its next look and ends
the run in order. Later signals change nothing: the ending is bounded in time (processes
get a grace period, then SIGKILL), and cutting it short would lose the summary and the
recording's end. SIGKILL needs no handler: every child dies with the launcher
(bestofn_swarm/plumbing/lifecycle.py).
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from dataclasses import dataclass

from bestofn_swarm.plumbing import stop_signals
from bestofn_swarm.wire.endings import StopSignal

# The handled signals, in the order wire.endings lists them (SIGINT, SIGTERM, SIGHUP).
STOP_SIGNALS = tuple(signal.Signals(stop) for stop in StopSignal)


@dataclass(frozen=True)
class Signalled:
    """A stop signal, as an event in the launcher's inbox."""

    signum: int


class StopSignals(stop_signals.StopSignals):
    """The launcher's stop signals (SIGHUP too: a closed terminal ends a run in order)."""

    def __init__(self, notify: Callable[[int], None] | None = None) -> None:
        super().__init__(notify, STOP_SIGNALS)
