"""The link between a robot outside the emulator and the bridge, without sockets: frames
(bestofn_swarm/link/core/codec.py), the robot's end of a session (``LinkClient``) against the
bridge's (``LinkPeer``) in memory, refusals of what is forged, replayed, oversized or out of place,
and the impairment that makes a link worse on purpose."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bestofn_swarm.link.core import codec, pacing
from bestofn_swarm.link.core.session import LinkClient, LinkData, Lost, Welcomed
from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.keyspace import Part
from bestofn_swarm.wire.rng import Stream
from world_server.bridge.core.impairment import ImpairedDirection, LinkImpairment
from world_server.bridge.core.peer import (
    FRAME_BURST,
    MAX_FROM_ROBOT_BYTES,
    PING_TIMEOUT,
    LinkPeer,
    Message,
    SessionClosed,
    SessionOpened,
)

ROBOT_KEY = bytes(range(32))
KEY = codec.link_key(ROBOT_KEY)
ROBOT = 8
SOURCE = ("127.0.0.1", 40000)


def welcome(cipher: codec.Cipher = "none") -> codec.LinkWelcome:
    return codec.LinkWelcome(
        v=1,
        run="demo",
        root="bestofn",
        cipher=cipher,
        ping_every=0.5,
        silence=3.0,
        controller=msgspec.Raw(b'{"dwell":3.0}'),
    )


def counting_nonces(start: int) -> Callable[[], bytes]:
    counter = itertools.count(start)
    return lambda: next(counter).to_bytes(codec.NONCE_BYTES, "big")


class Pair:
    """A program's client and the bridge's peer, wired back to back in memory."""

    def __init__(self, cipher: codec.Cipher = "none") -> None:
        self.client = LinkClient(ROBOT, KEY, nonce=counting_nonces(1))
        self.peer = LinkPeer(
            ROBOT,
            KEY,
            welcome(cipher),
            transport="udp",
            address="udp://127.0.0.1:47800",
            nonce=counting_nonces(1000),
        )
        self.now = 0.0
        self.to_peer: list[bytes] = []  # frames the client sent, as the wire saw them
        self.to_client: list[bytes] = []
        self.client_events: list[object] = []
        self.peer_events: list[object] = []

    def exchange(self) -> None:
        """Deliver everything queued both ways until nothing moves."""
        while True:
            up = self.client.take_outgoing()
            down = [frame for frame, _ in self.peer.take_outgoing()]
            if not up and not down:
                return
            for frame in up:
                self.to_peer.append(frame)
                self.peer_events += self.peer.receive(frame, SOURCE, self.now)
            for frame in down:
                self.to_client.append(frame)
                self.client_events += self.client.receive(frame, self.now)

    def connect(self) -> None:
        self.client.wake(self.now)
        self.exchange()


# --- frames --------------------------------------------------------------------------------


def frame(kind: codec.FrameType = codec.FrameType.DATA, **changes: object) -> codec.Frame:
    fields: dict[str, object] = {
        "type": kind,
        "from_bridge": False,
        "robot": ROBOT,
        "robot_nonce": b"\x01" * 8,
        "bridge_nonce": b"\x02" * 8,
        "seq": 1,
        "body": codec.encode_data(keyspace.link(keyspace.ACT), b'{"v":1}', b"t" * 16),
    }
    fields.update(changes)
    return codec.Frame(**fields)  # type: ignore[arg-type]


def test_a_frame_is_its_header_body_and_tag_and_reads_back() -> None:
    sent = frame()
    data = codec.seal(sent, KEY)
    assert data[:2] == b"BL" and data[2] == 1 and data[3] == codec.FrameType.DATA
    assert data[4] == 0  # from the robot, not encrypted
    assert int.from_bytes(data[5:9], "big") == ROBOT
    assert len(data) == codec.HEADER_BYTES + len(sent.body) + codec.TAG_BYTES
    assert codec.open_frame(data, KEY) == sent
    assert codec.decode_data(sent.body) == (keyspace.link(keyspace.ACT), b'{"v":1}', b"t" * 16)


def test_an_encrypted_frame_hides_its_body_and_checks_out_only_under_its_session_key() -> None:
    session = codec.session_key(KEY, b"\x01" * 8, b"\x02" * 8)
    sent = frame(encrypted=True)
    data = codec.seal(sent, KEY, session)
    assert sent.body not in data and data[4] == codec.ENCRYPTED
    assert codec.open_frame(data, KEY, session) == sent
    other = codec.session_key(KEY, b"\x01" * 8, b"\x03" * 8)
    with pytest.raises(codec.LinkError) as refused:
        codec.open_frame(data, KEY, other)
    assert refused.value.refusal is codec.Refusal.FORGED


@pytest.mark.parametrize(
    ("change", "refusal"),
    [
        (lambda data: data[:20], codec.Refusal.MALFORMED),
        (lambda data: b"XX" + data[2:], codec.Refusal.MALFORMED),
        (lambda data: data[:2] + b"\x02" + data[3:], codec.Refusal.MALFORMED),
        (lambda data: data[:3] + b"\x09" + data[4:], codec.Refusal.MALFORMED),
        (lambda data: data[:4] + b"\x80" + data[5:], codec.Refusal.MALFORMED),
        (lambda data: data[:-1] + bytes([data[-1] ^ 1]), codec.Refusal.FORGED),
        (lambda data: data[:40] + b"!" + data[41:], codec.Refusal.FORGED),
        (lambda data: data + b"\0" * codec.MAX_FRAME_BYTES, codec.Refusal.OVERSIZE),
    ],
)
def test_a_frame_changed_in_any_way_is_refused_for_its_reason(
    change: object, refusal: codec.Refusal
) -> None:
    data = change(codec.seal(frame(), KEY))  # type: ignore[operator]
    with pytest.raises(codec.LinkError) as refused:
        codec.open_frame(data, KEY)
    assert refused.value.refusal is refusal


def test_the_link_key_is_not_the_robot_key_and_cannot_tag_as_the_robot() -> None:
    assert codec.link_key(ROBOT_KEY) != ROBOT_KEY and len(KEY) == 32
    data = codec.seal(frame(), ROBOT_KEY)
    with pytest.raises(codec.LinkError):
        codec.open_frame(data, KEY)


@given(st.binary(max_size=3000))
def test_any_bytes_are_a_frame_or_a_link_error(data: bytes) -> None:
    try:
        opened = codec.open_frame(data, KEY)
    except codec.LinkError as error:
        assert error.refusal in codec.Refusal
    else:
        assert isinstance(opened, codec.Frame)


@given(st.lists(st.binary(min_size=1, max_size=600), min_size=1, max_size=8), st.data())
def test_serial_framing_cuts_any_split_stream_back_into_its_frames(
    frames: list[bytes], data: st.DataObject
) -> None:
    stream = b"".join(codec.serial_encode(item) for item in frames)
    assert stream.count(0) == len(frames)  # COBS: the only zeros end frames
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    deframer = codec.Deframer()
    found: list[bytes | codec.LinkError] = []
    for start, end in itertools.pairwise([0, *cuts, len(stream)]):
        found += deframer.feed(stream[start:end])
    assert found == frames


def test_serial_framing_refuses_a_bad_crc_and_finds_the_next_frame() -> None:
    good = codec.serial_encode(b"hello")
    bad = bytearray(codec.serial_encode(b"world"))
    bad[2] ^= 0x40
    found = codec.Deframer().feed(bytes(bad) + good)
    assert isinstance(found[0], codec.LinkError) and found[0].refusal is codec.Refusal.CORRUPT
    assert found[1:] == [b"hello"]


def test_serial_framing_drops_a_run_longer_than_any_frame_until_the_next_zero() -> None:
    deframer = codec.Deframer()
    found = deframer.feed(b"\x01" * (codec.MAX_ENCODED_BYTES + 10))
    assert found == [] and len(deframer.buffer) < codec.MAX_ENCODED_BYTES
    found = deframer.feed(b"\x01\x00" + codec.serial_encode(b"next"))
    assert isinstance(found[0], codec.LinkError) and found[0].refusal is codec.Refusal.OVERSIZE
    assert found[1:] == [b"next"]


def test_the_replay_window_takes_each_number_once_and_allows_reordering() -> None:
    window = codec.ReplayWindow()
    for seq in (1, 3, 2, 10, 5):
        assert window.refuses(seq) is None
        window.take(seq)
    assert all(window.refuses(seq) is not None for seq in (1, 2, 3, 5, 10))
    assert window.refuses(4) is None
    window.take(200)
    assert window.refuses(4) is not None  # too far behind
    assert window.refuses(199) is None


def test_a_paced_line_hands_a_frame_on_when_its_last_byte_would_arrive() -> None:
    pacer = pacing.LinePacer(115200)
    assert pacer.done_at(1152, 0.0) == pytest.approx(0.1)  # 11520 bits
    assert pacer.done_at(1152, 0.05) == pytest.approx(0.2)  # waits for the line
    assert pacer.done_at(10, 1.0) == pytest.approx(1.0 + 100 / 115200)


def test_a_paced_line_hands_bytes_on_as_the_line_carries_them_each_frame_in_time() -> None:
    """11520 bytes at 115200 baud take 1 s: a slice of 230 bytes every 20 ms on the way, the
    last byte at 1 s exactly (LinePacer's time); the next frame follows the first."""
    line = pacing.PacedLine(115200)
    first, second = bytes(range(256)) * 45, b"next"
    assert line.put(first, 0.0) == pytest.approx(1.0)
    assert line.put(second, 0.5) == pytest.approx(1.0 + 40 / 115200)
    assert line.busy_until == pytest.approx(1.0 + 40 / 115200)
    assert line.take(0.0) == (b"", 0) and line.deadline == pytest.approx(230 * 10 / 115200)
    carried = b""
    times = []
    while line.deadline is not None and line.deadline < 1.0:
        times.append(line.deadline)
        due, completed = line.take(line.deadline)
        assert 0 < len(due) <= 230 and completed == 0
        carried += due
    assert len(times) == 11520 // 230 and times == sorted(times)
    due, completed = line.take(0.999)  # by then all but the last few bytes
    assert 0 < len(carried + due) < len(first) and completed == 0
    carried += due
    due, completed = line.take(1.0)
    assert carried + due == first and completed == 1
    assert line.take(1.0 + 40 / 115200) == (second, 1)
    assert line.deadline is None and line.held_bytes == 0


def test_a_paced_line_drops_the_frames_not_begun_and_finishes_the_one_under_way() -> None:
    """When a session ends, what waits for it on the line is dropped (the next session's
    welcome would wait behind it), but the frame whose bytes are going finishes whole."""
    line = pacing.PacedLine(115200)
    done = line.put(b"x" * 11520, 0.0)  # 1 s of line
    line.put(b"y" * 11520, 0.0)
    line.put(b"z" * 100, 0.0)
    line.take(0.5)
    assert line.discard_waiting(0.5) == 2
    assert line.busy_until == pytest.approx(done) and line.held_bytes == 11520
    rest, completed = line.take(1.0)
    assert completed == 1 and line.held_bytes == 0 and set(rest) == {ord("x")}
    assert line.put(b"next", 1.0) == pytest.approx(1.0 + 40 / 115200)  # free again


def test_a_frame_under_way_on_a_serial_line_keeps_the_session_at_both_ends() -> None:
    """Bytes of a frame arriving (hearing) restart the silence at either end; and the bridge
    does not count as the robot's silence the time its own frames take to reach the robot,
    which cannot answer a ping queued behind them. Before a session, hearing opens nothing."""
    pair = Pair()
    pair.client.hearing(1.0)
    assert not pair.client.open and pair.client.last_heard == 0.0
    pair.connect()
    for pair.now in (2.0, 4.0, 5.5):  # a long frame to the robot, seen arriving
        pair.client.hearing(pair.now)
        assert pair.client.wake(pair.now) == [] and pair.client.open
    pair.peer.sending(until=5.5)  # the bridge's frames reach the robot at 5.5
    assert pair.peer.wake(5.0) == [] and pair.peer.connected
    assert pair.peer.deadline is not None and pair.peer.deadline <= 8.5
    pair.peer.hearing(7.0)  # then a frame of the robot's, arriving
    assert pair.peer.wake(9.9) == [] and pair.peer.connected
    assert pair.peer.wake(10.0) == [SessionClosed(ROBOT, "silent for 3 s")]
    assert [type(event) for event in pair.client.wake(8.5)] == [Lost]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("udp://127.0.0.1:47800", codec.LinkAddress("udp", host="127.0.0.1", port=47800)),
        ("udp://[::1]:9", codec.LinkAddress("udp", host="::1", port=9)),
        ("serial:/dev/ttyUSB0", codec.LinkAddress("serial", path="/dev/ttyUSB0")),
        ("serial:/dev/pts/4@921600", codec.LinkAddress("serial", path="/dev/pts/4", baud=921600)),
    ],
)
def test_link_addresses_read_and_print_back(text: str, expected: codec.LinkAddress) -> None:
    address = codec.parse_address(text)
    assert address == expected
    assert codec.parse_address(str(address)) == address


