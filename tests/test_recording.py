"""Recordings: a real short run read back with mcap's reader, every message validated.

One module-scoped run (3 robots, 5 sites, loopback, hard timeout) is recorded; the tests
read it back and check schemas, Foxglove types, metadata, timing and message counts. The
recorder's own decisions (rejected samples, a stop by signal) are tested on their own.
"""

from __future__ import annotations

import base64
import io
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from swarm_helpers import REPO, kill_leftovers, loopback_router, run_swarm, unique_run_id

from bestofn_swarm.wire import keyspace, protocol
from bestofn_swarm.wire.names import Role
from deploy.reports import audit, collect, report
from world_server.core.layout import make_layout
from world_server.core.palette import site_colour
from world_server.recorder import options as recorder_options
from world_server.recording import foxglove, records, writer
from world_server.recording.description import RunDescription

ROBOTS, SITES, SEED = 3, 5, 3
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FOXGLOVE_TOPICS = {
    "foxglove/scene": foxglove.SCENE_UPDATE,
    "foxglove/transforms": foxglove.FRAME_TRANSFORMS,
    "foxglove/log": foxglove.LOG,
}


class Run:
    def __init__(self, path: Path, run_id: str, summary: dict[str, Any]) -> None:
        self.path = path
        self.run_id = run_id
        self.summary = summary
        self.keys = keyspace.Keys(run_id)
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            contents = reader.get_summary()
            assert contents is not None and contents.statistics is not None
            self.statistics = contents.statistics
            self.messages: list[tuple[Schema, Channel, Message]] = []
            for schema, channel, message in reader.iter_messages():
                assert schema is not None, f"{channel.topic} has no schema"
                self.messages.append((schema, channel, message))
            self.metadata = {record.name: record.metadata for record in reader.iter_metadata()}

    def of_schema(self, name: str) -> list[tuple[Any, Any, dict[str, Any]]]:
        return [
            (channel, message, json.loads(message.data))
            for schema, channel, message in self.messages
            if schema.name == name
        ]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    path = tmp_path_factory.mktemp("recording") / "run.mcap"
    run_id = unique_run_id("rec")
    code, summary, stderr = run_swarm(
        [
            "--robots",
            str(ROBOTS),
            "--sites",
            str(SITES),
            "--seed",
            str(SEED),
            "--timeout",
            "900",
            "--record",
            str(path),
        ],
        run_id,
        timeout=120.0,
    )
    assert code == 0, stderr
    assert summary["recording"] == str(path)
    return Run(path, run_id, summary)


@pytest.mark.timeout(180)
def test_every_message_validates_against_its_channels_json_schema(run: Run) -> None:
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    for schema, channel, message in run.messages:
        assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
        validator = validators.get(schema.id)
        if validator is None:
            document = json.loads(schema.data)
            jsonschema.Draft202012Validator.check_schema(document)
            validator = validators[schema.id] = jsonschema.Draft202012Validator(document)
        validator.validate(json.loads(message.data))
    assert len(run.messages) == run.statistics.message_count > 1000


@pytest.mark.timeout(180)
def test_one_channel_per_key_with_its_protocol_schema(run: Run) -> None:
    topics = Counter(
        channel.topic
        for _, channel, _ in {
            (schema.id, channel.id): (schema, channel, None) for schema, channel, _ in run.messages
        }.values()
    )
    assert all(count == 1 for count in topics.values())
    by_topic = {channel.topic: schema for schema, channel, _ in run.messages}
    keys = run.keys
    expected = {
        keys.of(keyspace.CLOCK): "bestofn.Clock",
        keys.of(keyspace.STATE): "bestofn.WorldState",
        keys.of(keyspace.ACK, "nest"): "bestofn.Ack",
        keys.of(keyspace.RADIO_TX, "nest"): "bestofn.RadioTxRecord",
        keys.of(keyspace.LOG, "world"): "bestofn.LogLine",
    }
    for robot in range(ROBOTS):
        expected |= {
            keys.of(keyspace.SENSE, robot): "bestofn.Sense",
            keys.of(keyspace.ACT, robot): "bestofn.Act",
            keys.of(keyspace.STATUS, robot): "bestofn.Status",
            keys.of(keyspace.CAMERA, robot): foxglove.COMPRESSED_IMAGE,
            keys.of(keyspace.RADIO_TX, robot): "bestofn.RadioTxRecord",
            keys.of(keyspace.RADIO_RX, robot): "bestofn.RadioRxRecord",
        }
    for topic, name in expected.items():
        assert by_topic[topic].name == name, topic
    # The schemas are the protocol's own definitions, not a second copy.
    assert json.loads(by_topic[keys.of(keyspace.SENSE, 0)].data) == records.inline_refs(
        protocol.json_schema(protocol.Sense)
    )
    assert "$ref" not in by_topic[keys.of(keyspace.STATE)].data.decode()
    assert not [topic for topic in by_topic if topic.endswith("recorder/rejected")]


