"""A run's time series as its observer collects it (world_server/observer/frame.py), the
bounded chart series of the live page (deploy/viewer/core/series.py), the conditions a
report groups runs by (deploy/reports/conditions.py), the site palette and the plain
progress lines: pure parts, fed by hand."""

from __future__ import annotations

import io
import math
from typing import Any

import pytest
from rich.console import Console

from bestofn_swarm.plumbing.progress import PlainProgress
from bestofn_swarm.wire import protocol
from deploy.reports import conditions
from deploy.viewer.core.series import Series
from world_server.core import palette
from world_server.observer.frame import PHASES, FrameCollector, entropy, swarm_sample
from world_server.observer.observer import RunObserver

SITES, BEST = 4, 2


def _status(
    robot: int,
    tick: int,
    opinion: list[float],
    *,
    poolings: int = 0,
    pool_size: int = 0,
    decided: int | None = None,
    trips: int = 0,
) -> protocol.Status:
    return protocol.Status(
        v=1,
        id=robot,
        tick=tick,
        t=tick * 0.1,
        phase="stopped" if decided is not None else "to_site",
        trips=trips,
        opinion=opinion,
        pool_size=pool_size,
        poolings=poolings,
        decided_site=decided,
        decision_time=tick * 0.1 if decided is not None else None,
        decision_trips=trips if decided is not None else None,
        comparison=None,
    )


def _state(tick: int, robots: int = 2) -> protocol.WorldState:
    return protocol.WorldState(
        v=1,
        tick=tick,
        t=tick * 0.1,
        robots=[protocol.Pose(robot, 0.1 * robot, -0.1 * tick, 0.0) for robot in range(robots)],
        radio=protocol.RadioCounters(),
        rejected=0,
        stalls=0,
    )


UNIFORM = [0.25] * 4
LEANING = [0.1, 0.1, 0.7, 0.1]
CERTAIN = [0.0, 0.0, 1.0, 0.0]

# One run's messages in the order a world publishes them in lockstep: the state of a tick
# first, then the statuses its robots send while stepping it.
RUN: list[protocol.Status | protocol.WorldState] = [
    _state(0),
    _status(0, 0, UNIFORM),
    _status(1, 0, UNIFORM),
    _state(10),
    _status(0, 14, LEANING, poolings=1, pool_size=2, trips=1),
    _state(20),
    _status(1, 20, LEANING, poolings=1, pool_size=3, trips=1),
    _state(30),
    _status(0, 33, CERTAIN, poolings=2, pool_size=2, decided=BEST, trips=2),
    _status(1, 35, CERTAIN, poolings=2, pool_size=1, decided=BEST, trips=2),
    _state(40),
    _state(44),  # the world's last state, when the run stopped
]


def _collect(messages: list[Any], **options: Any) -> FrameCollector:
    collector = FrameCollector(SITES, BEST, **options)
    observer = RunObserver(range(2), series=collector)
    for message in messages:
        if isinstance(message, protocol.Status):
            observer.status(message)
        else:
            observer.state(message)
    collector.finish()
    return collector


def _rows(collector: FrameCollector) -> tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]:
    def rows(table: Any) -> list[tuple[Any, ...]]:
        return list(zip(*(list(column) for column in table.values), strict=True))

    return rows(collector.robots), rows(collector.swarm)


def test_one_row_per_robot_per_world_state_from_its_latest_status_of_that_tick() -> None:
    robots, swarm = _rows(_collect(RUN))
    assert [row[0] for row in swarm] == [0, 10, 20, 30, 40, 44]
    assert len(robots) == 2 * len(swarm)
    by_tick = {(row[0], row[2]): row for row in robots}
    # Robot 0 leaned at tick 14: the row of tick 10 does not know it yet, that of 20 does.
    assert by_tick[(10, 0)][9] == 0 and by_tick[(10, 0)][11] == pytest.approx(0.25)
    lean = by_tick[(20, 0)]
    assert (lean[9], lean[10], lean[11]) == (BEST, 0.7, 0.7)  # leading site, its p, p_best
    assert lean[12] == pytest.approx(entropy(LEANING)) and lean[13:] == (2, 1)
    decided = by_tick[(40, 1)]
    assert PHASES[decided[6]] == "stopped" and decided[8] == BEST and decided[12] == 0.0
    # The pose is the world state's.
    assert (by_tick[(30, 1)][3], by_tick[(30, 1)][4]) == (pytest.approx(0.1), pytest.approx(-3.0))
    assert entropy(UNIFORM) == pytest.approx(2.0)


def test_the_swarm_rows_count_decisions_shares_and_the_poolings_since_the_row_before() -> None:
    _, swarm = _rows(_collect(RUN))
    names = [name for name, _ in FrameCollector(SITES, BEST).swarm_columns]
    first, twenty, forty = (dict(zip(names, swarm[i], strict=True)) for i in (0, 2, 4))
    assert first["decided"] == 0 and first["share_2"] == pytest.approx(0.25)
    assert first["poolings"] == 0 and math.isnan(first["pool_size_mean"])
    # Robot 0 pooled (2) by tick 20; robot 1 pooled (3) at tick 20.
    assert twenty["poolings"] == 2 and twenty["pool_size_mean"] == pytest.approx(2.5)
    assert twenty["share_2"] == pytest.approx(0.7)
    assert forty["decided"] == 2 and forty["share_2"] == 1.0 and forty["p_best_mean"] == 1.0
    assert forty["entropy_mean"] == 0.0
    message = swarm_sample(swarm[0])
    assert message.shares == pytest.approx([0.25] * 4) and message.pool_size_mean is None


