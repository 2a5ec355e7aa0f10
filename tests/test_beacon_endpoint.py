"""The nest beacon's end of the wire without Zenoh (nest_beacon/core/endpoint.py): which
clocks it answers, what it refuses and counts, and what it sends."""

from __future__ import annotations

import pytest

from bestofn_swarm.wire import auth, guard, keyspace, names, protocol
from bestofn_swarm.wire.rng import Stream
from nest_beacon.core.beacon import Beacon, BeaconConfig
from nest_beacon.core.endpoint import BeaconEndpoint, Outgoing

SECRET = bytes(range(32))
KEYS = keyspace.Keys("beacon")
RUN_KEYS = auth.Keyring(secret=SECRET)  # the world's and the beacon's keys derive from it
DT = 0.1
IDENTITY = names.beacon_identity("nest")


def beacon(keyed: bool = True) -> BeaconEndpoint:
    config = BeaconConfig(period=0.5)  # every five ticks
    keyring = RUN_KEYS.only([IDENTITY, names.WORLD]) if keyed else None
    return BeaconEndpoint(Beacon(config, Stream(0)), KEYS, DT, keyring)


def clock(
    tick: int, *, keyring: auth.Keyring | None = RUN_KEYS, t: float | None = None
) -> tuple[bytes, bytes | None]:
    payload = protocol.encode(protocol.Clock(v=1, tick=tick, t=tick * DT if t is None else t))
    return payload, auth.seal(keyring, names.WORLD, KEYS.of(keyspace.BEACON_CLOCK, "nest"), payload)


def ack(message: Outgoing) -> protocol.Ack:
    assert message.kind is keyspace.ACK and message.key == KEYS.of(keyspace.ACK, "nest")
    return protocol.decode(message.payload, protocol.Ack)


def test_each_tick_is_answered_and_a_transmission_sent_when_due() -> None:
    endpoint = beacon()
    answers = [endpoint.receive_clock(*clock(tick)) for tick in range(7)]
    assert [[message.kind for message in answer] for answer in answers] == [
        [keyspace.RADIO_TX, keyspace.ACK],
        *[[keyspace.ACK]] * 4,
        [keyspace.RADIO_TX, keyspace.ACK],
        [keyspace.ACK],
    ]
    assert [(ack(answer[-1]).tick, ack(answer[-1]).radio_tx) for answer in answers] == [
        (tick, 1 if tick in (0, 5) else 0) for tick in range(7)
    ]
    # Each ack names the next tick with a transmission due: the world skips those between.
    assert [ack(answer[-1]).next_tick for answer in answers] == [5, 5, 5, 5, 5, 10, 10]
    sent = answers[5][0]
    assert sent.key == KEYS.of(keyspace.RADIO_TX, "nest")
    assert protocol.decode(sent.payload, protocol.BeaconPayload).seq == 2


def test_what_the_beacon_sends_is_sealed_with_its_own_key() -> None:
    endpoint = beacon()
    for message in endpoint.receive_clock(*clock(0)):
        metadata = RUN_KEYS.open(IDENTITY, message.key, message.payload, message.attachment)
        if message.kind is keyspace.RADIO_TX:
            meta = protocol.decode(metadata, protocol.RadioTxMeta)
            assert (meta.tick, meta.seq) == (0, 1)
        with pytest.raises(auth.AuthError):  # not in the world's name
            RUN_KEYS.open(names.WORLD, message.key, message.payload, message.attachment)
    unkeyed = beacon(keyed=False).receive_clock(*clock(0, keyring=None))
    assert [message.attachment is None for message in unkeyed] == [False, True]  # bare meta


def test_a_repeated_or_old_clock_is_not_answered_nor_counted() -> None:
    endpoint = beacon()
    assert endpoint.receive_clock(*clock(3))
    assert endpoint.receive_clock(*clock(3)) == []
    assert endpoint.receive_clock(*clock(1)) == []
    assert endpoint.rejected == 0


