"""A study's grid, pure: expanding points into runs, keying them, choosing part of a grid
(``--only``), ordering the work (long first, then seed by seed), the time left, and the
sample a check makes again."""

from __future__ import annotations

import pytest

from deploy.study import check, grid
from deploy.study.catalogue import studies
from deploy.study.runner import Eta


def _point(robots: int, seeds: range, cost: float = 1.0, **more: object) -> grid.Point:
    return grid.Point(
        {"robots": robots, **more},  # type: ignore[dict-item]
        seeds,
        options=["--robots", str(robots)],
        timeout=60.0,
        cost=cost,
    )


def test_a_key_is_the_parameters_by_name_then_the_seed() -> None:
    assert (
        grid.key_of({"sites": 5, "drop": 0.2, "robots": 10}, 3)
        == "drop=0.2 robots=10 sites=5 seed=3"
    )
    assert grid.key_of({"robots": 10, "sites": 5}, 0) == grid.key_of({"sites": 5, "robots": 10}, 0)
    assert grid.text(0.0) == grid.text(0) == "0"
    assert grid.text(True) == "true"


def test_a_point_gives_one_run_per_seed_with_its_seed_and_timeout_as_options() -> None:
    runs = _point(10, range(2), drop=0.2).runs("s")
    assert [run.key for run in runs] == ["drop=0.2 robots=10 seed=0", "drop=0.2 robots=10 seed=1"]
    assert runs[1].options == ("--robots", "10", "--seed", "1", "--timeout", "60")
    assert runs[1].command() == "swarm run --robots 10 --seed 1 --timeout 60"
    assert runs[1].point == "drop=0.2 robots=10"


def test_options_that_depend_on_the_seed_are_added_per_run() -> None:
    point = grid.Point(
        {"liars": 1},
        range(2),
        options=[],
        timeout=9.0,
        per_seed=lambda seed: ["--byzantine", str(seed)],
    )
    assert [run.options[-1] for run in point.runs("s")] == ["0", "1"]


def test_settings_without_an_option_make_a_run_that_swarm_run_cannot_replay() -> None:
    point = grid.Point({"a": 1}, (0,), timeout=9.0, configs={"spec.max_wheel_speed": 0.065})
    (run,) = point.runs("s")
    assert run.configs == (("spec.max_wheel_speed", 0.065),)
    assert run.command() is None


def test_bad_points_are_refused() -> None:
    with pytest.raises(ValueError, match="timeout"):
        grid.Point({"robots": 10}, (0,))
    with pytest.raises(ValueError, match="kind"):
        grid.Point({"robots": 10}, (0,), kind="teleport")
    with pytest.raises(ValueError, match="spaces"):
        grid.Point({"setting": "a b"}, (0,), timeout=1.0)
    with pytest.raises(ValueError, match="two runs have the key"):
        grid.expand("s", [_point(10, range(2)), _point(10, range(1, 3))])


def test_product_is_every_combination_first_axis_slowest() -> None:
    assert grid.product(a=(1, 2), b=("x", "y")) == [
        {"a": 1, "b": "x"},
        {"a": 1, "b": "y"},
        {"a": 2, "b": "x"},
        {"a": 2, "b": "y"},
    ]


def test_only_chooses_runs_by_parameter_or_seed() -> None:
    runs = grid.expand("s", [_point(10, range(3)), _point(500, range(3))])
    only = grid.parse_only(["robots=500", "seed=0,2"])
    assert only == {"robots": {"500"}, "seed": {"0", "2"}}
    assert [run.key for run in grid.select(runs, only)] == [
        "robots=500 seed=0",
        "robots=500 seed=2",
    ]
    assert grid.select(runs, {}) == runs
    # A value with '=' in it is the setting's own.
    assert grid.parse_only(["setting=dwell=4"]) == {"setting": {"dwell=4"}}


def test_only_names_what_it_cannot_find() -> None:
    runs = grid.expand("s", [_point(10, range(2)), _point(50, range(2))])
    with pytest.raises(ValueError, match=r"no such parameter \(it has robots, seed\)"):
        grid.select(runs, {"sites": {"5"}})
    with pytest.raises(ValueError, match=r"robots=7: no run has it \(robots: 10, 50\)"):
        grid.select(runs, {"robots": {"7"}})
    with pytest.raises(ValueError, match="NAME=VALUE"):
        grid.parse_only(["robots"])


def test_the_work_goes_longest_first_then_seed_by_seed() -> None:
    runs = grid.expand("s", [_point(10, range(2), cost=2.0), _point(500, range(2), cost=900.0)])
    assert [run.key for run in grid.order(runs)] == [
        "robots=500 seed=0",
        "robots=500 seed=1",
        "robots=10 seed=0",
        "robots=10 seed=1",
    ]
    # What the runs of a point took, once some are made, beats what it declares.
    walls = {"robots=10": [3000.0, 1000.0, 2000.0]}
    assert grid.estimate(runs[0], walls) == 2000.0
    assert grid.order(runs, walls)[0].key == "robots=10 seed=0"


def test_the_time_left_scales_the_estimates_by_how_the_runs_went() -> None:
    eta = Eta(remaining=400.0, workers=2)
    assert eta.seconds_left() == 200.0
    eta.finished(expected=100.0, actual=200.0)  # twice as slow as expected
    assert eta.seconds_left() == 300.0
    eta.dropped(expected=100.0)  # a run that failed
    assert eta.seconds_left() == 200.0