@pytest.mark.timeout(180)
def test_foxglove_channels_use_the_official_schemas(run: Run) -> None:
    by_name = {schema.name: schema for schema, _, _ in run.messages}
    for name in foxglove.SCHEMA_NAMES:
        official = json.loads((foxglove.SCHEMA_DIR / f"{name.split('.')[1]}.json").read_text())
        assert json.loads(by_name[name].data) == official
        assert official["title"] == name
    topics = {channel.topic: schema.name for schema, channel, _ in run.messages}
    for leaf, name in FOXGLOVE_TOPICS.items():
        assert topics[f"{run.keys.prefix}/{leaf}"] == name


@pytest.mark.timeout(180)
def test_foxglove_messages_carry_the_required_fields_and_the_run(run: Run) -> None:
    images = run.of_schema(foxglove.COMPRESSED_IMAGE)
    assert images
    for _, message, image in images:
        assert set(image) == {"timestamp", "frame_id", "data", "format"}
        assert image["format"] == "png" and base64.b64decode(image["data"]).startswith(PNG_MAGIC)
        assert image["timestamp"]["sec"] * 10**9 + image["timestamp"]["nsec"] == message.log_time
    layout = make_layout(SITES, ROBOTS, SEED)
    scenes = run.of_schema(foxglove.SCENE_UPDATE)
    full = [scene for _, _, scene in scenes if len(scene["entities"]) > 1]
    assert full
    entities = {entity["id"]: entity for entity in full[-1]["entities"]}
    assert {"arena", "radio-links", *(f"robot-{robot}" for robot in range(ROBOTS))} <= set(entities)
    panels = entities["arena"]["cubes"]
    assert [panel["color"] for panel in panels] == [
        foxglove.colour(site_colour(site.id, SITES)) for site in layout.sites
    ]
    labels = [text["text"] for text in entities["arena"]["texts"]]
    assert f"site {layout.best_site}\nrho = 1.00" in labels
    robot = entities["robot-0"]
    assert robot["frame_id"] == "robot-0" and robot["frame_locked"] is True
    links = [
        entity
        for scene in full
        for entity in scene["entities"]
        if entity["id"] == "radio-links" and entity["lines"]
    ]
    assert links and all(len(entity["lines"][0]["points"]) % 2 == 0 for entity in links)
    transforms = run.of_schema(foxglove.FRAME_TRANSFORMS)
    children = {t["child_frame_id"] for _, _, message in transforms for t in message["transforms"]}
    assert children == {f"robot-{robot}" for robot in range(ROBOTS)}
    assert all(
        t["parent_frame_id"] == foxglove.ARENA_FRAME
        for _, _, message in transforms
        for t in message["transforms"]
    )
    logs = run.of_schema(foxglove.LOG)
    names = {entry["name"] for _, _, entry in logs}
    # A robot process is named after the robots it hosts: robot-0, or robot-0-2 for 0 to 2.
    assert names >= {"world", "beacon"} and any(name.startswith("robot-0") for name in names)
    assert foxglove.LOG_INFO in {entry["level"] for _, _, entry in logs}
    # Lines from before the recorder listened are held back and recorded, in order.
    world_lines = [entry["message"] for _, _, entry in logs if entry["name"] == "world"]
    assert "listening on" in world_lines[0] and "waiting for" in world_lines[1]


@pytest.mark.timeout(180)
def test_log_time_is_sim_time_and_publish_time_is_wall_time(run: Run) -> None:
    dt_ns = 100_000_000  # the world's default tick
    for _, message, sense in run.of_schema("bestofn.Sense"):
        assert message.log_time == sense["tick"] * dt_ns
    for _, message, record in run.of_schema("bestofn.RadioRxRecord"):
        assert message.log_time == record["meta"]["tick"] * dt_ns
    now = time.time_ns()
    publish = [message.publish_time for _, _, message in run.messages]
    assert now - 600 * 10**9 < min(publish) <= max(publish) <= now
    assert max(message.log_time for _, _, message in run.messages) >= round(
        run.summary["sim_time_s"] * 1e9
    )


