"""A program that speaks the link, driven through the controller vectors (``swarm
conformance``'s first part).

A port takes its inputs only as the link brings them (docs/protocol.md, "The link to a
robot outside the emulator"), so this is how the vectors reach it: this process plays the
bridge *and* the world behind it. It starts the program as a porter does, with the link's
command line (``--link ADDRESS --id ID --key-file FILE``, a key file of a run of its own),
welcomes it with the track's controller settings, answers its question on ``world/info``
with the track's map (the generator's seed is the map's), and then, tick by tick, sends the
track's radio messages (``RadioRxMeta``), frame (PNG, ``CameraMeta``) and sense, each
sealed with the robot's run key as a world seals them, and waits for the program's answer:
its transmissions, its act and, if it changed, its status. Each is checked against the
track as soon as it is complete; the first output that differs ends the track.

UDP on loopback, or a serial line made of two pseudo-terminals (``socat``).
"""

from __future__ import annotations

import contextlib
import json
import secrets
import shutil
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import msgspec

from bestofn_swarm.link.core import codec
from bestofn_swarm.link.io.hub import Hub
from bestofn_swarm.link.io.transport import SerialLine, UdpServer
from bestofn_swarm.plumbing import run_keys
from bestofn_swarm.wire import auth, keyspace, names, protocol, settings
from bestofn_swarm.wire.keyspace import Part
from deploy.conformance.vectors import Divergence, Tick, Track, first_difference
from world_server.bridge.core.peer import LinkPeer, Message, SessionClosed

RUN = "conformance"
READY_TIMEOUT = 60.0  # seconds for a program to start, say hello and ask for its map
EXIT_TIMEOUT = 10.0  # seconds for a program told the run ended to exit


@dataclass
class Answer:
    """What the program sent for one tick."""

    act: protocol.Act | None = None
    broadcasts: list[dict[str, Any]] = field(default_factory=list)


class ProgramFailedError(Exception):
    """The program did something no port may do (wrong tags, messages that do not decode,
    ending early, no answer in time): a divergence of its own."""

    def __init__(self, field: str, expected: str, received: str) -> None:
        super().__init__(f"{field}: expected {expected}, received {received}")
        self.field, self.expected, self.received = field, expected, received


