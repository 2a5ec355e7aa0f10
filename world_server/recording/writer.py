"""The MCAP writer: ``McapRecorder`` turns one run's samples into the records of one MCAP
file that opens in Foxglove. No Zenoh: the recorder process (``world_server/recorder/``)
feeds it what it receives, the in-process engine what it computes, Foxglove live what it
forwards.

What a recording holds (see docs/recording.md; the record types in ``records.py``):

* one channel per key, topic = the key, schema encoding ``jsonschema`` with the schema
  generated from the message's one definition in ``bestofn_swarm/wire/protocol.py`` (refs
  inlined), message encoding ``json``, the payload bytes as they were on the wire. Radio
  samples are recorded as ``{"meta": <attachment>, "payload": <payload>}``; camera frames
  as ``foxglove.CompressedImage``;
* log time = sim time: ``tick * dt`` for every message that carries a tick, the latest
  ``world/clock`` for the rest (process logs); publish time = the wall time of arrival;
* derived Foxglove topics ``<prefix>/foxglove/{scene,transforms,log}``: the arena as a
  ``foxglove.SceneUpdate`` at every ``world/state``, robot poses as
  ``foxglove.FrameTransforms`` every tick, process logs as ``foxglove.Log``; and the
  swarm's curves as ``<prefix>/foxglove/swarm`` (``bestofn.SwarmSample``: robots decided,
  each site's share of the swarm's opinion, mean entropy, poolings), one message per world
  state at its sim time, fields a Plot panel draws (``.decided``, ``.shares[0]``);
* a sample that fails its tag (in a keyed run), or to decode or validate, is counted;
  the first ``REJECTED_KEPT`` of them go, base64-encoded with their key, the reason and
  their first ``REJECTED_SAMPLE_BYTES`` bytes, to the ``<prefix>/recorder/rejected``
  channel. Junk costs a recording a few hundred kilobytes at most, however much is sent;
* metadata records: ``bestofn.start`` when recording begins (configuration, versions,
  seed, layout, world info) and ``bestofn.run`` at the end (the same, the recorder's
  counts, and the run summary when the launcher sent one).
"""

from __future__ import annotations

import base64
import contextlib
import functools
import importlib.metadata
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO, Any, NamedTuple

import msgspec
from mcap.writer import CompressionType, Writer

from bestofn_swarm.wire import auth, batch, keyspace, names, protocol
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.core.pooling import LINK_SECONDS, Pooling
from world_server.observer.frame import FrameCollector, swarm_sample
from world_server.observer.observer import RunObserver
from world_server.recording import foxglove
from world_server.recording.description import RunDescription, layout_description, versions
from world_server.recording.records import (
    REJECTED,
    RUN_METADATA,
    START_METADATA,
    SWARM,
    RejectedSample,
    classify,
    message_schema,
    schema_name,
)

log = logging.getLogger("recorder")

# A crash loses at most the chunk being filled. The MCAP writer keeps every chunk's index
# (an offset per channel in the chunk, channels being per robot) until the file is closed,
# so small chunks of a large swarm grow the recorder with the run: at 1000 robots, 256 KiB
# chunks held about as many bytes of index in memory as they wrote to the file. A chunk
# grows with the swarm instead, keeping a crash's loss at about the same sim time.
CHUNK_BYTES = 256 * 1024  # up to 64 robots
CHUNK_BYTES_PER_ROBOT = 4 * 1024
# Rejected samples: every one counted, the first REJECTED_KEPT kept, each cut to this size.
REJECTED_KEPT, REJECTED_SAMPLE_BYTES = 100, 1024
# Keys of the protocol a recorder routes, at most: a run has a few per robot (sense, act,
# status, camera, radio, log) and a few of its own. A sample on a key beyond them is
# rejected, so that samples on ever new keys cannot grow the recorder.
KEYS_PER_ROBOT, KEYS_OF_A_RUN = 16, 256


def chunk_bytes(robots: int) -> int:
    """The uncompressed size of a recording's chunks for a swarm of ``robots``."""
    return max(CHUNK_BYTES, robots * CHUNK_BYTES_PER_ROBOT)


