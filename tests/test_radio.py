"""The radio medium: range, delivery order and timing, the fault model, determinism."""

from __future__ import annotations

import math
import random
from collections import Counter
from collections.abc import Mapping
from typing import Any

import pytest

from bestofn_swarm.wire import names, protocol
from world_server.core.radio import Delivery, RadioConfig, RadioMedium, SenderKind, sender_order

pytestmark = pytest.mark.timeout(60)

Positions = Mapping[str, tuple[float, float]]


def ring(count: int, radius: float, prefix: int = 100) -> dict[str, tuple[float, float]]:
    """``count`` robot receivers evenly spread on a circle around the origin."""
    return {
        str(prefix + k): (
            radius * math.cos(2 * math.pi * k / count),
            radius * math.sin(2 * math.pi * k / count),
        )
        for k in range(count)
    }


def broadcast(
    medium: RadioMedium,
    ticks: int,
    receivers: Positions,
    *,
    sender: str = "0",
    kind: SenderKind = "robot",
    deliver: bool = True,
) -> list[tuple[int, Delivery]]:
    """``sender`` at the origin sends one message a tick; every (tick, delivery) returned.

    With ``deliver``, deliveries are collected each tick and the medium drained after.
    """
    everyone = {**receivers, sender: (0.0, 0.0)}
    received = []
    for tick in range(ticks):
        medium.transmit(tick, sender, tick, b"m%d" % tick, (0.0, 0.0), kind, everyone)
        if deliver:
            received += [(tick, delivery) for delivery in medium.deliveries(tick)]
    return received + drain(medium, ticks) if deliver else received


def drain(medium: RadioMedium, start: int, ticks: int = 50) -> list[tuple[int, Delivery]]:
    """Collect deliveries tick by tick from ``start`` for ``ticks`` ticks."""
    return [(tick, d) for tick in range(start, start + ticks) for d in medium.deliveries(tick)]


def loss_runs(lost: list[bool]) -> list[int]:
    """Lengths of the runs of consecutive losses."""
    runs, current = [], 0
    for flag in lost:
        if flag:
            current += 1
        elif current:
            runs.append(current)
            current = 0
    return runs + ([current] if current else [])


# --- range, self, timing, order ------------------------------------------------------


def test_range_depends_on_the_sender_kind() -> None:
    medium = RadioMedium(RadioConfig(robot_range=0.5, beacon_range=0.2), seed=1)
    positions = {
        "1": (0.19, 0.0),
        "2": (0.0, 0.21),
        "3": (-0.49, 0.0),
        "4": (0.0, -0.51),
        "0": (0.0, 0.0),
        "nest": (0.0, 0.0),
    }
    medium.transmit(0, "0", 0, b"robot", (0.0, 0.0), "robot", positions)
    medium.transmit(0, "nest", 0, b"beacon", (0.0, 0.0), "beacon", positions)
    got = {(d.sender, d.receiver) for d in medium.deliveries(1)}
    assert got == {("0", "1"), ("0", "2"), ("0", "3"), ("0", "nest"), ("nest", "0"), ("nest", "1")}


def test_a_sender_never_hears_itself() -> None:
    medium = RadioMedium(RadioConfig(), seed=1)
    positions = {"4": (0.0, 0.0), "5": (0.1, 0.0)}
    medium.transmit(0, "4", 0, b"x", (0.0, 0.0), "robot", positions)
    assert [(d.receiver, d.sender, d.payload) for d in medium.deliveries(1)] == [("5", "4", b"x")]


def test_next_tick_by_default_and_latency_adds_whole_ticks() -> None:
    for latency in (0, 3):
        medium = RadioMedium(RadioConfig(latency=latency), seed=1)
        medium.transmit(7, "1", 42, b"x", (0.0, 0.0), "robot", {"2": (0.1, 0.1)})
        arrivals = drain(medium, 7, 10)
        assert [tick for tick, _ in arrivals] == [7 + 1 + latency]
        assert arrivals[0][1] == Delivery("2", "1", 42, 7, b"x")