@pytest.mark.parametrize(
    "text", ["tcp://1.2.3.4:5", "udp://nohost", "udp://:5", "serial:", "serial:/dev/x@fast"]
)
def test_a_bad_link_address_is_a_value_error(text: str) -> None:
    with pytest.raises(ValueError, match=r"link|UDP|serial"):
        codec.parse_address(text)


# --- sessions ------------------------------------------------------------------------------


@pytest.mark.parametrize("cipher", ["none", "chacha20-poly1305"])
def test_hello_welcome_and_the_first_frame_open_a_session_both_ends_agree_on(
    cipher: codec.Cipher,
) -> None:
    pair = Pair(cipher)
    pair.connect()
    assert [type(event) for event in pair.client_events] == [Welcomed]
    assert pair.peer_events == [SessionOpened(ROBOT)]
    assert pair.client.open and pair.peer.connected
    assert pair.client.cipher_key == pair.peer.session.cipher_key  # type: ignore[union-attr]
    assert (pair.client.cipher_key is None) == (cipher == "none")
    # Messages both ways, in order, as they were sent.
    assert pair.client.send(keyspace.link(keyspace.STATUS), b"status", b"t" * 16)
    pair.peer.send(keyspace.link(keyspace.SENSE), b"sense", b"s" * 16)
    pair.exchange()
    assert pair.peer_events[-1] == Message(
        ROBOT, keyspace.link(keyspace.STATUS), b"status", b"t" * 16
    )
    assert pair.client_events[-1] == LinkData(keyspace.link(keyspace.SENSE), b"sense", b"s" * 16)


