"""Byzantine robots (``--byzantine ROBOT[:MODE]``): the wrappers' behaviour on fakes, the
command line, the consensus rule, and a real run that agrees with the in-process one."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fakes import FakeSwarm, make_swarm
from mcap.reader import make_reader
from swarm_helpers import run_swarm, unique_run_id

from bestofn_swarm.wire import keyspace, names, protocol, settings
from bestofn_swarm.wire.rng import Stream
from deploy.cli import main as swarm_main
from robot_agent.core import byzantine, decision, ports
from robot_agent.core.byzantine import Behaviour, ByzantineRobot
from robot_agent.core.controller import ControllerConfig
from robot_agent.node import cli as node
from robot_agent.node import options
from robot_agent.node.options import RobotAgentConfig
from world_server.core.layout import make_layout
from world_server.observer.summary import (
    RobotRecord,
    RunOutcome,
    build_summary,
    byzantine_in_config,
)

# --- the wrappers, on a lone robot in the fake world -----------------------------------


def _lone(seed: int, sites: int, behaviour: Behaviour | None) -> tuple[FakeSwarm, Any]:
    swarm = make_swarm(1, sites, seed=seed)
    rng = Stream.named(seed, "robot", 0)
    robot = byzantine.build_controller(0, swarm.world.info, ControllerConfig(), rng, behaviour)
    return swarm, robot


def _drive(
    swarm: FakeSwarm,
    robot: ports.RobotController,
    until: Callable[[], bool],
    inject: bytes | None = None,
) -> list[protocol.OpinionPayload]:
    """Step ``robot`` until ``until()``; what it broadcast. ``inject`` is heard every step
    (a neighbour's opinion, from radio name 5)."""
    sent: list[protocol.OpinionPayload] = []
    body, radio = swarm.bodies[0], swarm.radios[0]
    for _ in range(20_000):
        if until():
            return sent
        if inject is not None:
            radio.inbox.append(("5", inject))
        command = ports.control_step(robot, body, radio, swarm.rejects[0])
        assert all(isinstance(p, protocol.OpinionPayload) for p in command.broadcasts)
        sent += [p for p in command.broadcasts if isinstance(p, protocol.OpinionPayload)]
        swarm.world.advance()
    raise AssertionError("the robot never got there")


def test_a_liar_broadcasts_certainty_of_its_site_every_trip_and_never_settles() -> None:
    sites, claimed = 5, 2
    swarm, liar = _lone(seed=12, sites=sites, behaviour=Behaviour("liar", claimed))
    # A neighbour certain of site 0 at every step: an honest robot would adopt it.
    neighbour = protocol.encode(
        protocol.OpinionPayload(
            v=1, id=5, trip=0, decided=True, opinion=byzantine.one_hot(0, sites)
        )
    )
    sent = _drive(swarm, liar, lambda: liar.status(0).trips >= 3, inject=neighbour)
    # Three visits to the nest, each broadcasting for the 3 s dwell every 0.5 s: 7 each.
    assert [payload.trip for payload in sent] == [0] * 7 + [1] * 7 + [2] * 7
    assert {tuple(payload.opinion) for payload in sent} == {(0.0, 0.0, 1.0, 0.0, 0.0)}
    assert all(payload.id == 0 and payload.decided for payload in sent)
    # It never decides, and it heard no opinion: its own stays uniform.
    status = liar.status(0)
    assert liar.decided_site is None and status.decided_site is None
    assert status.opinion == [0.2] * sites
    assert status.poolings == 3 and status.pool_size == 1


def test_a_liar_needs_its_site_and_a_site_of_the_world() -> None:
    swarm, _ = _lone(seed=1, sites=4, behaviour=None)
    info, config = swarm.world.info, ControllerConfig()
    with pytest.raises(ValueError, match="claims"):
        byzantine.build_controller(0, info, config, Stream(0), Behaviour("liar"))
    with pytest.raises(ValueError, match=r"outside 0\.\.3"):
        byzantine.build_controller(0, info, config, Stream(0), Behaviour("liar", 4))


def test_an_inverted_robot_eliminates_the_better_site_of_the_same_pair() -> None:
    seed, sites = 5, 5
    swarm, honest = _lone(seed, sites, None)
    _drive(swarm, honest, lambda: honest.status(0).comparison is not None)
    swarm_inverted, inverted = _lone(seed, sites, Behaviour("inverted"))
    _drive(swarm_inverted, inverted, lambda: inverted.status(0).comparison is not None)
    right, wrong = honest.status(0).comparison, inverted.status(0).comparison
    assert right is not None and wrong is not None
    qualities = swarm.world.qualities
    pair = (right.site_a, right.site_b)
    assert (wrong.site_a, wrong.site_b) == pair  # same seed, same pair
    assert qualities[pair[0]] != qualities[pair[1]]
    assert right.eliminated == min(pair, key=qualities.__getitem__)
    assert wrong.eliminated == max(pair, key=qualities.__getitem__)
    assert wrong.quality_a == pytest.approx(1.0 - right.quality_a)
    assert wrong.quality_b == pytest.approx(1.0 - right.quality_b)


def test_a_silent_robot_pools_and_decides_but_never_broadcasts() -> None:
    swarm, silent = _lone(seed=12, sites=4, behaviour=Behaviour("silent"))
    sent = _drive(swarm, silent, lambda: silent.decided_site is not None)
    assert sent == []
    assert silent.decided_site == swarm.best_site
    twin_swarm, twin = _lone(seed=12, sites=4, behaviour=None)
    assert len(_drive(twin_swarm, twin, lambda: twin.decided_site is not None)) == 3 * 7


def test_the_default_liar_site_is_seeded_never_the_best_and_shared() -> None:
    for seed in range(30):
        best = make_layout(6, 10, seed).best_site
        site = byzantine.default_liar_site(6, best, seed)
        assert site != best and 0 <= site < 6
        assert byzantine.default_liar_site(6, best, seed) == site
    assert len({byzantine.default_liar_site(6, 0, seed) for seed in range(30)}) == 5


def test_a_one_hot_opinion_is_final_under_both_pooling_operators() -> None:
    """The hole the liar uses (docs/byzantine.md): a certain opinion wins every pool that
    has no exact zero on its site, with MProdOp and with the log-linear pool alike."""
    claim = byzantine.one_hot(2, 4)
    distrustful = [0.4, 0.3, 0.2, 0.1]  # alpha > 0: no option is ever exactly zero
    for pool in (decision.mprodop, decision.loglinear_pool):
        assert pool([distrustful, claim]) == claim
        assert pool([distrustful, distrustful, distrustful, claim]) == claim
        # alpha = 0: a robot that already eliminated site 2 keeps its own opinion.
        assert pool([[0.5, 0.5, 0.0, 0.0], claim]) is None


# --- parsing --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "parsed"),
    [
        ("3", ByzantineRobot(3, Behaviour("liar"))),
        ("3:liar", ByzantineRobot(3, Behaviour("liar"))),
        ("0:liar=7", ByzantineRobot(0, Behaviour("liar", 7))),
        ("12:inverted", ByzantineRobot(12, Behaviour("inverted"))),
        ("1:silent", ByzantineRobot(1, Behaviour("silent"))),
    ],
)
def test_switches_parse_and_print_back(text: str, parsed: ByzantineRobot) -> None:
    assert ByzantineRobot.parse(text) == parsed
    assert ByzantineRobot.parse(str(parsed)) == parsed


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--byzantine", "10"], "there is no robot 10 in a swarm of 10"),
        (["--byzantine", "1:bogus"], "unknown Byzantine mode 'bogus'"),
        (["--byzantine", "x:liar"], "is not ROBOT[:MODE]"),
        (["--byzantine", "1:inverted=2"], "only a liar claims a site"),
        (["--byzantine", "1:liar=10"], "robot 1 would claim site 10: there are"),
        (["--byzantine", "1:liar=-1"], "must be a site id"),
        (["--byzantine", "1", "--byzantine", "1:silent"], "names robot 1 twice"),
    ],
)
@pytest.mark.parametrize("command", ["run", "experiment"])
def test_bad_switches_exit_with_code_2_and_one_line(
    command: str,
    arguments: list[str],
    message: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = ["--out", str(tmp_path / "out")] if command == "experiment" else ["--no-record"]
    with pytest.raises(SystemExit) as exit_info:
        swarm_main([command, *out, *arguments])
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert message in lines[-1] and sum("error" in line for line in lines) == 1
    assert not (tmp_path / "out").exists()  # nothing was started


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--id", "1", "--byzantine", "2:inverted"], "robot 2 is not hosted here"),
        (["--id", "1", "--byzantine", "1:liar"], "name the site it claims"),
        (["--id", "1", "--byzantine", "1:silent", "--byzantine", "1"], "names robot 1 twice"),
        (["--id", "1", "--byzantine", "1:lie"], "unknown Byzantine mode 'lie'"),
    ],
)
def test_robot_agent_refuses_bad_switches_with_code_2(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        node.main(arguments)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert message in lines[-1] and sum("error" in line for line in lines) == 1


def test_swarm_run_forwards_each_switch_only_to_the_process_hosting_the_robot(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from bestofn_swarm.plumbing.inbox import BoundedInbox
    from deploy.cli import build_parser
    from deploy.launcher.plan import plan_from_args
    from deploy.launcher.supervisor import Supervisor
    from deploy.security.credentials import RunNetwork

    parser = build_parser(["run"])
    seed, sites = 4, 6
    args = parser.parse_args(
        [
            *("run", "--no-record", "--seed", str(seed), "--sites", str(sites), "--robots", "4"),
            *("--byzantine", "1", "--byzantine", "2:inverted", "--robots-per-process", "2"),
        ]
    )
    plan = plan_from_args(args)
    liar_site = byzantine.default_liar_site(sites, make_layout(sites, 4, seed).best_site, seed)
    assert plan.byzantine_robots == {1: Behaviour("liar", liar_site), 2: Behaviour("inverted")}
    assert plan.config["byzantine"] == [f"1:liar={liar_site}", "2:inverted"]
    json.dumps(plan.config)  # the recorder gets the configuration as JSON
    started: list[list[str]] = []
    swarm = Supervisor(plan, BoundedInbox())
    monkeypatch.setattr(
        swarm.group, "fork", lambda name, module, argv, env=None: started.append(list(argv))
    )
    swarm.network = RunNetwork.create(plan.run_id, plan.robots, connect=None, keyed=True)
    try:
        swarm.start_robots([0, 1])
        swarm.start_robots([2, 3])
    finally:
        swarm.network.close()
    hosts = [argv[: argv.index("--run-id")] for argv in started]
    assert hosts == [["--id", "0", "--id", "1"], ["--id", "2", "--id", "3"]]
    handed = [
        settings.decode(argv[argv.index("--config") + 1], RobotAgentConfig) for argv in started
    ]
    assert [config.byzantine for config in handed] == [
        (ByzantineRobot(1, Behaviour("liar", liar_site)),),
        (ByzantineRobot(2, Behaviour("inverted")),),
    ]


def test_swarm_experiment_passes_byzantine_and_kill_switches_on_to_each_run() -> None:
    from deploy.cli import build_parser
    from deploy.launcher.experiment import plan_runs, validate_run_options

    parser = build_parser(["experiment"])
    args = parser.parse_args(
        [
            *("experiment", "--out", "x", "--runs", "1", "--sites", "5"),
            *("--byzantine", "1:liar=0", "--byzantine", "2", "--kill", "3@15.5"),
            *("--", "--robots-per-process", "1"),
        ]
    )
    (spec,) = plan_runs(args, "tcp/127.0.0.1:1")
    assert spec.argv[spec.argv.index("--kill") + 1] == "3@15.5"
    flags = [spec.argv[i + 1] for i, arg in enumerate(spec.argv) if arg == "--byzantine"]
    assert flags == ["1:liar=0", "2:liar"]
    validate_run_options(spec)  # each run's command line parses as swarm run's


# --- the consensus rule -----------------------------------------------------------------


def _records(decided: list[int | None]) -> list[RobotRecord]:
    records = []
    for robot, site in enumerate(decided):
        record = RobotRecord(robot)
        record.update(
            protocol.Status(
                v=1,
                id=robot,
                tick=1,
                t=10.0 + robot,
                phase="stopped" if site is not None else "to_site",
                trips=2,
                opinion=[0.5, 0.5],
                pool_size=1,
                poolings=2,
                decided_site=site,
                decision_time=10.0 + robot if site is not None else None,
                decision_trips=2 if site is not None else None,
                comparison=None,
                rejected=0,
            )
        )
        records.append(record)
    return records


def _outcome(byzantine_robots: dict[int, str]) -> RunOutcome:
    return RunOutcome(
        run_id="r",
        num_robots=3,
        num_sites=2,
        seed=0,
        best_site=1,
        sim_time_s=50.0,
        wall_time_s=1.0,
        timed_out=False,
        radio=protocol.RadioCounters(),
        world_rejected=0,
        stalls=0,
        observer_rejected=0,
        config={},
        byzantine=byzantine_robots,
    )


def test_consensus_and_its_time_are_the_honest_robots() -> None:
    summary = build_summary(_outcome({2: "liar=0"}), _records([1, 1, None]))
    assert (summary["consensus"], summary["chosen_site"], summary["correct"]) == (True, 1, True)
    assert summary["sim_time_s"] == 11.0  # the last honest robot's decision
    assert [robot["byzantine"] for robot in summary["per_robot"]] == [None, None, "liar=0"]
    # A Byzantine robot's decision neither makes nor breaks the consensus.
    summary = build_summary(_outcome({0: "inverted"}), _records([0, 1, 1]))
    assert (summary["consensus"], summary["correct"], summary["sim_time_s"]) == (True, True, 12.0)
    # Without Byzantine robots every robot counts, as before.
    summary = build_summary(_outcome({}), _records([0, 1, 1]))
    assert (summary["consensus"], summary["chosen_site"]) == (False, None)
    assert [robot["byzantine"] for robot in summary["per_robot"]] == [None, None, None]


def test_a_report_rebuilding_a_summary_reads_the_byzantine_robots_from_the_config() -> None:
    config = {"byzantine": ["1:liar=3", "4:inverted", "nonsense"]}
    assert byzantine_in_config(config) == {1: "liar=3", 4: "inverted"}
    assert byzantine_in_config({}) == {} == byzantine_in_config({"byzantine": "1"})


# --- a real run --------------------------------------------------------------------------


@pytest.mark.timeout(240)
def test_a_real_run_with_a_liar_and_an_inverted_robot_matches_the_in_process_run(
    tmp_path: Path,
) -> None:
    """Robot 1 lies (its default site), robot 2 reads qualities inverted; two robots per
    process. The recording shows robot 1's one-hot broadcasts; the results are the
    in-process engine's, robot by robot."""
    from deploy.inprocess.engine import run_in_process
    from world_server.server import cli as server

    seed, robots, sites = 1, 4, 5
    common = ["--seed", str(seed), "--robots", str(robots), "--sites", str(sites)]
    switches = {1: Behaviour("liar"), 2: Behaviour("inverted")}
    world_config = server.config_from_args(
        server.build_parser().parse_args([*common, "--run-id", "memory"])
    )
    controller_config = options.controller_config(node.build_parser().parse_args(["--id", "0"]))
    in_memory = run_in_process(
        world_config, controller_config, timeout=900, byzantine_robots=switches
    )
    path = tmp_path / "byzantine.mcap"
    code, summary, stderr = run_swarm(
        [
            *(*common, "--timeout", "900", "--record", str(path), "--robots-per-process", "2"),
            *("--byzantine", "1", "--byzantine", "2:inverted"),
            # A robot a busy machine starved is waited for: the run stays the seed's.
            *("--stall-timeout", "120"),
        ],
        unique_run_id("byzantine"),
        timeout=180.0,
    )
    assert code == 0, stderr
    liar_site = byzantine.default_liar_site(sites, summary["best_site"], seed)
    assert [robot["byzantine"] for robot in summary["per_robot"]] == [
        None,
        f"liar={liar_site}",
        "inverted",
        None,
    ]
    assert summary["config"]["byzantine"] == [f"1:liar={liar_site}", "2:inverted"]

    def results(run: dict[str, Any]) -> list[tuple[object, ...]]:
        return [
            (r["id"], r["decided_site"], r["steps"], r["decision_time_s"], r["pool_sizes"])
            for r in run["per_robot"]
        ]

    # The honest robots' results; a Byzantine robot that never decides goes on after the
    # honest consensus until the run is stopped, which the in-process run does at once.
    honest = [0, 3]
    assert [results(summary)[robot] for robot in honest] == [
        results(in_memory)[robot] for robot in honest
    ], {key: summary.get(key) for key in ("world", "ended", "stalls", "departures")}
    verdict = ("consensus", "chosen_site", "correct", "sim_time_s")
    assert [summary[key] for key in verdict] == [in_memory[key] for key in verdict]
    # This seed: the liar wins over both honest robots.
    assert (summary["consensus"], summary["chosen_site"]) == (True, liar_site)
    assert liar_site != summary["best_site"]

    keys = keyspace.Keys(summary["run_id"])
    broadcasts: dict[int, list[dict[str, Any]]] = {robot: [] for robot in range(robots)}
    with open(path, "rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            for robot in range(robots):
                if channel.topic == keys.of(keyspace.RADIO_TX, names.robot_name(robot)):
                    broadcasts[robot].append(json.loads(message.data)["payload"])
    claim = byzantine.one_hot(liar_site, sites)
    lies = broadcasts[1]
    # 7 broadcasts a nest visit (every 0.5 s of the 3 s dwell), each trip; the run was
    # stopped somewhere in the last one.
    per_trip = Counter(payload["trip"] for payload in lies)
    last = max(per_trip)
    assert sorted(per_trip) == list(range(last + 1))
    assert all(per_trip[trip] == 7 for trip in range(last)) and 1 <= per_trip[last] <= 7
    assert all(payload["opinion"] == claim and payload["decided"] for payload in lies)
    assert all(payload["id"] == 1 for payload in lies)
    # The honest robots were not certain of anything before they met the liar.
    assert broadcasts[0] and broadcasts[0][0]["opinion"] != claim