def test_deliveries_are_sorted_by_receiver_sender_and_seq_in_sender_order() -> None:
    assert sorted(["nest", "10", "2", "beacon", "0"], key=sender_order) == [
        "0",
        "2",
        "10",
        "beacon",
        "nest",
    ]
    assert RadioMedium.sender_order("10") == sender_order("10")
    positions = {"10": (0.0, 0.0), "2": (0.1, 0.0), "9": (0.0, 0.1), "nest": (0.1, 0.1)}
    medium = RadioMedium(RadioConfig(), seed=1)
    calls = sorted(
        [("2", 1), ("10", 0), ("2", 0), ("nest", 5), ("9", 3)],
        key=lambda call: (sender_order(call[0]), call[1]),
    )
    for sender, seq in calls:
        kind: SenderKind = "beacon" if sender == "nest" else "robot"
        medium.transmit(0, sender, seq, b"", positions[sender], kind, positions)
    got = [(d.receiver, d.sender, d.seq) for d in medium.deliveries(1)]
    assert got == sorted(got, key=lambda k: (sender_order(k[0]), sender_order(k[1]), k[2]))
    assert got[0] == ("2", "9", 3) and got[-1][0] == "nest"
    assert len(got) == 5 * 3  # everyone is in everyone's range: three copies a message


def test_invalid_calls_and_configs_are_refused() -> None:
    medium = RadioMedium(RadioConfig(), seed=1)
    with pytest.raises(ValueError):
        drone: Any = "drone"  # no such kind of sender
        medium.transmit(0, "1", 0, b"", (0.0, 0.0), drone, {})
    with pytest.raises(ValueError):
        medium.transmit(0, "1", 0, b"", (math.nan, 0.0), "robot", {})
    for bad in (
        {"drop": 1.5},
        {"latency": -1},
        {"jitter": 0.5},
        {"robot_range": 0.0},
        {"range_loss_start": math.nan},
        {"range_loss_exponent": 0.0},
    ):
        with pytest.raises(ValueError):
            RadioConfig(**bad)


# --- faults --------------------------------------------------------------------------


def test_iid_drop_rate_matches_the_probability() -> None:
    medium = RadioMedium(RadioConfig(drop=0.3), seed=11)
    receivers = ring(8, 0.3)
    received = broadcast(medium, 2500, receivers)
    copies = 2500 * len(receivers)
    rate = 1 - len(received) / copies
    assert rate == pytest.approx(0.3, abs=5 * math.sqrt(0.3 * 0.7 / copies))
    assert medium.dropped == copies - len(received)


def test_gilbert_elliott_losses_come_in_longer_runs_than_iid_at_the_same_rate() -> None:
    enter, leave = 0.05, 0.2  # stationary loss e / (e + x) = 0.2, bad spells 5 copies long
    bursty = RadioMedium(RadioConfig(burst_enter=enter, burst_exit=leave), seed=3)
    iid = RadioMedium(RadioConfig(drop=enter / (enter + leave)), seed=3)
    ticks = 20000
    patterns = []
    for medium in (bursty, iid):
        heard = {tick for tick, _ in broadcast(medium, ticks, {"1": (0.1, 0.0)})}
        patterns.append([tick - 1 not in heard for tick in range(1, ticks + 1)])
    for lost in patterns:
        assert sum(lost) / ticks == pytest.approx(0.2, abs=0.03)
    bursty_runs, iid_runs = (loss_runs(lost) for lost in patterns)
    assert sum(bursty_runs) / len(bursty_runs) == pytest.approx(1 / leave, rel=0.15)
    assert sum(iid_runs) / len(iid_runs) == pytest.approx(1 / (1 - 0.2), rel=0.1)


def test_gilbert_elliott_keeps_one_chain_per_directed_link() -> None:
    # Good state loses nothing, bad state everything, and a link never leaves bad:
    # once a link has gone bad it is silent forever, independently of the others.
    config = RadioConfig(burst_enter=0.02, burst_exit=0.0)
    medium = RadioMedium(config, seed=8)
    receivers = ring(6, 0.2)
    received = broadcast(medium, 400, receivers)
    last_heard = {}
    for tick, delivery in received:
        last_heard[delivery.receiver] = tick
    per_receiver = Counter(delivery.receiver for _, delivery in received)
    for receiver in receivers:
        # Heard without a gap until the link went bad, then never again.
        assert per_receiver[receiver] == last_heard.get(receiver, 0)
    assert len(set(per_receiver.values())) > 1  # the links went bad at different times