def test_a_checks_sample_reaches_every_kind_varies_with_its_seed_and_keeps_to_its_budget() -> None:
    runs = grid.expand("s", [_point(10, range(20)), _point(50, range(20)), _point(500, range(2))])
    walls = {"robots=10": 1.0, "robots=50": 20.0, "robots=500": 1500.0}
    records = {run.key: {"wall_s": walls[run.point] + run.seed / 100} for run in runs}
    drawn = check.sample(runs, records, seed=1)
    # One run of each kind (how it is made and its size), the same from the same seed in
    # any order of the runs; a kind whose every run is over the budget is named, not made.
    assert {run.point for run in drawn.runs} == {"robots=10", "robots=50"}
    assert list(drawn.kinds) == ["inprocess, 10 robots", "inprocess, 50 robots"]
    assert drawn.out_of_reach == {"inprocess, 500 robots": 1500.0}
    assert check.sample(list(reversed(runs)), records, seed=1).runs == drawn.runs
    # Another seed draws other runs of the same kinds.
    seeds = {tuple(run.key for run in check.sample(runs, records, seed=s).runs) for s in range(8)}
    assert len(seeds) > 4
    # A study's own kinds: here one of each swarm size group.
    grouped = check.sample(
        runs, records, seed=1, kind_of=lambda run: "small" if run.param("robots") == 10 else "big"
    )
    assert [run.point for run in grouped.kinds["small"]] == ["robots=10"]
    assert [run.point for run in grouped.kinds["big"]] == ["robots=50"]  # 500: over budget
    assert grouped.beyond == {"big": 2}
    # Two runs of each kind within a budget of 30 s: the costliest drawn give way.
    tight = check.sample(runs, records, seed=1, per_kind=2, budget=30.0)
    assert sum(records[run.key]["wall_s"] for run in tight.runs) <= 30.0
    assert {run.point for run in tight.runs} == {"robots=10", "robots=50"}  # every kind kept
    # Each kind's cheapest run fits, but not together: a kind is never left out for it.
    snug = check.sample(runs, records, seed=1, budget=20.5)
    assert [run.key for run in snug.runs] == ["robots=10 seed=0", "robots=50 seed=0"]


def test_every_kind_of_run_of_every_study_is_within_the_checks_budget() -> None:
    """make check-published makes one run of each kind of each study: a well-stirred cell,
    a 50-robot swarm, a run over Zenoh, the camera alone, the runs observed for the lag."""
    from pathlib import Path

    from deploy.study.state import state_of

    root = Path(__file__).resolve().parent.parent
    kinds = {}
    for name, study in studies().items():
        state = state_of(study, root)
        drawn = check.sample(
            state.done, state.loaded.runs, seed=0, kind_of=study.kinds or check.default_kind
        )
        assert drawn.out_of_reach == {}, name
        assert sum(check.wall(state.loaded.runs, run) for run in drawn.runs) <= check.BUDGET
        kinds[name] = set(drawn.kinds)
        made = {run.kind for run in drawn.runs}
        assert made == {run.kind for run in state.done}, name  # every way of making a run
    assert {"a well-stirred cell", "a 50-robot swarm"} <= kinds["strategies"]
    assert {"over Zenoh", "the camera alone"} <= kinds["robustness"]
    assert "the defaults, observed for the lag" in kinds["section5-settings"]
    assert kinds["scale"] == {"in one process", "over Zenoh"}
    assert "a 50-robot swarm, trimmed pooling" in kinds["defence"]
    assert len(kinds["byzantine"]) == 4  # no Byzantine robot, liars, inverted, silent


def test_differences_name_each_field_of_the_published_result() -> None:
    published = {"sim_time_s": 1.5, "robots": {"steps": [1, 2]}, "ended": "consensus"}
    fresh = {"sim_time_s": 1.5, "robots": {"steps": [1, 3]}, "ended": "consensus", "new": 1}
    assert check.differences(published, fresh) == ["robots.steps: [1, 2] -> [1, 3]"]
    assert check.differences({"a": 1}, {}) == ["a: 1 -> (none)"]


def test_the_declared_studies_have_the_sizes_asked_for() -> None:
    found = studies()
    sizes = {name: len(study.runs()) for name, study in found.items()}
    # strategies: 4 strategies x 4 n x 2 losses x (20 seeds at 10 robots + 10 at 50), and
    # 20 well-stirred cells
    assert sizes["strategies"] == 4 * 4 * 2 * (20 + 10) + 20
    # defence: 4 liar counts x 2 defences x 20 seeds; 3 liar counts x 3 defences x 10 seeds
    assert sizes["defence"] == 4 * 2 * 20 + 3 * 3 * 10
    assert sizes["byzantine"] == 4 * (1 + 3 * 3) * 40
    # scale: 10-200 robots seeds 0-9, 500 seeds 0-9, 1000 seeds 0-2, over Zenoh 4 + 1
    assert sizes["scale"] == 40 + 10 + 3 + 4 + 1
    scale = {run.key: run for run in found["scale"].runs()}
    assert scale["engine=zenoh robots=1000 seed=0"].record
    assert scale["engine=zenoh robots=1000 seed=0"].kind == "zenoh"
    assert scale["engine=zenoh robots=1000 seed=0"].wall_limit == 12 * 3600
    assert scale["engine=inprocess robots=1000 seed=2"].options[-1] == "12000"