@pytest.mark.parametrize(
    "bad",
    [
        clock(1, keyring=None),  # untagged
        clock(1, keyring=auth.Keyring(secret=bytes(32))),  # another run's world
        (
            clock(1)[0],
            RUN_KEYS.seal(IDENTITY, KEYS.of(keyspace.BEACON_CLOCK, "nest"), clock(1)[0]),
        ),  # beacon
        clock(1, t=0.5),  # sim time not its tick's
        (
            b"[]",
            RUN_KEYS.seal(names.WORLD, KEYS.of(keyspace.BEACON_CLOCK, "nest"), b"[]"),
        ),  # no clock
        (
            clock(1)[0],
            RUN_KEYS.seal(names.WORLD, KEYS.of(keyspace.CLOCK), clock(1)[0]),
        ),  # another key
        clock(guard.TICK_WINDOW + 5 + 1),  # beyond the window of tick 0 (and a period)
    ],
    ids=[
        "untagged",
        "other run",
        "not the world",
        "wrong time",
        "undecodable",
        "world clock",
        "too far",
    ],
)
def test_a_clock_that_fails_a_check_is_refused_and_counted_in_the_next_ack(
    bad: tuple[bytes, bytes | None],
) -> None:
    endpoint = beacon()
    assert endpoint.receive_clock(*clock(0))
    assert endpoint.receive_clock(*bad) == []
    endpoint.count_dropped(2)  # what the transport dropped on arrival
    assert ack(endpoint.receive_clock(*clock(1))[-1]).rejected == 3


@pytest.mark.parametrize(("period", "dt"), [(0.5, 0.1), (0.3, 0.1), (0.25, 0.05), (30.0, 0.1)])
def test_the_next_tick_named_is_the_next_on_which_the_beacon_acts(period: float, dt: float) -> None:
    """Stepped every tick, as the in-process engine may, the beacon transmits on exactly the
    ticks its acks name, so skipping the others changes nothing it does."""
    config = BeaconConfig(period=period, flaky=0.3)
    every_tick = Beacon(config, Stream(5))
    transmitted = [tick for tick in range(2000) if every_tick.on_tick(tick * dt)]
    named = Beacon(config, Stream(5))
    tick, answered, sent = 0, [], []
    while tick < 2000:
        answered.append(tick)
        if named.on_tick(tick * dt):
            sent.append(tick)
        tick = named.next_tick(tick, dt)
    assert sent == transmitted and (every_tick.seq, every_tick.skipped) == (
        named.seq,
        named.skipped,
    )
    period_ticks = round(period / dt)
    assert answered[:4] == [0, period_ticks, 2 * period_ticks, 3 * period_ticks]


def test_a_new_world_is_followed_from_its_tick_zero() -> None:
    endpoint = beacon()
    endpoint.world_appeared("first")
    for tick in range(8):
        endpoint.receive_clock(*clock(tick))
    endpoint.world_appeared("impostor")  # a second token while the first lives: ignored
    assert endpoint.receive_clock(*clock(0)) == []
    endpoint.world_vanished("first")
    endpoint.world_appeared("second")
    answer = endpoint.receive_clock(*clock(0))  # its tick 0, and a transmission at once
    assert [message.kind for message in answer] == [keyspace.RADIO_TX, keyspace.ACK]
    assert endpoint.rejected == 0


def test_world_tokens_no_world_answers_for_are_counted_and_change_nothing() -> None:
    endpoint = beacon()
    endpoint.world_appeared("real")
    assert endpoint.receive_clock(*clock(5))
    for index in range(30):
        endpoint.world_unproven(f"fake{index}")
        endpoint.world_vanished(f"fake{index}")
    assert endpoint.receive_clock(*clock(5)) == []  # still a replay: the ticks are kept
    assert endpoint.worlds.followed == "real" and endpoint.rejected == 30


def test_the_same_world_back_is_rejoined_at_its_tick_and_a_replay_is_still_refused() -> None:
    endpoint = beacon()
    endpoint.world_appeared("world")
    assert endpoint.receive_clock(*clock(10))
    endpoint.world_vanished("world")
    endpoint.world_appeared("world")
    assert endpoint.receive_clock(*clock(10)) == []  # a replay
    far = 10 + 5 * guard.TICK_WINDOW
    assert ack(endpoint.receive_clock(*clock(far))[-1]).tick == far
    assert endpoint.receive_clock(*clock(far + endpoint.window + 1)) == []
    assert endpoint.rejected == 1  # bounded again from there