def test_a_replayed_or_forged_frame_is_refused_and_counted_and_changes_nothing() -> None:
    pair = Pair()
    pair.connect()
    pair.client.send(keyspace.link(keyspace.ACT), b"act", b"t" * 16)
    pair.exchange()
    events = len(pair.peer_events)
    act = pair.to_peer[-1]
    assert pair.peer.receive(act, SOURCE, 0.0) == []  # replayed
    forged = act[:-1] + bytes([act[-1] ^ 1])
    assert pair.peer.receive(forged, SOURCE, 0.0) == []
    hello = pair.to_peer[0]
    assert pair.peer.receive(hello, SOURCE, 0.0) == []  # a hello already answered
    assert len(pair.peer_events) == events and pair.peer.connected
    assert pair.peer.refused == {"replayed": 2, "forged": 1}
    # The program refuses a replayed frame of the bridge's just the same.
    assert pair.client.receive(pair.to_client[-1], 0.0) == []
    assert pair.client.refused == {"replayed": 1}


def test_a_frame_of_another_robot_direction_or_kind_is_refused() -> None:
    pair = Pair()
    pair.connect()
    other_key = codec.link_key(bytes(32))
    stranger = codec.seal(frame(robot=9), other_key)
    assert pair.peer.receive(stranger, SOURCE, 0.0) == []
    session = pair.peer.session
    assert session is not None
    # Authentic, of this session, but a message only the world sends a robot.
    wrong_kind = frame(
        robot_nonce=session.robot_nonce,
        bridge_nonce=session.bridge_nonce,
        seq=99,
        body=codec.encode_data(keyspace.link(keyspace.SENSE), b"x", None),
    )
    assert pair.peer.receive(codec.seal(wrong_kind, KEY), SOURCE, 0.0) == []
    assert pair.peer.refused == {"unexpected": 2}


