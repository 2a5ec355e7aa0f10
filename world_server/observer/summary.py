"""What a run decided, gathered from robots' status messages (pure, no I/O)."""

from __future__ import annotations

import hashlib
import json
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.endings import Ending, Stop, TimeLimit, ending_of
from robot_agent.core import byzantine


@dataclass
class RobotRecord:
    """Everything the launcher learned about one robot from its status messages."""

    id: int
    status: protocol.Status | None = None
    pool_sizes: list[int] = field(default_factory=list)
    missed_poolings: int = 0
    restarts: int = 0
    crashed: bool = False
    killed: bool = False  # on purpose (--kill), not restarted
    outside: str | None = None  # the link's transport of a robot outside the emulator
    departed: bool = False  # outside, and its link was down when the run ended
    restarting: bool = False  # a fresh process was started and has not reported yet
    _poolings_before_restart: int = 0

    def update(self, status: protocol.Status) -> None:
        self.restarting = False
        known = len(self.pool_sizes) + self.missed_poolings - self._poolings_before_restart
        if status.poolings > known:
            self.missed_poolings += status.poolings - known - 1
            self.pool_sizes.append(status.pool_size)
        self.status = status

    def restarted(self) -> None:
        """A fresh process now runs this robot: its controller counts from zero again."""
        self.restarts += 1
        self.restarting = True
        self.crashed = False
        self._poolings_before_restart = len(self.pool_sizes) + self.missed_poolings

    @property
    def decided_site(self) -> int | None:
        if self.restarting or self.status is None:
            return None
        return self.status.decided_site


@dataclass(frozen=True)
class RunOutcome:
    run_id: str
    num_robots: int
    num_sites: int
    seed: int
    best_site: int
    sim_time_s: float  # sim time the launcher saw when it stopped the run
    wall_time_s: float
    timed_out: bool
    radio: protocol.RadioCounters
    world_rejected: int
    stalls: int
    observer_rejected: int
    config: dict[str, Any]
    stop: Stop | None = None  # None: not known (a summary rebuilt from a recording)
    timeout_kind: TimeLimit | None = None
    stuck: list[dict[str, Any]] = field(default_factory=list)
    beacon_rejected: int = 0
    byzantine: Mapping[int, str] = field(default_factory=dict)  # robot -> how it misbehaves
    departures: int = 0  # robots and beacons whose liveliness went mid-run (world's count)
    robot_processes: int = 0  # processes the robots were started in (0: in one process)
    links: Mapping[int, protocol.LinkStats] = field(default_factory=dict)  # outside robots


def build_summary(outcome: RunOutcome, records: Iterable[RobotRecord]) -> dict[str, Any]:
    """The ``swarm run --json`` object."""
    robots = sorted(records, key=lambda record: record.id)
    # Consensus is among the honest robots still running at the end: one killed on purpose
    # or crashed cannot hold up or spoil the swarm's decision (it is reported separately),
    # and a Byzantine robot's own decision is not the swarm's (docs/byzantine.md).
    survivors = [
        record
        for record in robots
        if not record.killed
        and not record.crashed
        and not record.departed
        and record.id not in outcome.byzantine
    ]
    decided = [record.decided_site for record in survivors]
    consensus = (
        bool(survivors) and all(site is not None for site in decided) and len(set(decided)) == 1
    )
    chosen = decided[0] if consensus else None
    wall = max(outcome.wall_time_s, 1e-9)
    decision_times = [
        r.status.decision_time for r in survivors if r.status and r.status.decision_time
    ]
    # The run's length in sim time is when its last robot decided (deterministic in
    # lockstep); the launcher notices a little later, which only the speed figure uses.
    all_decided = bool(survivors) and all(site is not None for site in decided)
    sim_time = max(decision_times) if all_decided and decision_times else outcome.sim_time_s
    ended = ending_of(outcome.stop, all_decided, consensus)
    summary: dict[str, Any] = {
        "run_id": outcome.run_id,
        "num_robots": outcome.num_robots,
        "num_sites": outcome.num_sites,
        "robot_processes": outcome.robot_processes,
        "seed": outcome.seed,
        "best_site": outcome.best_site,
        "consensus": consensus,
        "chosen_site": chosen,
        "correct": consensus and chosen == outcome.best_site,
        "timed_out": outcome.timed_out,
        "ended": None if ended is None else ended.value,
        "sim_time_s": round(sim_time, 3),
        "wall_time_s": round(outcome.wall_time_s, 3),
        "real_time_factor": round(outcome.sim_time_s / wall, 2),
        "radio": {
            "sent": outcome.radio.sent,
            "delivered": outcome.radio.delivered,
            "dropped": outcome.radio.dropped,
            "rejected": outcome.radio.rejected,
        },
        "world": {
            "rejected": outcome.world_rejected,
            "stalls": outcome.stalls,
            "departures": outcome.departures,
        },
        "rejected": {
            "world": outcome.world_rejected,
            "robots": sum(r.status.rejected for r in robots if r.status),
            "observer": outcome.observer_rejected,
            "beacon": outcome.beacon_rejected,
        },
        "config": outcome.config,
        "per_robot": [
            robot_summary(record) | {"byzantine": outcome.byzantine.get(record.id)}
            for record in robots
        ],
    }
    summary["digest"] = run_digest(summary["per_robot"])
    if outcome.links:
        summary["links"] = {
            str(robot): link_summary(stats) for robot, stats in outcome.links.items()
        }
    if ended is Ending.TIMEOUT:
        kind = outcome.timeout_kind
        summary["timeout_kind"] = None if kind is None else kind.value
    if ended is not Ending.CONSENSUS:
        summary["stuck"] = list(outcome.stuck)
    return summary