@dataclass
class _Channel:
    id: int | None  # None until its first message: a key that only carries junk gets none
    kind: keyspace.KeyKind | str  # a kind of the key table, or a derived topic's schema
    robot: int | None = None
    sequence: int = 0
    topic: str = ""
    ident: str | None = None  # the name the key gives

    @property
    def counted_as(self) -> str:
        return self.kind if isinstance(self.kind, str) else self.kind.name


class Sample(NamedTuple):
    """One sample as it arrived (in the recorder, a Zenoh sample as its callback copied it)."""

    key: str
    payload: bytes
    attachment: bytes | None
    wall_ns: int  # wall time of arrival: the MCAP publish time


class McapRecorder:
    """Writes one run's samples to an MCAP stream. Not thread-safe: one writer thread."""

    def __init__(
        self,
        stream: IO[bytes] | None,
        keys: keyspace.Keys,
        run: RunDescription,
        info: protocol.WorldInfo | None = None,
        *,
        chunk_size: int | None = None,
        writer: Any = None,
        keyring: auth.Keyring | None = None,
    ) -> None:
        """``writer``: where records go instead of an MCAP file in ``stream``; any object
        with ``mcap.writer.Writer``'s methods (Foxglove live passes one;
        deploy/viewer/foxglove_live.py).
        """
        self.keys = keys
        self.keyring = keyring  # None: an unauthenticated run, every tag-less sample taken
        self.run = run
        self.info = info
        self.layout = make_layout(run.sites, run.robots, run.seed)
        self.scene = foxglove.ArenaScene(
            self.layout, info.robot_radius if info is not None else EPUCK.radius
        )
        self.dt_ns = round(info.dt * 1e9) if info is not None else 0
        self.sim_ns = 0
        self.counts: dict[str, int] = {}
        self.rejected = 0
        self.closed = False
        self._versions = versions()
        if writer is None:
            if stream is None:
                raise ValueError("a recorder needs a stream to write to, or a writer")
            if chunk_size is None:
                chunk_size = chunk_bytes(run.robots)
            writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer = writer
        self._writer.start(library=f"bestofn-swarm recorder, {self._writer_library()}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, _Channel] = {}
        self._routes: dict[str, tuple[Callable[[Sample], None], str | None]] = {}
        self._max_routes = KEYS_PER_ROBOT * run.robots + KEYS_OF_A_RUN
        self._host_prefix = f"{keys.prefix}/host/"
        self._encoder = msgspec.json.Encoder()
        # Scene state: the run's observer (the latest pose and status of each robot, whom each
        # pooling joined, as the live page sees it) and the pooling links drawn.
        # The swarm's curves: a collector the observer feeds, swarm rows only.
        self.curves = FrameCollector(
            len(self.layout.sites), self.layout.best_site, robot_rows=False, keep=False
        )
        self.observer = RunObserver(
            range(run.robots), poolings=True, open_roster=True, series=self.curves
        )
        self._pose_batch: list[tuple[int, float, float, float]] = []
        self._pose_batch_ns = 0
        self._links: dict[int, tuple[int, list[foxglove.Segment]]] = {}  # robot -> (when, links)
        self._writer.add_metadata(START_METADATA, self._description())

    @staticmethod
    def _writer_library() -> str:
        try:
            return f"mcap-python {importlib.metadata.version('mcap')}"
        except importlib.metadata.PackageNotFoundError:
            return "mcap-python"

    def _description(self) -> dict[str, str]:
        run = self.run
        return {
            "run_id": run.run_id,
            "root": self.keys.root,
            "seed": str(run.seed),
            "robots": str(run.robots),
            "sites": str(run.sites),
            "config": json.dumps(run.config),
            "versions": json.dumps(self._versions),
            "layout": json.dumps(layout_description(self.layout)),
            "world_info": protocol.encode(self.info).decode() if self.info is not None else "",
            "foxglove_schemas": foxglove.SCHEMA_SOURCE,
        }

    # --- channels ------------------------------------------------------------------

    def _schema_id(self, name: str, schema: dict[str, Any]) -> int:
        schema_id = self._schemas.get(name)
        if schema_id is None:
            data = json.dumps(schema, separators=(",", ":")).encode()
            schema_id = self._writer.register_schema(name, "jsonschema", data)
            self._schemas[name] = schema_id
        return schema_id

    def _channel(self, topic: str, kind: str) -> _Channel:
        channel = self._channels.get(topic)
        if channel is None:
            channel = _Channel(None, kind, topic=topic)
            self._register(channel)
        return channel

    def _register(self, channel: _Channel) -> int:
        kind = channel.kind
        if isinstance(kind, str) and kind in foxglove.SCHEMA_NAMES:
            schema_id = self._schema_id(kind, foxglove.schema(kind))
        else:
            schema_id = self._schema_id(schema_name(kind), message_schema(kind))
        channel.id = self._writer.register_channel(channel.topic, "json", schema_id)
        self._channels[channel.topic] = channel
        return channel.id

    def _write(self, channel: _Channel, log_ns: int, data: bytes, wall_ns: int) -> None:
        channel_id = self._register(channel) if channel.id is None else channel.id
        self._writer.add_message(channel_id, log_ns, data, wall_ns, channel.sequence)
        channel.sequence += 1
        counted = channel.counted_as
        self.counts[counted] = self.counts.get(counted, 0) + 1

    def _write_derived(
        self, leaf: str, schema: str, log_ns: int, message: Any, wall_ns: int
    ) -> None:
        channel = self._channel(f"{self.keys.prefix}/foxglove/{leaf}", schema)
        self._write(channel, log_ns, self._encoder.encode(message), wall_ns)

    # --- samples -------------------------------------------------------------------

    def record(self, sample: Sample) -> None:
        """Record one sample, in the order samples arrived; a batch (``host/<first>/sense``
        or ``act``, bestofn_swarm/wire/batch.py) as the robots' own messages it carries."""
        if sample.key.startswith(self._host_prefix):
            self._record_batch(sample)
        else:
            self._record_one(sample)

    def _record_one(self, sample: Sample, checked: bool = False) -> None:
        """Record a sample whose tag is checked here, or was with its batch (``checked``)."""
        route = self._routes.get(sample.key)
        if route is None:
            route = self._route(sample.key)
            if route[1] is not None:  # a key of the protocol: kept, up to a run's number
                if len(self._routes) >= self._max_routes:
                    self.reject(sample, f"more keys than a run of {self.run.robots} has")
                    return
                self._routes[sample.key] = route
        handler, speaker = route
        try:
            if self.keyring is not None and speaker is not None and not checked:
                try:
                    metadata = self.keyring.open(
                        speaker, sample.key, sample.payload, sample.attachment
                    )
                except auth.AuthError as error:
                    self.reject(sample, f"{speaker}: {error}")
                    return
                sample = sample._replace(attachment=metadata or None)
            handler(sample)
        except Exception as error:  # a recorder bug must not cost the rest of the run
            log.exception("failed to record a sample on %s", sample.key)
            self.reject(sample, f"recorder error: {error!r}")

    def _record_batch(self, sample: Sample) -> None:
        """A batch, checked against its host's tag, as the JSON messages of its robots (the
        same bytes as each robot's own message on its key)."""
        found = keyspace.classify(self.keys, sample.key)
        first = None if found is None else found.robot
        if found is None or first is None or found.kind.recorded is not keyspace.Recorded.BATCH:
            self.reject(sample, "not a key of the protocol")
            return
        of_senses = found.kind is keyspace.HOST_SENSE
        try:
            entries: list[tuple[int, msgspec.Struct]]
            if of_senses:
                senses = batch.decode_senses(sample.payload)
                last, entries = senses.last, list(zip(senses.robots, senses.senses, strict=True))
            else:
                acts = batch.decode_acts(sample.payload)
                last, entries = acts.last, list(acts.acts)
            identity = names.host_identity(first, last)
        except (protocol.ProtocolError, ValueError) as error:
            self.reject(sample, f"batch: {error}")
            return
        if self.keyring is not None:
            try:
                self.keyring.open(identity, sample.key, sample.payload, sample.attachment)
            except auth.AuthError as error:
                self.reject(sample, f"{identity}: {error}")
                return
        per_robot = keyspace.SENSE if of_senses else keyspace.ACT
        for robot, message in entries:
            if not first <= robot <= last:
                self.reject(sample, f"batch: robot {robot} is not one {identity} hosts")
                continue
            entry = Sample(
                self.keys.of(per_robot, robot), protocol.encode(message), None, sample.wall_ns
            )
            self._record_one(entry, checked=True)

    def _route(self, key: str) -> tuple[Callable[[Sample], None], str | None]:
        """How to record a sample on ``key``, and whose tag it must carry (None: the key
        is none of the protocol's, and every sample on it is rejected)."""
        found = classify(self.keys, key)
        if found is None:
            return functools.partial(self.reject, reason="not a key of the protocol"), None
        speaker = found.speaker  # whose key tags the key: the key table says
        if speaker is None or not names.is_identity(speaker):
            return functools.partial(self.reject, reason="no identity of the run"), None
        channel = _Channel(None, found.kind, found.robot, topic=key, ident=found.ident)
        return functools.partial(self._record_kind, channel), speaker

    def _tick_ns(self, tick: int) -> int:
        return tick * self.dt_ns if self.dt_ns else self.sim_ns

    def reject(self, sample: Sample, reason: str) -> None:
        """Count a sample that is not a valid message; keep the first few, cut short, raw,
        on the rejected channel."""
        self.rejected += 1
        if self.rejected <= 10:
            log.warning("recording a sample on %s as rejected: %s", sample.key, reason[:200])
        if self.rejected > REJECTED_KEPT:
            return

        def head(data: bytes) -> str:
            return base64.b64encode(data[:REJECTED_SAMPLE_BYTES]).decode("ascii")

        record = RejectedSample(
            key=sample.key[:1000],
            reason=reason[:1000],
            payload=head(sample.payload),
            attachment=head(sample.attachment) if sample.attachment is not None else None,
            payload_bytes=len(sample.payload),
        )
        channel = self._channel(f"{self.keys.prefix}/recorder/rejected", REJECTED)
        self._write(channel, self.sim_ns, self._encoder.encode(record), sample.wall_ns)

    def _record_kind(self, channel: _Channel, sample: Sample) -> None:
        """Record one sample of a kind of the key table as the table says a recording keeps
        it, once it passed the table's gate; and what the scene derives from it."""
        kind = channel.kind
        assert isinstance(kind, keyspace.KeyKind)
        try:
            opened = keyspace.open_message(kind, channel.ident, sample.payload, sample.attachment)
        except keyspace.SampleError as error:
            self.reject(sample, str(error))
            return
        if kind.recorded is keyspace.Recorded.CHECKED:
            return  # a beacon's clock: world/clock's message of that tick, recorded there
        if kind is keyspace.CAMERA and len(sample.payload) > protocol.MAX_CAMERA_FRAME_BYTES:
            self.reject(sample, f"camera frame of {len(sample.payload)} bytes")
            return
        timed = opened.meta if opened.meta is not None else opened.message
        tick = getattr(timed, "tick", None)
        if kind is keyspace.CLOCK and not self.dt_ns and tick:
            self.dt_ns = round(opened.message.t * 1e9 / tick)
        if tick is None:
            ns = self.sim_ns
        elif kind is keyspace.CLOCK and not self.dt_ns:
            ns = round(opened.message.t * 1e9)
        else:
            ns = self._tick_ns(tick)
        if kind.recorded is keyspace.Recorded.RADIO:
            assert sample.attachment is not None  # the gate refused a missing one
            data = b'{"meta":' + sample.attachment + b',"payload":' + sample.payload + b"}"
        elif kind.recorded is keyspace.Recorded.IMAGE:
            frame_id = f"{foxglove.robot_frame(channel.robot or 0)}/camera"
            image = foxglove.compressed_image(ns, frame_id, sample.payload, opened.meta.encoding)
            data = self._encoder.encode(image)
        else:
            data = sample.payload
        if kind is keyspace.CLOCK:
            self.sim_ns = max(self.sim_ns, ns)
        self._write(channel, ns, data, sample.wall_ns)
        self._derive(opened, ns, sample.wall_ns)

    def _derive(self, opened: keyspace.Opened, ns: int, wall_ns: int) -> None:
        """What the Foxglove scene and log derive from a recorded sample, fed to the run's
        observer first."""
        kind, message, robot = opened.kind, opened.message, opened.robot
        run = self.observer
        if kind is keyspace.RADIO_RX:
            if robot is not None:
                run.delivery(robot, opened.meta.sender, self._tick_ns(opened.meta.tick) / 1e9)
            return
        if kind is keyspace.STATUS:
            assert robot is not None
            previous = self._view(robot)
            try:
                noted = run.status(message)
            except keyspace.SampleError:
                return  # recorded as it came; the scene keeps the robot's latest
            if noted.pooling is not None:
                self._note_links(noted.pooling, ns)
            view = self._view(robot)
            if (view.phase, view.decided_site) != (previous.phase, previous.decided_site):
                update = self.scene.robot_update(ns, robot, view)
                self._write_derived("scene", foxglove.SCENE_UPDATE, ns, update, wall_ns)
        elif kind is keyspace.CLOCK:
            run.clock(message)
            self._flush_poses(wall_ns)
        elif kind is keyspace.SENSE:
            assert robot is not None
            if ns != self._pose_batch_ns:
                self._flush_poses(wall_ns)
                self._pose_batch_ns = ns
            self._pose_batch.append((robot, message.x, message.y, message.theta))
            run.poses[robot] = (message.x, message.y, message.theta)
        elif kind is keyspace.STATE:
            with contextlib.suppress(keyspace.SampleError):
                run.state(message)
            recent = ns - round(LINK_SECONDS * 1e9)  # as long as the live page draws one
            segments = [
                segment
                for pooled_ns, robot_segments in self._links.values()
                if pooled_ns >= recent
                for segment in robot_segments
            ]
            views = {robot: self._view(robot) for robot in run.poses}
            update = self.scene.update(ns, views, segments)
            self._write_derived("scene", foxglove.SCENE_UPDATE, ns, update, wall_ns)
            self._write_curves(wall_ns)
        elif kind is keyspace.LOG:
            log_line = foxglove.log_message(self.sim_ns, message.process, message.line)
            self._write_derived("log", foxglove.LOG, self.sim_ns, log_line, wall_ns)

    def _write_curves(self, wall_ns: int) -> None:
        """The swarm rows finished, each at its sample's sim time."""
        for row in self.curves.take()[1]:
            sample = swarm_sample(row)
            ns = self._tick_ns(sample.tick) if self.dt_ns else round(sample.t * 1e9)
            self._write_derived(SWARM, SWARM, ns, sample, wall_ns)

    def _view(self, robot: int) -> foxglove.SceneRobot:
        """What the scene shows of a robot: its latest status, as the observer has it."""
        record = self.observer.records.get(robot)
        status = None if record is None else record.status
        if status is None:
            return foxglove.SceneRobot()
        return foxglove.SceneRobot(status.phase, status.decided_site, status.trips, status.poolings)

    def _flush_poses(self, wall_ns: int) -> None:
        """All robots' poses of one tick as one ``foxglove.FrameTransforms``."""
        if self._pose_batch:
            message = foxglove.frame_transforms(self._pose_batch_ns, self._pose_batch)
            self._write_derived(
                "transforms", foxglove.FRAME_TRANSFORMS, self._pose_batch_ns, message, wall_ns
            )
            self._pose_batch = []

    def _note_links(self, pooling: Pooling, ns: int) -> None:
        """The radio links of a pooling: to every robot whose opinion it joined."""
        poses = self.observer.poses
        here = poses.get(pooling.robot)
        if here is None:
            return
        segments = [
            ((here[0], here[1]), (poses[other][0], poses[other][1]))
            for other in pooling.members
            if other in poses
        ]
        self._links[pooling.robot] = (ns, segments)

    # --- the end -------------------------------------------------------------------

    def finish(self, summary: Any = None, finished_by: str = "finish query") -> None:
        """Write the run's metadata record and close the MCAP file's summary section."""
        if self.closed:
            return
        self._flush_poses(time.time_ns())
        self.curves.finish()
        self._write_curves(time.time_ns())
        record = self._description()
        record["finished_by"] = finished_by
        record["recorder"] = json.dumps(
            {
                "messages": dict(sorted(self.counts.items())),
                "rejected": self.rejected,
                "channels": len(self._channels),
            }
        )
        if summary is not None:
            record["summary"] = summary if isinstance(summary, str) else json.dumps(summary)
        self._writer.add_metadata(RUN_METADATA, record)
        self._writer.finish()
        self.closed = True