def test_duplicates_arrive_again_no_earlier_than_the_original() -> None:
    config = RadioConfig(duplicate=0.5, duplicate_delay=2)
    medium = RadioMedium(config, seed=4)
    receivers = ring(5, 0.2)
    received = broadcast(medium, 400, receivers)
    arrivals: dict[tuple[str, int], list[int]] = {}
    for tick, delivery in received:
        arrivals.setdefault((delivery.receiver, delivery.seq), []).append(tick)
    counts = Counter(len(ticks) for ticks in arrivals.values())
    assert set(counts) == {1, 2}
    assert counts[2] / len(arrivals) == pytest.approx(0.5, abs=0.05)
    lags = Counter(ticks[1] - ticks[0] for ticks in arrivals.values() if len(ticks) == 2)
    assert set(lags) == {0, 1, 2}
    for (_, seq), ticks in arrivals.items():
        assert ticks[0] == seq + 1  # the original keeps its time
    assert medium.copies == len(received) == medium.delivered


def test_jitter_spreads_arrivals_and_reorders_a_senders_messages() -> None:
    messages = 2000
    medium = RadioMedium(RadioConfig(latency=1, jitter=3), seed=5)
    received = broadcast(medium, messages, {"1": (0.1, 0.0)})
    delays = Counter(tick - delivery.sent_tick for tick, delivery in received)
    assert set(delays) == {2, 3, 4, 5}
    # Uniform over the four delays: each count within 5 standard deviations of its mean.
    assert all(
        abs(count - messages / 4) < 5 * math.sqrt(messages * 3 / 16) for count in delays.values()
    )
    sequence = [delivery.seq for _, delivery in received]
    assert sorted(sequence) == list(range(messages)) and sequence != list(range(messages))


def test_reorder_shuffles_a_tick_but_delivers_the_same_copies() -> None:
    receivers = ring(12, 0.3)
    lists = {}
    for reorder in (False, True):
        medium = RadioMedium(RadioConfig(drop=0.2, reorder=reorder), seed=6)
        everyone = {**receivers, "1": (0.0, 0.0), "2": (0.01, 0.0)}
        for seq in range(3):
            for sender in ("1", "2"):
                medium.transmit(0, sender, seq, b"", everyone[sender], "robot", everyone)
        lists[reorder] = [(d.receiver, d.sender, d.seq) for d in medium.deliveries(1)]
    assert sorted(lists[True]) == sorted(lists[False])  # reordering draws from its own stream
    assert lists[True] != lists[False]


def test_range_loss_follows_its_formula_and_rises_with_distance() -> None:
    config = RadioConfig(range_loss_start=0.5)
    assert [config.range_loss_probability(f * 0.5, 0.5) for f in (0.2, 0.5, 0.75, 1.0)] == [
        0.0,
        0.0,
        pytest.approx(0.5),
        1.0,
    ]
    curved = RadioConfig(range_loss_start=0.5, range_loss_exponent=2.0)
    assert curved.range_loss_probability(0.375, 0.5) == pytest.approx(0.25)

    fractions = (0.3, 0.55, 0.7, 0.85, 0.95)
    receivers = {str(k + 1): (f * 0.5, 0.0) for k, f in enumerate(fractions)}
    medium = RadioMedium(config, seed=7)
    ticks = 3000
    heard = Counter(d.receiver for _, d in broadcast(medium, ticks, receivers))
    rates = [1 - heard[str(k + 1)] / ticks for k in range(len(fractions))]
    assert rates[0] == 0.0
    assert rates == sorted(rates)
    for fraction, rate in zip(fractions, rates, strict=True):
        assert rate == pytest.approx(max(0.0, (fraction - 0.5) / 0.5), abs=0.04)


