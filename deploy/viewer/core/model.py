"""What the page draws, built from a run's decoded messages (pure: no I/O, no clock).

The live bridge (``deploy.viewer.live``) and the replay (``deploy.viewer.replay``) feed the same
types: ``Scene`` says what never changes in a run (arena, sites in their rendered colours and
qualities, nest, palette), ``RobotView`` one robot's latest pose and status, and ``frame``
turns one moment of the run into the JSON object the page draws; which robots' opinions
each pooling joined is ``world_server.core.pooling``'s, as in the recording's scene.

Qualities are not on the wire: like the recorder, the scene computes the run's layout
from its seed and sizes (``world_server.core.layout.make_layout``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from bestofn_swarm.wire import protocol
from bestofn_swarm.wire.endings import Ending
from world_server.core.body import EPUCK
from world_server.core.layout import Layout
from world_server.core.palette import (
    PHASE_COLOURS,
    UNKNOWN_PHASE_COLOUR,
    hex_colour,
    site_colour,
)
from world_server.core.pooling import LINK_SECONDS, Pooling
from world_server.observer.observer import RunObserver

# The page's legend, in the order of a trip. Each phase keeps the colour it has in the
# recording's Foxglove scene (world_server.core.palette.PHASE_COLOURS).
PHASES: tuple[tuple[str, str], ...] = (
    ("to_site", "to a site"),
    ("sensing", "sensing"),
    ("to_nest", "home"),
    ("waiting", "waiting for the beacon"),
    ("at_nest", "pooling"),
    ("lingering", "lingering"),
    ("to_decision", "decided, to its site"),
    ("stopped", "decided, parked"),
)
PHASE_INDEX = {name: index for index, (name, _) in enumerate(PHASES)}
UNKNOWN_PHASE = -1

# Target kinds in a frame: none, a site the status names, a site inferred from the
# robot's heading (the status does not say which site of its pair it is going to), nest.
TARGET_NONE, TARGET_SITE, TARGET_SITE_INFERRED, TARGET_NEST = 0, 1, 2, 3
HOMEWARD = frozenset({"to_nest", "waiting", "at_nest", "lingering"})


def site_hex(site: int, sites: int) -> str:
    """A site's colour on the page (``world_server.core.palette``: categorical, not its
    quality, which the page writes beside it)."""
    return hex_colour(site_colour(site, sites))


@dataclass(frozen=True)
class Scene:
    """What never changes during a run: sent once to every page that connects."""

    run_id: str
    seed: int
    robots: int
    layout: Layout
    robot_radius: float = EPUCK.radius
    mode: str = "live"  # live | replay

    def hello(self, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
        layout = self.layout
        return {
            "type": "hello",
            "mode": self.mode,
            "run_id": self.run_id,
            "seed": self.seed,
            "robots": self.robots,
            "sites": len(layout.sites),
            "arena": {
                "radius": layout.arena_radius,
                "nest": {"x": 0.0, "y": 0.0, "radius": layout.nest_radius},
                "robot_radius": self.robot_radius,
                "best_site": layout.best_site,
                "sites": [
                    {
                        "id": site.id,
                        "x": site.x,
                        "y": site.y,
                        "angle": site.angle,
                        "half_width": site.half_width,
                        "quality": site.quality,
                        "colour": site_hex(site.id, len(layout.sites)),
                    }
                    for site in layout.sites
                ],
            },
            "phases": [
                {
                    "name": name,
                    "label": label,
                    "colour": hex_colour(PHASE_COLOURS.get(name, UNKNOWN_PHASE_COLOUR)),
                }
                for name, label in PHASES
            ],
            **(extra or {}),
        }

    def inferred_site(self, x: float, y: float, theta: float) -> int:
        """The site a robot heads for, judged from its heading: the one it faces most."""

        def off_heading(site_id: int) -> float:
            site = self.layout.sites[site_id]
            bearing = math.atan2(site.y - y, site.x - x)
            return abs(math.remainder(bearing - theta, 2 * math.pi))

        return min(range(len(self.layout.sites)), key=off_heading)


@dataclass
class RobotView:
    """The latest of one robot: its pose (from world/state) and its status."""

    pose: tuple[float, float, float] | None = None
    status: protocol.Status | None = None


def views_of(run: RunObserver) -> dict[int, RobotView]:
    """Each robot the observer knows, as the page draws it."""
    robots = set(run.poses) | {robot for robot, record in run.records.items() if record.status}
    return {
        robot: RobotView(
            run.poses.get(robot),
            record.status if (record := run.records.get(robot)) is not None else None,
        )
        for robot in robots
    }


def leading(opinion: Sequence[float]) -> tuple[int, float]:
    site = max(range(len(opinion)), key=opinion.__getitem__)
    return site, opinion[site]


def robot_row(robot: int, view: RobotView, scene: Scene) -> list[Any] | None:
    """``[id, x, y, theta, phase, target kind, target site, lead site, lead p, decided site,
    trips, pool size]`` (-1 for unknown), or None before the robot's first pose."""
    if view.pose is None:
        return None
    x, y, theta = view.pose
    status = view.status
    if status is None:
        return [robot, _r(x), _r(y), _r(theta), UNKNOWN_PHASE, TARGET_NONE, -1, -1, 0.0, -1, 0, 0]
    kind, target = TARGET_NONE, -1
    if status.decided_site is not None and status.phase == "to_decision":
        kind, target = TARGET_SITE, status.decided_site
    elif status.phase in HOMEWARD:
        kind = TARGET_NEST
    elif status.phase in ("to_site", "sensing"):
        kind, target = TARGET_SITE_INFERRED, scene.inferred_site(x, y, theta)
    lead, p = leading(status.opinion)
    return [
        robot,
        _r(x),
        _r(y),
        _r(theta),
        PHASE_INDEX.get(status.phase, UNKNOWN_PHASE),
        kind,
        target,
        lead,
        round(p, 4),
        -1 if status.decided_site is None else status.decided_site,
        status.trips,
        status.pool_size,
    ]