def test_an_oversized_frame_from_a_robot_is_refused_before_its_tag_is_checked() -> None:
    pair = Pair()
    pair.connect()
    assert pair.peer.receive(b"BL" + bytes(MAX_FROM_ROBOT_BYTES), SOURCE, 0.0) == []
    assert pair.peer.refused == {"oversize": 1}


def test_a_replayed_hello_opens_nothing_and_the_live_session_goes_on() -> None:
    pair = Pair()
    pair.connect()
    # Someone replays the program's hello to a bridge that forgot it (a restarted one):
    # it is welcomed, but nobody can make the frame that would take the session.
    fresh = LinkPeer(
        ROBOT, KEY, welcome(), transport="udp", address="x", nonce=counting_nonces(5000)
    )
    assert fresh.receive(pair.to_peer[0], ("10.0.0.1", 1), 0.0) == []
    assert fresh.pending is not None and not fresh.connected
    assert [target for _, target in fresh.take_outgoing()] == [("10.0.0.1", 1)]


def test_a_newer_session_replaces_the_old_one_which_the_run_sees_leave_and_join() -> None:
    pair = Pair()
    pair.connect()
    restarted = LinkClient(ROBOT, KEY, nonce=counting_nonces(77))
    pair.client = restarted
    pair.connect()
    replaced = SessionClosed(ROBOT, "a newer session replaced it")
    assert pair.peer_events == [SessionOpened(ROBOT), replaced, SessionOpened(ROBOT)]
    assert pair.peer.sessions == 2