@pytest.mark.timeout(180)
def test_metadata_holds_config_versions_seed_and_summary(run: Run) -> None:
    start, final = run.metadata[records.START_METADATA], run.metadata[records.RUN_METADATA]
    for record in (start, final):
        assert record["run_id"] == run.run_id and record["seed"] == str(SEED)
        assert record["robots"] == str(ROBOTS) and record["sites"] == str(SITES)
        config = json.loads(record["config"])
        assert config == run.summary["config"]
        versions = json.loads(record["versions"])
        assert versions["protocol"] == str(protocol.VERSION)
        assert {"python", "mcap", "eclipse-zenoh", "msgspec", "bestofn-swarm"} <= set(versions)
        assert (
            json.loads(record["layout"])["best_site"] == make_layout(SITES, ROBOTS, SEED).best_site
        )
        assert protocol.decode(record["world_info"].encode(), protocol.WorldInfo).seed == SEED
    assert json.loads(final["summary"]) == run.summary
    assert final["finished_by"] == "finish query"
    counts = json.loads(final["recorder"])
    assert counts["rejected"] == 0
    assert sum(counts["messages"].values()) == run.statistics.message_count


@pytest.mark.timeout(180)
def test_nothing_published_is_missing_from_the_recording(run: Run) -> None:
    recording = collect.read_recording(run.path)
    assert recording.complete and recording.problem is None
    found = audit.audit(recording)
    for kind, counts in found.items():
        assert counts["recorded"] == counts["expected"], kind
    assert found["radio/rx/*"]["recorded"] == run.summary["radio"]["delivered"] > 0
    assert found["robot/*/camera"]["recorded"] > 0
    rebuilt = collect.rebuild_summary(recording)
    assert rebuilt["per_robot"] == run.summary["per_robot"]
    # The recording's run is the run: the same digest, from its status messages alone.
    assert rebuilt["digest"] == run.summary["digest"]


@pytest.mark.timeout(180)
def test_a_cut_short_recording_still_gives_a_report(run: Run, tmp_path: Path) -> None:
    data = run.path.read_bytes()
    for fraction in (0.35, 0.7, 0.97):
        cut = tmp_path / f"cut-{fraction}.mcap"
        cut.write_bytes(data[: int(len(data) * fraction)])
        out = tmp_path / f"report-{fraction}"
        done = subprocess.run(
            [sys.executable, "-m", "deploy.cli", "report", str(cut), "--out", str(out), "--json"],
            capture_output=True,
            timeout=120,
            cwd=REPO,
        )
        assert done.returncode == 0, done.stderr.decode()
        assert "cut short" in done.stderr.decode()
        result = json.loads(done.stdout)
        (row,) = result["runs"]
        assert row["complete"] is False and row["run_id"] == run.run_id
        for name in (*report.FIGURES, "summary.csv", "summary.json"):
            assert (out / name).stat().st_size > 0
        if fraction < 0.9:  # the summary section and the final metadata are gone
            assert row["source"] == "status messages"
            assert row["robots"] == ROBOTS and row["sites"] == SITES


def _sample(key: str, payload: bytes, attachment: bytes | None = None) -> writer.Sample:
    return writer.Sample(key, payload, attachment, time.time_ns())


def test_samples_that_do_not_decode_are_kept_raw_on_the_rejected_channel() -> None:
    keys = keyspace.Keys("rejects")
    stream = io.BytesIO()
    mcap = writer.McapRecorder(stream, keys, RunDescription("rejects", 1, 2, 3))
    clock = protocol.encode(protocol.Clock(v=1, tick=5, t=0.5))
    bad = [
        _sample(keys.of(keyspace.SENSE, 0), b'{"v": 1, "tick": -1}'),
        _sample(keys.of(keyspace.RADIO_TX, 1), b"{}", None),
        _sample(keys.of(keyspace.CAMERA, 0), b"\x89PNG", b"not json"),
        _sample(f"{keys.prefix}/nonsense", b"x"),
    ]
    for sample in [_sample(keys.of(keyspace.CLOCK), clock), *bad]:
        mcap.record(sample)
    mcap.finish()
    stream.seek(0)
    reader = make_reader(stream)
    rejected = [
        (channel.topic, json.loads(message.data))
        for schema, channel, message in reader.iter_messages()
        if schema is not None and schema.name == "bestofn.RejectedSample"
    ]
    assert [record["key"] for _, record in rejected] == [sample.key for sample in bad]
    assert {topic for topic, _ in rejected} == {f"{keys.prefix}/recorder/rejected"}
    assert base64.b64decode(rejected[0][1]["payload"]) == bad[0].payload
    assert rejected[2][1]["attachment"] == base64.b64encode(b"not json").decode()
    assert mcap.rejected == len(bad) and mcap.counts == {"clock": 1, "rejected": len(bad)}
    schema = records.message_schema("rejected")
    for _, record in rejected:
        jsonschema.validate(record, schema)


