"""What a recording misses: messages recorded against messages their publishers declared or
must have sent."""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Sequence

from bestofn_swarm.wire import keyspace
from deploy.reports.collect import Recording, TickSpan


def audit(recording: Recording) -> dict[str, dict[str, int]]:
    """Messages recorded against messages their publishers declared or must have sent.

    ``expected`` comes from the recording itself: each tick's Sense says how many radio
    deliveries and camera frames the world published for it; each Act and Ack says how many
    radio messages its controller sent; clock, sense and act ticks must be contiguous, and
    each ack must be followed by one at the tick it named (``Ack.next_tick``);
    a robot's trip and pooling counters step by one per status update.
    """
    counts = recording.messages
    declared = recording.declared

    def spans(found: dict[int, TickSpan]) -> dict[str, int]:
        return {
            "expected": sum(span.expected for span in found.values()),
            "recorded": sum(span.count for span in found.values()),
        }

    status = counts[keyspace.STATUS.name]
    found = {
        keyspace.CLOCK: {"expected": recording.clock.expected, "recorded": recording.clock.count},
        keyspace.STATE: {
            "expected": _states_expected(recording.state_ticks),
            "recorded": len(recording.state_ticks),
        },
        keyspace.SENSE: spans(recording.sense),
        keyspace.ACT: spans(recording.act),
        keyspace.ACK: {"expected": recording.ack.expected, "recorded": recording.ack.count},
        keyspace.CAMERA: {"expected": declared.camera, "recorded": counts[keyspace.CAMERA.name]},
        keyspace.RADIO_TX: {"expected": declared.tx, "recorded": counts[keyspace.RADIO_TX.name]},
        keyspace.RADIO_RX: {"expected": declared.rx, "recorded": counts[keyspace.RADIO_RX.name]},
        keyspace.STATUS: {"expected": status + declared.status_gaps, "recorded": status},
    }
    return {kind.label: entry for kind, entry in found.items()}


def _states_expected(ticks: Sequence[int]) -> int:
    """World states due from the first to the last recorded: one every ``state_every``
    ticks (the most common step) and any off that grid (the world's last state, published
    when it stops), which the recording holds by definition."""
    if not ticks:
        return 0
    steps = Counter(b - a for a, b in itertools.pairwise(ticks) if b > a)
    step = steps.most_common(1)[0][0] if steps else 1
    on_grid = [tick for tick in ticks if (tick - ticks[0]) % step == 0]
    return (max(on_grid) - ticks[0]) // step + 1 + len(ticks) - len(on_grid)


def missing_messages(recording: Recording) -> int:
    """How many messages ``audit`` finds missing from the file, of every kind together."""
    return sum(max(0, entry["expected"] - entry["recorded"]) for entry in audit(recording).values())