@contextlib.contextmanager
def pty_pair(folder: Path) -> Iterator[tuple[str, str]]:
    """A serial line made of two pseudo-terminals joined by ``socat``: (this end, the
    program's end). OSError if socat is missing or the line does not appear."""
    socat = shutil.which("socat")
    if socat is None:
        raise OSError("socat is not installed: no serial line to test on")
    folder.mkdir(parents=True, exist_ok=True)
    ours, theirs = folder / "bridge-tty", folder / "robot-tty"
    process = subprocess.Popen(
        [socat, f"pty,raw,echo=0,link={ours}", f"pty,raw,echo=0,link={theirs}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 10.0
        while not (ours.exists() and theirs.exists()):
            if time.monotonic() > deadline or process.poll() is not None:
                raise OSError("socat made no serial line")
            time.sleep(0.02)
        yield str(ours), str(theirs)
    finally:
        stop(process)


def stop(process: subprocess.Popen[Any], grace: float = 2.0) -> None:
    """End ``process`` (and only it): SIGTERM, then SIGKILL after ``grace`` seconds."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(grace)


class LinkedProgram:
    """The program under test on one link, with this process as its bridge and world."""

    def __init__(
        self,
        command: Sequence[str],
        track: Track,
        folder: Path,
        *,
        serial: tuple[str, str, int] | None = None,  # (our end, its end, baud)
        answer_timeout: float = 10.0,
    ) -> None:
        self.command = list(command)
        self.track = track
        self.robot = track.robot
        self.identity = names.robot_identity(self.robot)
        self.keys = keyspace.Keys(RUN)
        self.keyring = auth.Keyring(secret=secrets.token_bytes(32))
        robot_key = self.keyring.key(self.identity)
        assert robot_key is not None
        self.world = msgspec.structs.replace(track.world, run=RUN)
        self.answer_timeout = answer_timeout
        folder.mkdir(parents=True, exist_ok=True)
        self.key_file = folder / f"robot-{self.robot}.key"
        run_keys.write(self.key_file, self.keyring.only([self.identity]), RUN)
        self.log_path = folder / f"{track.name}.log"
        self.hub = Hub()
        if serial is None:
            server = UdpServer("127.0.0.1", 0)
            self.hub.add("link", lambda: server, must_open=True)
            self.address = f"udp://127.0.0.1:{server.port}"
            transport: codec.Transport = "udp"
        else:
            ours, theirs, baud = serial
            self.hub.add("link", lambda: SerialLine(ours, baud), must_open=True)
            self.address = f"serial:{theirs}@{baud}"
            transport = "serial"
        welcome = codec.LinkWelcome(
            v=1,
            run=RUN,
            root=protocol.DEFAULT_ROOT,
            cipher="none",
            ping_every=codec.PING_EVERY,
            silence=codec.SILENCE,
            controller=msgspec.Raw(settings.encode(track.controller).encode()),
        )
        self.peer = LinkPeer(
            self.robot,
            codec.link_key(robot_key),
            welcome,
            transport=transport,
            address=self.address,
        )
        self.process: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None
        self.answers: dict[int, Answer] = {}
        self.statuses: dict[int, bytes] = {}  # by tick, the first of each tick
        self.first_status: protocol.Status | None = None
        self.asked = 0
        self.closing = False

    # --- the program -----------------------------------------------------------------

    def start(self) -> None:
        """Start the program and wait until it has its map and has said so (its first
        status); ProgramFailedError if it does not."""
        self._log = self.log_path.open("wb")
        arguments = [
            "--link",
            self.address,
            "--id",
            str(self.robot),
            "--key-file",
            str(self.key_file),
        ]
        try:
            self.process = subprocess.Popen(
                [*self.command, *arguments],
                stdin=subprocess.DEVNULL,
                stdout=self._log,
                stderr=subprocess.STDOUT,
            )
        except OSError as error:
            raise ProgramFailedError("program", "a program to start", str(error)) from None
        self._pump(lambda: self.first_status is not None, READY_TIMEOUT, "its first status")

    def close(self) -> None:
        """Tell the program the run ended (BYE 1), let it exit, and stop what is left."""
        self.closing = True
        try:
            if self.peer.connected:
                self.peer.close(codec.ByeReason.RUN_ENDED)
                self._flush()
            if self.process is not None:
                deadline = time.monotonic() + EXIT_TIMEOUT
                while self.process.poll() is None and time.monotonic() < deadline:
                    self._turn(min(deadline, time.monotonic() + 0.05))
        except (ProgramFailedError, OSError):
            pass  # the track's verdict is in; what the program does now changes nothing
        finally:
            if self.process is not None:
                stop(self.process)
            self.hub.drain()
            self.hub.close()
            if self._log is not None:
                self._log.close()

    def log_tail(self, lines: int = 12) -> list[str]:
        """The last lines the program wrote (standard output and error)."""
        try:
            text = self.log_path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return []
        return text.splitlines()[-lines:]

    # --- a track -----------------------------------------------------------------------

    def run_track(self) -> Divergence | None:
        """Every tick of the track, in order; the first output that differs, or None."""
        previous: Tick | None = None
        for tick in self.track.ticks:
            try:
                self._send_inputs(tick)
                answer = self._await_answer(tick)
            except ProgramFailedError as failure:
                return self._failed(previous, failure, tick)
            if previous is not None:
                found = self._check_status(previous)
                if found is not None:
                    return found
            found = self._check_answer(tick, answer)
            if found is not None:
                return found
            previous = tick
        if previous is not None:
            # The last tick's status, if it has one, follows its act.
            expected = "status" in previous.out
            try:
                self._pump(lambda: previous.tick in self.statuses, 1.0 if expected else 0.3, None)
            except ProgramFailedError as failure:
                return self._failed(previous, failure, None)
            return self._check_status(previous)
        return None

    def _failed(
        self, previous: Tick | None, failure: ProgramFailedError, tick: Tick | None
    ) -> Divergence:
        at = tick.tick if tick is not None else (previous.tick if previous is not None else 0)
        return Divergence(self.track.name, at, failure.field, failure.expected, failure.received)

    def _check_answer(self, tick: Tick, answer: Answer) -> Divergence | None:
        act = answer.act
        assert act is not None
        observed = {
            "left": act.left,
            "right": act.right,
            "capture": act.capture,
            "broadcasts": answer.broadcasts,
            "status": None,
        }
        found = first_difference(tick, observed, fields=())
        if found is not None and not found[0].startswith("status"):
            return Divergence(self.track.name, tick.tick, *found)
        return None

    def _check_status(self, tick: Tick) -> Divergence | None:
        sent = self.statuses.get(tick.tick)
        out = tick.out
        status = json.loads(sent) if sent is not None else None
        observed = {
            "left": out["left"],
            "right": out["right"],
            "capture": out["capture"],
            "broadcasts": out["broadcasts"],
            "status": status,
        }
        found = first_difference(tick, observed, fields=())
        return None if found is None else Divergence(self.track.name, tick.tick, *found)

    # --- what goes to the program ----------------------------------------------------

    def _send_inputs(self, tick: Tick) -> None:
        number = tick.tick
        for index, (sender, payload) in enumerate(tick.radio(), start=1):
            meta = protocol.encode(
                protocol.RadioRxMeta(
                    v=protocol.VERSION,
                    tick=number,
                    sender=sender,
                    seq=index,
                    sent_tick=max(0, number - 1),
                )
            )
            key = self.keys.of(keyspace.RADIO_RX, names.robot_name(self.robot))
            self._send(
                keyspace.link(keyspace.RADIO_RX),
                payload,
                self.keyring.seal(self.identity, key, payload, meta),
            )
        frame = self.track.frame(tick)
        if frame is not None:
            camera = self.world.camera
            meta = protocol.encode(
                protocol.CameraMeta(
                    v=protocol.VERSION,
                    tick=number,
                    width=camera.width,
                    height=camera.height,
                    encoding="png",
                )
            )
            key = self.keys.of(keyspace.CAMERA, self.robot)
            self._send(
                keyspace.link(keyspace.CAMERA),
                frame,
                self.keyring.seal(self.identity, key, frame, meta),
            )
        sense = protocol.encode(tick.sense())
        key = self.keys.of(keyspace.SENSE, self.robot)
        self._send(
            keyspace.link(keyspace.SENSE), sense, self.keyring.seal(self.identity, key, sense)
        )

    def _send(self, kind: keyspace.LinkCode, payload: bytes, attachment: bytes | None) -> None:
        if not self.peer.send(kind, payload, attachment):
            raise ProgramFailedError("link", "an open session", "none (the program went quiet)")
        self._flush()

    def _await_answer(self, tick: Tick) -> Answer:
        def complete() -> bool:
            answer = self.answers.get(tick.tick)
            return (
                answer is not None
                and answer.act is not None
                and len(answer.broadcasts) >= answer.act.radio_tx
            )

        self._pump(complete, self.answer_timeout, f"its act of tick {tick.tick}")
        answer = self.answers.pop(tick.tick)
        assert answer.act is not None
        if len(answer.broadcasts) != answer.act.radio_tx:
            raise ProgramFailedError(
                "act.radio_tx", f"{len(answer.broadcasts)} (what it sent)", str(answer.act.radio_tx)
            )
        return answer

    # --- the loop ----------------------------------------------------------------------

    def _pump(self, done: Callable[[], bool], timeout: float, waiting_for: str | None) -> None:
        """Run the link until ``done()`` or ``timeout`` seconds; ProgramFailedError if it timed
        out while ``waiting_for`` something, or the program ended."""
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() >= deadline:
                if waiting_for is None:
                    return
                raise ProgramFailedError("answer", f"{waiting_for} within {timeout:g} s", "nothing")
            self._turn(deadline)
            process = self.process
            if process is not None and process.poll() is not None and not done():
                raise ProgramFailedError(
                    "program",
                    "a program that runs on",
                    f"it ended with exit code {process.returncode}",
                )

    def _turn(self, deadline: float) -> None:
        now = time.monotonic()
        wake = self.peer.deadline
        self.hub.poll(min(deadline, wake if wake is not None else deadline))
        now = time.monotonic()
        for data, source in self.hub.receive("link", now):
            for event in self.peer.receive(data, source, now):
                self._event(event)
        for event in self.peer.wake(now):
            self._event(event)
        self._flush()

    def _flush(self) -> None:
        now = time.monotonic()
        for frame, target in self.peer.take_outgoing():
            self.hub.send("link", frame, target, now)
        self.hub.flush(now)

    def _event(self, event: object) -> None:
        if isinstance(event, SessionClosed) and self.first_status is not None and not self.closing:
            raise ProgramFailedError(
                "link", "the session to stay open", f"it closed: {event.reason}"
            )
        if isinstance(event, Message):
            self._message(event)

    def _message(self, message: Message) -> None:
        kind, payload, attachment = message.kind, message.payload, message.attachment
        if kind is keyspace.link(keyspace.INFO):
            self._answer_question(payload, attachment)
            return
        keys, robot = self.keys, self.robot
        key = {
            keyspace.link(keyspace.ACT): keys.of(keyspace.ACT, robot),
            keyspace.link(keyspace.RADIO_TX): keys.of(keyspace.RADIO_TX, names.robot_name(robot)),
            keyspace.link(keyspace.STATUS): keys.of(keyspace.STATUS, robot),
        }[kind]
        what = kind.name.lower()
        try:
            metadata = self.keyring.open(self.identity, key, payload, attachment)
        except auth.AuthError as error:
            raise ProgramFailedError(
                what, f"a {what} tagged with the robot's run key", str(error)
            ) from None
        try:
            if kind is keyspace.link(keyspace.ACT):
                act = protocol.decode(payload, protocol.Act)
                self.answers.setdefault(act.tick, Answer()).act = act
            elif kind is keyspace.link(keyspace.RADIO_TX):
                meta = protocol.decode(metadata, protocol.RadioTxMeta)
                broadcast = protocol.decode_radio(payload)
                value = json.loads(protocol.encode(broadcast))
                self.answers.setdefault(meta.tick, Answer()).broadcasts.append(value)
            else:
                status = protocol.decode(payload, protocol.Status)
                canonical = protocol.encode(status)
                if self.first_status is None:
                    self.first_status = status  # at tick 0, before any step
                    self.statuses[status.tick] = canonical
                else:
                    self.statuses.setdefault(status.tick, canonical)  # a repeat: the same
        except protocol.ProtocolError as error:
            raise ProgramFailedError(
                what, f"a valid {what}", f"{error} ({payload[:200]!r})"
            ) from None

    def _answer_question(self, payload: bytes, attachment: bytes | None) -> None:
        self.asked += 1
        try:
            identity, nonce = auth.query_open(
                self.keyring, self.keys.of(keyspace.INFO), payload, attachment
            )
        except auth.AuthError as error:
            raise ProgramFailedError(
                keyspace.INFO.label, "a question tagged with the robot's key", str(error)
            ) from None
        if payload:
            # A proof of a world instance: none was reported, so none answers.
            self._send(keyspace.link(keyspace.INFO, Part.ERROR), b"not this world instance", None)
            return
        info = protocol.encode(self.world)
        sealed = auth.reply_seal(self.keyring, identity, self.keys.of(keyspace.INFO), info, nonce)
        self._send(keyspace.link(keyspace.INFO, Part.REPLY), info, sealed)


def run_tracks(
    command: Sequence[str],
    tracks: Sequence[Track],
    folder: Path,
    *,
    serial_baud: int | None = None,
    answer_timeout: float = 10.0,
    on_track: Callable[[Track, Divergence | None, LinkedProgram], None] | None = None,
) -> list[tuple[Track, Divergence | None, list[str]]]:
    """Each track through a fresh start of the program (on a serial line at
    ``serial_baud`` when given); per track, its first divergence (or None) and the
    program's last lines of output."""
    results = []
    for track in tracks:
        with contextlib.ExitStack() as stack:
            serial = None
            if serial_baud is not None:
                ours, theirs = stack.enter_context(pty_pair(folder / f"{track.name}-line"))
                serial = (ours, theirs, serial_baud)
            program = LinkedProgram(
                command, track, folder / track.name, serial=serial, answer_timeout=answer_timeout
            )
            try:
                try:
                    program.start()
                    found = program.run_track()
                except ProgramFailedError as failure:
                    found = Divergence(  # before its first tick
                        track.name, -1, failure.field, failure.expected, failure.received
                    )
            finally:
                program.close()
            if on_track is not None:
                on_track(track, found, program)
            results.append((track, found, program.log_tail()))
    return results


__all__ = ["LinkedProgram", "ProgramFailedError", "pty_pair", "run_tracks", "stop"]