@pytest.mark.parametrize("niceness", ["-1", "20", "low"])
def test_a_bad_niceness_is_a_usage_error(niceness: str, tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        recorder_options.build_parser().parse_args(
            ["--out", str(tmp_path / "x.mcap"), "--niceness", niceness]
        )
    assert exit_info.value.code == 2


@pytest.mark.timeout(60)
def test_sigterm_without_a_finish_query_closes_the_file_cleanly(tmp_path: Path) -> None:
    run_id = unique_run_id("rec-term")
    keys = keyspace.Keys(run_id)
    out = tmp_path / "term.mcap"
    with loopback_router() as (session, endpoint):
        process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "world_server.recorder",
                "--run-id",
                run_id,
                "--mode",
                "client",
                "--connect",
                endpoint,
                "--out",
                str(out),
                "--robots",
                "2",
                "--sites",
                "4",
                "--info-timeout",
                "0.5",
                "--config-json",
                '{"robots": 2}',
            ],
            cwd=REPO,
            stderr=subprocess.PIPE,
        )
        try:
            deadline = time.monotonic() + 30
            while not list(session.liveliness().get(keys.token(Role.RECORDER, 0), timeout=1.0)):
                assert process.poll() is None and time.monotonic() < deadline
                time.sleep(0.05)
            # Recording yields the CPU to the swarm (it is off the barrier's critical path).
            expected_niceness = min(
                19, os.getpriority(os.PRIO_PROCESS, 0) + recorder_options.DEFAULT_NICENESS
            )
            assert os.getpriority(os.PRIO_PROCESS, process.pid) == expected_niceness
            for tick in range(1, 4):
                session.put(
                    keys.of(keyspace.CLOCK),
                    protocol.encode(protocol.Clock(v=1, tick=tick, t=tick * 0.1)),
                )
            time.sleep(0.5)
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=20) == 0
        finally:
            process.kill()
            process.wait()
            kill_leftovers(run_id)
    with open(out, "rb") as stream:
        reader = make_reader(stream)
        clocks = [json.loads(m.data)["tick"] for _, _, m in reader.iter_messages()]
        final = {record.name: record.metadata for record in reader.iter_metadata()}
    assert clocks == [1, 2, 3]
    record = final[records.RUN_METADATA]
    assert record["finished_by"] == "signal" and "summary" not in record
    assert json.loads(record["config"]) == {"robots": 2}


# --- waiting for a recorder that fell behind ------------------------------------------


def test_a_query_is_waited_for_while_worth_it_and_given_up_when_not() -> None:
    """The launcher's finish query waits beyond a short timeout while the recorder works,
    and gives up at once when the recorder stops making progress."""
    import threading

    from bestofn_swarm.plumbing.world_info import ask

    def answer_late(query: Any) -> None:
        def later() -> None:
            time.sleep(1.5)
            query.reply("test/late", b"done")
            query.drop()

        threading.Thread(target=later, daemon=True).start()

    with loopback_router() as (session, _):
        queryable = session.declare_queryable("test/late", answer_late)
        try:
            asked = []

            def still_working() -> bool:
                asked.append(time.monotonic())
                return True

            answers, _ = ask(
                session, "test/late", None, "launcher", timeout=20.0, worth_waiting=still_working
            )
            assert answers == [b"done"]
            assert 2 <= len(asked) <= 5  # polled every 0.5 s for the 1.5 s it took

            started = time.monotonic()
            answers, _ = ask(
                session, "test/late", None, "launcher", timeout=20.0, worth_waiting=lambda: False
            )
            assert answers == []
            assert time.monotonic() - started < 1.4  # given up before the answer came
        finally:
            queryable.undeclare()