def test_the_bridge_pings_measures_round_trips_and_counts_unanswered_pings_as_lost() -> None:
    pair = Pair()
    pair.connect()  # at 0: the first ping is due at once
    for pair.now in (0.0, 0.5, 1.0, 1.5):  # pings 1 to 4; only the second gets through
        pair.peer.wake(pair.now)
        if pair.now == 0.5:
            pair.now = 0.54
            pair.exchange()
        else:
            pair.peer.take_outgoing()
    pair.now = 1.5 + PING_TIMEOUT
    pair.peer.last_heard = pair.now  # (not silent: only the pings are lost)
    pair.peer.wake(pair.now)
    stats = pair.peer.stats()
    assert stats.rtt_ms == pytest.approx(40.0)
    assert stats.pings == 4 and stats.loss == pytest.approx(0.75)
    assert stats.connected and stats.sessions == 1 and stats.transport == "udp"
    protocol.decode(protocol.encode(stats), protocol.LinkStats)


def test_silence_ends_the_session_at_both_ends_and_the_program_says_hello_again() -> None:
    pair = Pair()
    pair.connect()
    pair.now = 3.5
    assert pair.peer.wake(pair.now) == [SessionClosed(ROBOT, "silent for 3 s")]
    lost = pair.client.wake(pair.now)
    assert [type(event) for event in lost] == [Lost] and not pair.client.open
    pair.client_events.clear()
    pair.peer_events.clear()
    pair.connect()
    assert pair.peer_events == [SessionOpened(ROBOT)] and pair.client.sessions == 2