# What a run's digest covers, robot by robot: what it decided, when, after how many steps,
# and the size of every pool it joined. Two runs are the same run exactly when these are.
DIGEST_FIELDS = ("id", "decided_site", "decision_time_s", "steps", "pool_sizes")


def run_digest(per_robot: Sequence[Mapping[str, Any]]) -> str:
    """16 hex digits of the SHA-256 of the runs' per-robot results (``DIGEST_FIELDS`` of
    each robot, by id, as compact JSON): equal for the same run on any engine, process
    layout or machine, and different, but for a 2^-64 chance, for any other."""
    rows = [
        [robot[field] for field in DIGEST_FIELDS]
        for robot in sorted(per_robot, key=lambda robot: int(robot["id"]))
    ]
    text = json.dumps(rows, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def byzantine_in_config(config: dict[str, Any]) -> dict[int, str]:
    """Robot -> behaviour from a run's ``config["byzantine"]`` (``ROBOT:MODE`` texts, as
    ``swarm run`` records them); entries that do not parse are left out."""
    found: dict[int, str] = {}
    entries = config.get("byzantine")
    for text in entries if isinstance(entries, list) else []:
        try:
            switch = byzantine.ByzantineRobot.parse(str(text))
        except ValueError:
            continue
        found[switch.robot] = str(switch.behaviour)
    return found


def robot_summary(record: RobotRecord) -> dict[str, Any]:
    status = record.status
    return {
        "id": record.id,
        "decided_site": status.decided_site if status else None,
        "steps": status.decision_trips if status else None,
        "decision_time_s": round(status.decision_time, 3)
        if status and status.decision_time is not None
        else None,
        "trips": status.trips if status else 0,
        "phase": status.phase if status else None,
        "pool_sizes": list(record.pool_sizes),
        "rejected": status.rejected if status else 0,
        "restarts": record.restarts,
        "killed": record.killed,
        "crashed": record.crashed,
        "outside": record.outside,
        "departed": record.departed,
    }


def link_summary(stats: protocol.LinkStats) -> dict[str, Any]:
    """An outside robot's link as the summary shows it: transport, round trip (median and
    95th percentile, ms), loss, and what went through and was refused."""
    refused = msgspec.structs.asdict(stats.refused)
    return {
        "transport": stats.transport,
        "address": stats.address,
        "connected": stats.connected,
        "sessions": stats.sessions,
        "rtt_ms": stats.rtt_ms,
        "rtt_p95_ms": stats.rtt_p95_ms,
        "loss": stats.loss,
        "pings": stats.pings,
        "frames_in": stats.frames_in,
        "frames_out": stats.frames_out,
        "impaired": stats.impaired,
        "refused": sum(refused.values()),
        "refused_by": {reason: count for reason, count in refused.items() if count},
    }


def describe(values: list[float]) -> str:
    """``mean (min-max)`` of a list, or ``-``."""
    if not values:
        return "-"
    return f"{statistics.fmean(values):.2f} ({min(values):g}-{max(values):g})"