def test_the_launcher_waits_for_the_recorder_while_its_file_grows(tmp_path: Path) -> None:
    from deploy.launcher.recording import RECORDER_REPORT_EVERY, RecorderProgress

    path = tmp_path / "run.mcap"
    path.write_bytes(b"x" * 100)
    now = [0.0]

    def clock() -> float:
        return now[0]

    lines: list[str] = []
    waiting = RecorderProgress(path, lambda: True, lines.append, patience=30.0, clock=clock)
    assert waiting()
    for _ in range(3):  # growing: worth waiting however long it takes
        now[0] += 20.0
        with path.open("ab") as stream:
            stream.write(b"x" * 2**20)
        assert waiting()
    assert len(lines) == 3  # one line every RECORDER_REPORT_EVERY seconds: here, every look
    assert lines[-1].endswith("3 MB written, 60 s so far")
    now[0] += 29.0  # not grown, but within the patience
    assert waiting()
    now[0] += 1.0  # no growth for the patience
    assert not waiting()
    assert "did not grow for 30 s (3 MB written)" in waiting.why_not()

    said: list[str] = []
    now[0] = 100.0
    quiet = RecorderProgress(path, lambda: True, said.append, clock=clock)
    now[0] += RECORDER_REPORT_EVERY - 1.0
    assert quiet() and said == []  # nothing said before RECORDER_REPORT_EVERY
    now[0] += 1.0
    assert quiet() and said == [
        "waiting for the recorder to write what it fell behind on: 3 MB written, 10 s so far"
    ]

    dead = RecorderProgress(path, lambda: False)
    assert not dead()
    assert dead.why_not() == "exited before it confirmed the file"


def test_the_recorder_yields_the_cpu_only_to_a_swarm_that_leaves_it_idle_time() -> None:
    from deploy.launcher.plan import ROBOTS_PER_PROCESS, recorder_niceness

    assert recorder_niceness(10) == recorder_options.DEFAULT_NICENESS == 10
    assert recorder_niceness(ROBOTS_PER_PROCESS) == 10  # one robot process
    assert recorder_niceness(ROBOTS_PER_PROCESS + 1) == 0  # it would fall behind for good
    assert recorder_niceness(500) == 0


def _index_entries(robots: int, ticks: int, chunk_size: int | None) -> tuple[int, int]:
    """(chunks, channel offsets held in their indexes) of a recording of ``robots``
    robots' senses over ``ticks`` ticks: what the MCAP writer keeps in memory to the end."""
    keys = keyspace.Keys("chunks")
    stream = io.BytesIO()
    mcap = writer.McapRecorder(
        stream, keys, RunDescription("chunks", 1, robots, 10), chunk_size=chunk_size
    )
    for tick in range(ticks):
        mcap.record(
            _sample(
                keys.of(keyspace.CLOCK),
                protocol.encode(protocol.Clock(v=1, tick=tick, t=tick / 10)),
            )
        )
        for robot in range(robots):
            sense = protocol.Sense(
                v=1, tick=tick, t=tick / 10, x=0.1, y=0.01 * robot, theta=0.0,
                prox=[0.0] * 8, rx=0, camera=False,
            )  # fmt: skip
            mcap.record(_sample(keys.of(keyspace.SENSE, robot), protocol.encode(sense)))
    mcap.finish()
    stream.seek(0)
    summary = make_reader(stream).get_summary()
    assert summary is not None
    chunks = summary.chunk_indexes
    return len(chunks), sum(len(chunk.message_index_offsets) for chunk in chunks)


def test_a_large_swarms_recorder_holds_a_small_index() -> None:
    """The writer keeps each chunk's index (an offset per channel in it) until the end, so
    a large swarm gets larger chunks: fewer of them, each indexing at most every channel."""
    assert writer.chunk_bytes(10) == writer.chunk_bytes(64) == writer.CHUNK_BYTES
    assert writer.chunk_bytes(1000) == 1000 * writer.CHUNK_BYTES_PER_ROBOT
    small_chunks, small_index = _index_entries(1000, 30, writer.CHUNK_BYTES)
    chunks, index = _index_entries(1000, 30, None)
    assert chunks * 6 <= small_chunks
    assert index * 4 <= small_index