def test_statuses_that_come_after_the_next_world_state_land_in_the_same_rows() -> None:
    """Over Zenoh a robot's status may reach an observer after the world state of the next
    tick: the rows are those of the order the world made them in."""
    late = list(RUN)
    # Robot 1's status of tick 20 after the state of tick 30, robot 0's of 33 after 40.
    late.insert(late.index(RUN[7]) + 1, late.pop(late.index(RUN[6])))
    late.insert(late.index(RUN[10]) + 1, late.pop(late.index(RUN[8])))
    assert late != RUN
    assert repr(_rows(_collect(late))) == repr(_rows(_collect(RUN)))  # NaN as text


def test_every_nth_world_state_and_the_poolings_between_kept_ones() -> None:
    _, swarm = _rows(_collect(RUN, every=2))
    assert [row[0] for row in swarm] == [0, 20, 40]
    assert [row[6] for row in swarm] == [0, 2, 2]  # no pooling is lost between kept rows
    with pytest.raises(ValueError, match="every"):
        FrameCollector(SITES, BEST, every=0)


def test_rows_handed_out_when_not_kept_and_a_dataframe_when_kept() -> None:
    streamed = FrameCollector(SITES, BEST, keep=False)
    observer = RunObserver(range(2), series=streamed)
    seen: list[tuple[Any, ...]] = []
    for message in RUN:
        if isinstance(message, protocol.Status):
            observer.status(message)
        else:
            observer.state(message)
        seen += streamed.take()[0]
    streamed.finish()
    seen += streamed.take()[0]
    assert repr(seen) == repr(_rows(_collect(RUN))[0]) and len(streamed.robots) == 0
    pandas = pytest.importorskip("pandas")
    frame = _collect(RUN).dataframe(run_id="r")
    assert list(frame.columns[:4]) == ["run_id", "tick", "t", "robot"]
    assert frame["decided_site"].isna().sum() == 8 and frame["decided_site"].dropna().eq(2).all()
    assert isinstance(frame["phase"].dtype, pandas.CategoricalDtype)


def test_the_chart_series_stays_bounded_and_a_page_gets_what_it_lacks() -> None:
    series = Series(limit=8)
    rows = [
        (tick, tick / 10, 4, tick // 50, 1.0, 0.5, 0, math.nan, 0.5, 0.5)
        for tick in range(0, 100, 10)
    ]
    series.extend(rows[:5])
    first = series.since(-1, 0)
    assert first is not None and first["reset"] and len(first["points"]) == 5
    assert first["points"][0] == [0.0, 0, 1.0, None, 0.5, 0.5]
    assert series.since(series.epoch, 5) is None
    series.extend(rows[5:])  # past the limit: every other point goes
    assert len(series.points) <= 8 and series.epoch == 1
    again = series.since(0, 5)
    assert again is not None and again["reset"]


def test_the_conditions_that_differ_group_and_label_runs() -> None:
    def summary(run: str, drop: float, seed: int) -> dict[str, Any]:
        config = {"robots": 10, "sites": 5, "seed": seed, "run_id": run, "drop": drop}
        return {"num_robots": 10, "num_sites": 5, "config": config | {"alpha": 0.0}}

    runs = [summary("a", 0.0, 1), summary("b", 0.3, 2), summary("c", 0.0, 3)]
    assert conditions.differing(runs) == ["drop"]
    assert conditions.group_key(runs[0], ["drop"]) == conditions.group_key(runs[2], ["drop"])
    assert conditions.label(10, 5, {"drop": 0.3}) == "N = 10, n = 5, drop = 0.3"
    assert conditions.value_text(["3@60"]) == "3@60" and conditions.value_text(None) == "-"


def test_sites_get_distinct_colour_blind_safe_colours() -> None:
    assert palette.site_palette(5) == palette.OKABE_ITO[:5]
    assert palette.site_palette(10) == palette.TAB10
    for sites in (2, 8, 10, 20, 40):
        colours = palette.site_palette(sites)
        assert len(set(colours)) == sites
    swatches = {palette.hex_colour(colour) for colour in palette.PHASE_COLOURS.values()}
    assert len(swatches) == len(palette.PHASE_COLOURS)  # a swatch of its own for each state


def test_plain_progress_writes_lines_not_a_live_bar() -> None:
    out = io.StringIO()
    now = [0.0]
    progress = PlainProgress(Console(file=out, width=200), clock=lambda: now[0], every=10.0)
    with progress:
        task = progress.add_task("runs", total=3, info="starting")
        now[0] = 2.0
        progress.update(task, advance=1, info="run-1 consensus")
        now[0] = 2.5
        progress.update(task, info="nothing new")  # within 10 s of the last line: quiet
        now[0] = 4.0
        progress.update(task, advance=2, info="run-3 consensus")
    lines = out.getvalue().splitlines()
    assert lines == [
        "runs: 0/3, starting",
        "runs: 1/3, run-1 consensus",
        "runs: 3/3, run-3 consensus",
    ]
    assert "\x1b" not in out.getvalue()