def test_a_bye_that_the_run_ended_tells_the_program_to_stop() -> None:
    pair = Pair()
    pair.connect()
    pair.peer.close(codec.ByeReason.RUN_ENDED)
    pair.exchange()
    assert pair.client_events[-1] == Lost("the bridge said bye (run_ended)", ended=True)


def test_a_robot_that_floods_its_link_is_held_to_the_rate_bound() -> None:
    pair = Pair()
    pair.connect()
    for _ in range(int(FRAME_BURST) + 50):
        pair.client.send(keyspace.link(keyspace.ACT), b"a", None)
    pair.exchange()
    assert pair.peer.refused["rate"] >= 40


# --- impairment ----------------------------------------------------------------------------


def test_an_impaired_direction_delays_jitters_and_loses_frames_in_order_and_seeded() -> None:
    impairment = LinkImpairment(delay=0.05, jitter=0.01, loss=0.2)
    runs = []
    for _ in range(2):
        direction = ImpairedDirection.seeded(impairment, seed=3, robot=8, direction="up")
        kept = [n for n in range(1000) if direction.put(bytes([n % 256]), n, now=n * 0.001)]
        released = direction.due(10.0)
        assert [where for _, where in released] == kept  # in order
        runs.append(kept)
    assert runs[0] == runs[1]  # seeded
    assert 150 < 1000 - len(runs[0]) < 250


def test_a_frame_is_held_for_the_delay_and_no_less() -> None:
    direction = ImpairedDirection(LinkImpairment(delay=0.05), Stream(0))
    direction.put(b"x", "a", now=1.0)
    assert direction.due(1.049) == [] and direction.deadline == pytest.approx(1.05)
    assert direction.due(1.05) == [(b"x", "a")]


# --- the program, end to end in memory -----------------------------------------------------


INFO = protocol.WorldInfo(
    v=1,
    run="demo",
    seed=3,
    dt=0.1,
    arena_radius=0.75,
    nest=protocol.Nest(0.0, 0.0, 0.2),
    sites=[protocol.Site(0, 0.75, 0.0), protocol.Site(1, -0.75, 0.0)],
    robot_radius=0.037,
    wheel_base=0.053,
    max_wheel_speed=0.13,
    camera=protocol.CameraSpec(width=64, height=48, fov=0.84),
    clock="lockstep",
)


