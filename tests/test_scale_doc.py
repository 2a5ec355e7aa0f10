"""docs/scale.md is what the results file gives, and the results file is what today's
code gives, for the runs a check can afford: four of them, in ``make check-published``
(``pytest --published``).

The other runs take minutes to an hour each; the commands docs/scale.md names
(benchmarks/scale_consensus.py) make them again.
"""

from __future__ import annotations

import dataclasses

import pytest
from swarm_helpers import REPO

from benchmarks import scale_consensus as scale


def _runs() -> list[scale.Run]:
    return scale.load_runs(REPO / scale.RUNS_FILE)


def test_the_page_is_what_the_results_give() -> None:
    runs = _runs()
    before = scale.load_runs(REPO / scale.BEFORE_FILE)
    expected = scale.render_doc(runs, before, "scale.png")
    assert (REPO / "docs" / "scale.md").read_text() == expected


def test_readme_has_the_per_size_table_the_results_give() -> None:
    readme = (REPO / scale.README).read_text()
    block = f"{scale.README_BEGIN}\n{scale.readme_block(_runs())}\n{scale.README_END}"
    assert block in readme


def test_a_later_run_of_the_same_size_and_seed_replaces_an_earlier_one() -> None:
    first = next(run for run in _runs() if run.mode == "in-process")
    later = dataclasses.replace(first, wall_time_s=first.wall_time_s + 1)
    assert scale.merged([first, later]) == [later]


def test_every_size_and_seed_of_the_plan_is_in_the_results() -> None:
    """The table covers issue 10's whole plan in one process, and no run outside issue 24's
    plan, each once; every run that did not end in consensus says how it ended."""
    runs = [run for run in _runs() if run.mode == "in-process"]
    published = sorted((run.robots, run.seed) for run in runs)
    assert len(published) == len(set(published))
    planned = {(robots, seed) for robots, seeds in scale.DEFAULT_PLAN.items() for seed in seeds}
    assert set(published) <= planned
    least = {(robots, seed) for robots, seeds in scale.PUBLISHED_PLAN.items() for seed in seeds}
    assert least <= set(published)
    for run in runs:
        assert run.ended in ("consensus", "stalled", "timeout", "split"), run
        assert (run.ended == "consensus") == run.consensus, run


@pytest.mark.timeout(600)
@pytest.mark.parametrize(("robots", "seed"), [(10, 0), (10, 7), (50, 3), (100, 3)])
def test_a_published_run_is_what_the_code_gives(robots: int, seed: int) -> None:
    published = next(
        run for run in _runs() if (run.robots, run.seed, run.mode) == (robots, seed, "in-process")
    )
    fresh = scale.run_in_process((robots, seed, scale.DEFAULT_TIMEOUT))
    # Wall time is the machine's and is not compared; everything else is the code's.
    assert _results(fresh) == _results(published)


def _results(run: scale.Run) -> dict[str, object]:
    """What a run gives, without the wall time it took."""
    return {key: value for key, value in dataclasses.asdict(run).items() if key != "wall_time_s"}