def test_enabling_one_fault_leaves_the_others_decisions_unchanged() -> None:
    receivers = ring(6, 0.2)

    def dropped_copies(config: RadioConfig) -> set[tuple[str, int]]:
        medium = RadioMedium(config, seed=12)
        received = broadcast(medium, 200, receivers, deliver=False)
        assert not received
        heard = {(d.receiver, d.seq) for _, d in drain(medium, 0, 230)}
        return {(r, seq) for r in receivers for seq in range(200)} - heard

    plain = dropped_copies(RadioConfig(drop=0.3))
    assert plain == dropped_copies(RadioConfig(drop=0.3, jitter=4, duplicate=0.2, reorder=True))


# --- determinism and counters --------------------------------------------------------

ALL_FAULTS = RadioConfig(
    drop=0.1,
    latency=1,
    jitter=2,
    duplicate=0.1,
    duplicate_delay=2,
    reorder=True,
    burst_enter=0.1,
    burst_exit=0.3,
    burst_loss_good=0.02,
    burst_loss_bad=0.7,
    range_loss_start=0.6,
)


def swarm_traffic(seed: int, config: RadioConfig = ALL_FAULTS, ticks: int = 60):
    """Forty robots and a beacon wander; a seeded fifth of the robots broadcast each tick."""
    rng = random.Random(99)
    medium = RadioMedium(config, seed)
    log = []
    for tick in range(ticks):
        positions = {
            names.robot_name(k): (rng.uniform(-1, 1), rng.uniform(-1, 1)) for k in range(40)
        }
        positions["beacon"] = (0.0, 0.0)
        senders = sorted(rng.sample(sorted(positions), 9), key=sender_order)
        for sender in senders:
            kind: SenderKind = "beacon" if sender == "beacon" else "robot"
            medium.transmit(tick, sender, tick, sender.encode(), positions[sender], kind, positions)
        log.append(medium.deliveries(tick))
        assert medium.copies == medium.delivered + medium.dropped + medium.in_flight
    return medium, log


def test_same_seed_same_deliveries_and_another_seed_differs() -> None:
    first, second, other = swarm_traffic(1)[1], swarm_traffic(1)[1], swarm_traffic(2)[1]
    assert first == second
    assert first != other


def test_counters_add_up() -> None:
    medium, log = swarm_traffic(3)
    assert medium.sent == 60 * 9
    assert medium.dropped > 0 and medium.in_flight > 0
    assert medium.delivered == sum(len(tick) for tick in log)
    assert medium.copies == medium.delivered + medium.dropped + medium.in_flight
    medium.reject()
    medium.reject(4)
    assert medium.counters == protocol.RadioCounters(
        sent=medium.sent, delivered=medium.delivered, dropped=medium.dropped, rejected=5
    )
    remaining = drain(medium, 60)
    assert medium.in_flight == 0
    assert medium.copies == medium.delivered + medium.dropped
    assert len(remaining) > 0


def test_messages_without_anyone_in_range_still_count_as_sent() -> None:
    medium = RadioMedium(RadioConfig(), seed=1)
    medium.transmit(0, "1", 0, b"", (0.0, 0.0), "robot", {"1": (0.0, 0.0), "2": (2.0, 0.0)})
    assert medium.deliveries(1) == []
    assert medium.counters == protocol.RadioCounters(sent=1)


def test_positions_are_those_of_the_sending_tick_even_in_a_reused_mapping() -> None:
    medium = RadioMedium(RadioConfig(), seed=1)
    positions = {"1": (0.0, 0.0), "2": (0.1, 0.0)}
    medium.transmit(0, "1", 0, b"near", (0.0, 0.0), "robot", positions)
    positions["2"] = (2.0, 0.0)  # the world updates its mapping in place for tick 1
    medium.transmit(1, "1", 1, b"far", (0.0, 0.0), "robot", positions)
    medium.transmit(1, "1", 2, b"", (0.0, 0.0), "robot", {})  # nobody listening at all
    assert [d.payload for d in medium.deliveries(1) + medium.deliveries(2)] == [b"near"]
    assert medium.sent == 3