class ProgramOnABridge:
    """The robot program (``robot-agent --link`` without its loop) against the bridge's end
    and a world that answers world/info for any world or for its own instance only, as the
    world server does."""

    def __init__(self, instance: str = "w-1") -> None:
        from bestofn_swarm.wire import auth, names
        from robot_agent.core.link_robot import LinkRobot

        self.auth = auth
        self.secret = auth.Keyring(secret=bytes(32))  # the world's
        self.keys = keyspace.Keys("demo")
        self.identity = names.robot_identity(ROBOT)
        self.instance = instance
        self.robot = LinkRobot.create(ROBOT, "demo", self.secret.only([self.identity]))
        self.peer = LinkPeer(
            ROBOT,
            self.robot.client.key,
            msgspec.structs.replace(welcome(), controller=msgspec.Raw(b"{}")),
            transport="udp",
            address="x",
        )
        self.relayed: list[Message] = []
        self.slow = False  # the world holds its answers until ``answer_held``
        self.held: list[Message] = []

    def exchange(self, now: float = 0.0) -> None:
        self.robot.wake(now)
        self.peer.wake(now)
        while True:
            up, down = self.robot.client.take_outgoing(), self.peer.take_outgoing()
            if not up and not down:
                return
            for sent in up:
                for event in self.peer.receive(sent, SOURCE, now):
                    if isinstance(event, Message):
                        self.relayed.append(event)
                        self.world(event)
            for sent, _ in down:
                self.robot.receive(sent, now)

    def world(self, message: Message) -> None:
        if message.kind is not keyspace.link(keyspace.INFO):
            return
        if message.payload not in (b"", self.instance.encode()):
            return  # a question for another world instance: this world does not answer
        if self.slow:
            self.held.append(message)
            return
        self.answer(message)

    def answer(self, message: Message) -> None:
        info_key = self.keys.of(keyspace.INFO)
        asker, nonce = self.auth.query_open(
            self.secret, info_key, message.payload, message.attachment
        )
        payload = protocol.encode(INFO)
        sealed = self.auth.reply_seal(self.secret, asker, info_key, payload, nonce)
        self.peer.send(keyspace.link(keyspace.INFO, Part.REPLY), payload, sealed)

    def questions(self, instance: str) -> int:
        return sum(
            1
            for m in self.relayed
            if m.kind is keyspace.link(keyspace.INFO) and m.payload == instance.encode()
        )


def test_the_program_asks_for_the_map_says_it_is_there_and_steps_a_sealed_sense() -> None:
    """The map is asked and checked, the first status comes before anything else, and a
    sense sealed for the robot is answered by an act sealed by it."""
    bench = ProgramOnABridge()
    robot, peer, secret, keys, identity = (
        bench.robot,
        bench.peer,
        bench.secret,
        bench.keys,
        bench.identity,
    )
    bench.exchange()
    assert [m.kind for m in bench.relayed] == [
        keyspace.link(keyspace.INFO),
        keyspace.link(keyspace.STATUS),
    ]
    status = bench.relayed[-1]
    secret.open(identity, keys.of(keyspace.STATUS, ROBOT), status.payload, status.attachment)
    assert protocol.decode(status.payload, protocol.Status).tick == 0
    sense = protocol.encode(
        protocol.Sense(
            v=1, tick=0, t=0.0, x=0.3, y=0.0, theta=0.0, prox=[0.0] * 8, rx=0, camera=False
        )
    )
    peer.send(
        keyspace.link(keyspace.SENSE),
        sense,
        secret.seal(identity, keys.of(keyspace.SENSE, ROBOT), sense),
    )
    bench.exchange()
    act = next(m for m in bench.relayed if m.kind is keyspace.link(keyspace.ACT))
    secret.open(
        identity, keys.of(keyspace.ACT, ROBOT), act.payload, act.attachment
    )  # sealed by the robot
    assert protocol.decode(act.payload, protocol.Act).tick == 0
    # A sense forged by anyone without the robot's key is refused by the program itself.
    forged = sense.replace(b'"x":0.3', b'"x":0.4')
    peer.send(
        keyspace.link(keyspace.SENSE),
        forged,
        secret.seal(identity, keys.of(keyspace.SENSE, ROBOT), sense),
    )
    bench.exchange()
    assert robot.endpoint is not None and robot.endpoint.rejects.count == 1


def test_the_program_follows_a_world_token_only_once_that_world_answers_for_it() -> None:
    """The bridge is trusted with nothing the robot believes: a world token it reports is
    asked to answer for itself (world/info with its instance), followed once it does, and
    one that no world answers for is asked PROVE_TRIES times, PROVE_EVERY apart, then
    counted as a rejection, the robot still on its world."""
    from robot_agent.core.link_robot import PROVE_EVERY, PROVE_TRIES

    bench = ProgramOnABridge(instance="w-1")
    bench.exchange()
    endpoint = bench.robot.endpoint
    assert endpoint is not None and endpoint.worlds.followed is None
    bench.peer.send(keyspace.link(keyspace.ALIVE_WORLD), b"w-1", None)
    bench.exchange()
    assert bench.questions("w-1") == 1
    assert endpoint.worlds.followed == "w-1"  # answered at once by its world
    rejected = endpoint.rejects.count
    bench.peer.send(keyspace.link(keyspace.ALIVE_WORLD), b"w-2", None)
    now = 0.0
    while now <= PROVE_EVERY * (PROVE_TRIES + 1):
        bench.exchange(now)
        now += 0.25
    assert bench.robot.client.open  # the bridge's pings kept the session all along
    assert bench.questions("w-2") == PROVE_TRIES
    assert endpoint.rejects.count == rejected + 1
    assert endpoint.worlds.followed == "w-1" and bench.robot.proving == {}