def _r(value: float) -> float:
    return round(value, 4)


def frame(
    scene: Scene,
    *,
    t: float,
    tick: int,
    robots: Mapping[int, RobotView],
    decided: int,
    counters: protocol.WorldState | None,
    poolings: Iterable[Pooling] = (),
    deliveries: Sequence[tuple[str, int]] = (),
    real_time_factor: float | None = None,
    ended: Mapping[str, Any] | None = None,
    links: Mapping[int, protocol.LinkStats] | None = None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """One moment of the run as the page draws it; ``links``: the robots outside the
    emulator, as their bridge last reported their links."""
    rows = [row for robot, view in sorted(robots.items()) if (row := robot_row(robot, view, scene))]
    statuses = [view.status for view in robots.values() if view.status is not None]
    radio = counters.radio if counters is not None else protocol.RadioCounters()
    return {
        "type": "frame",
        "t": round(t, 3),
        "tick": tick,
        "rtf": None if real_time_factor is None else round(real_time_factor, 1),
        "robots": rows,
        "decided": decided,
        "total": scene.robots,
        "trips": sum(status.trips for status in statuses),
        "radio": {
            "sent": radio.sent,
            "delivered": radio.delivered,
            "dropped": radio.dropped,
            "rejected": radio.rejected,
        },
        "poolings": [
            [pooling.robot, round(pooling.t, 2), pooling.size, list(pooling.members)]
            for pooling in poolings
            if t - LINK_SECONDS <= pooling.t <= t
        ],
        "rx": [[sender, receiver] for sender, receiver in deliveries],
        "ended": dict(ended) if ended is not None else None,
        "links": {str(robot): link_row(stats) for robot, stats in sorted((links or {}).items())},
        **(extra or {}),
    }


def link_row(stats: protocol.LinkStats) -> dict[str, Any]:
    """An outside robot's link as the page shows it."""
    refused = stats.refused
    return {
        "transport": stats.transport,
        "connected": stats.connected,
        "rtt_ms": stats.rtt_ms,
        "rtt_p95_ms": stats.rtt_p95_ms,
        "loss": stats.loss,
        "refused": sum(getattr(refused, reason) for reason in refused.__struct_fields__),
    }


def opinion_message(robot: int, status: protocol.Status | None) -> dict[str, Any]:
    """The whole opinion vector of one robot, for the page's detail panel."""
    return {
        "type": "opinion",
        "robot": robot,
        "opinion": list(status.opinion) if status is not None else None,
        "phase": status.phase if status is not None else None,
        "comparison": (
            {
                "site_a": status.comparison.site_a,
                "quality_a": status.comparison.quality_a,
                "site_b": status.comparison.site_b,
                "quality_b": status.comparison.quality_b,
                "eliminated": status.comparison.eliminated,
            }
            if status is not None and status.comparison is not None
            else None
        ),
        "poolings": status.poolings if status is not None else 0,
    }


def ending(summary: Mapping[str, Any] | None, fallback: str = "stopped") -> dict[str, Any]:
    """How the run ended, in the page's words, from the launcher's summary (if any)."""
    if summary is None:
        return {"reason": fallback, "text": f"run {fallback}"}
    reason = summary.get("ended")
    if not isinstance(reason, str):  # the summary does not say (an older or rebuilt one)
        reason = (
            Ending.TIMEOUT.value
            if summary.get("timed_out")
            else Ending.CONSENSUS.value
            if summary.get("consensus")
            else "ended"
        )
    if summary.get("consensus"):
        verdict = (
            "the best" if summary.get("correct") else f"not the best ({summary.get('best_site')})"
        )
        text = f"consensus on site {summary.get('chosen_site')}, {verdict}"
    else:
        text = "no consensus"
    if reason not in (Ending.CONSENSUS, "ended"):
        text = f"{reason}: {text}"
    return {"reason": reason, "text": text}