def test_an_answer_slower_than_the_repeats_still_brings_the_map_and_the_proof() -> None:
    """A question asked again does not void the ones before it: over a relay slower than
    ASK_EVERY and PROVE_EVERY (a link with a long delay) the first answers still count."""
    from robot_agent.core.link_robot import ASK_EVERY, PROVE_EVERY

    bench = ProgramOnABridge(instance="w-1")
    bench.slow = True
    bench.exchange(0.0)
    bench.exchange(ASK_EVERY)
    bench.exchange(2 * ASK_EVERY)
    assert bench.questions("") == 3 and bench.robot.endpoint is None
    bench.answer(bench.held[0])  # the answer to the first question, two askings late
    bench.exchange(2 * ASK_EVERY)
    endpoint = bench.robot.endpoint
    assert endpoint is not None
    bench.held.clear()
    bench.peer.send(keyspace.link(keyspace.ALIVE_WORLD), b"w-1", None)
    now = 2 * ASK_EVERY
    for _ in range(3):
        bench.exchange(now)
        now += PROVE_EVERY
    assert bench.questions("w-1") == 3 and endpoint.worlds.followed is None
    bench.answer(bench.held[0])
    bench.exchange(now)
    assert endpoint.worlds.followed == "w-1" and bench.robot.proving == {}


def test_no_question_is_asked_again_while_a_frame_is_arriving_on_a_serial_line() -> None:
    """A map of 1000 sites takes 5 s at 115200 baud: while it comes (bytes heard, its end
    not yet) the program does not ask again, which would only queue more maps behind it; it
    asks again ASK_EVERY after the line falls quiet without the answer."""
    from robot_agent.core.link_robot import ASK_EVERY

    bench = ProgramOnABridge(instance="w-1")
    bench.slow = True
    bench.exchange(0.0)
    for now in (0.5, 1.5, 2.5, 3.5, 4.5):  # bytes of a frame arriving all along
        bench.robot.hearing(now)
        bench.exchange(now)
    assert bench.questions("") == 1 and bench.robot.client.open
    bench.exchange(4.5 + ASK_EVERY)
    assert bench.questions("") == 2
    bench.answer(bench.held[0])  # the first answer, at last
    bench.exchange(4.5 + ASK_EVERY)
    assert bench.robot.endpoint is not None


def test_a_welcome_of_another_run_gets_one_bye_and_ends_the_program_as_failed() -> None:
    """The key file is of another run: the program says BYE (going away) once, ends, and
    counts as failed (exit code 1); stopping it afterwards sends nothing more."""
    bench = ProgramOnABridge()
    robot = bench.robot
    robot.run = "another-run"
    robot.wake(0.0)
    for hello in robot.client.take_outgoing():
        for event in bench.peer.receive(hello, SOURCE, 0.0):
            assert not isinstance(event, Message)
    for sent, _ in bench.peer.take_outgoing():
        robot.receive(sent, 0.0)
    said = robot.client.take_outgoing()
    types = [codec.read_header(frame).type for frame in said]
    assert types == [codec.FrameType.PING, codec.FrameType.BYE]
    assert robot.ended and robot.failed and not robot.client.open
    robot.stop()
    assert robot.client.take_outgoing() == []
