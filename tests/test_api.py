"""The public Python API (``from bestofn_swarm import run, sweep``; docs/extending.md): a run
as ``swarm run`` makes it, in one process or over Zenoh, with its time series; a sweep on
the study runner, one row per run, resumable; refusals in one line; and the shared layers
importing none of it until it is asked for."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO, reference_run

import bestofn_swarm
from bestofn_swarm import api

pytestmark = pytest.mark.timeout(600)
pandas = pytest.importorskip(
    "pandas", reason="DataFrames need pandas: pip install -e '.[analysis]'"
)
SWARM: dict[str, Any] = {"robots": 6, "sites": 4, "seed": 3, "timeout": 600}


def test_the_shared_layers_import_no_part_of_the_api_until_it_is_asked_for() -> None:
    probe = (
        "import sys, bestofn_swarm, bestofn_swarm.wire.protocol\n"
        "print(sorted(m for m in sys.modules if m.startswith(('deploy', 'bestofn_swarm.api'))))\n"
        "from bestofn_swarm import run, sweep\n"
        "print(run.__module__, sweep.__module__)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert done.stdout.splitlines() == ["[]", "bestofn_swarm.api.runs bestofn_swarm.api.sweeps"]
    assert bestofn_swarm.run is api.run and bestofn_swarm.sweep is api.sweep
    with pytest.raises(AttributeError, match="has no attribute 'walk'"):
        bestofn_swarm.walk  # noqa: B018


def test_a_run_is_swarm_runs_in_one_process_and_over_zenoh() -> None:
    alone = api.run(**SWARM)
    command = reference_run(_options())
    assert alone.summary["per_robot"] == command["per_robot"]
    assert alone.digest == command["digest"] and alone.plugins == command["config"]["plugins"]
    zenoh = api.run(**SWARM, engine="zenoh")
    assert zenoh.ended == alone.ended == "consensus"
    assert zenoh.digest == alone.digest
    assert zenoh.plugins == alone.plugins
    assert zenoh.summary["robot_processes"] == 6


def _options() -> list[str]:
    return ["--robots", "6", "--sites", "4", "--seed", "3", "--timeout", "600"]


def test_its_time_series_ends_where_the_run_ends() -> None:
    result = api.run(**SWARM, drop=0.2)
    swarm = result.frame(swarm=True)
    assert list(swarm.columns[:5]) == ["run_id", "tick", "t", "robots", "decided"]
    assert swarm["t"].is_monotonic_increasing and swarm["decided"].is_monotonic_increasing
    last = swarm.iloc[-1]
    assert last["t"] == pytest.approx(result.summary["sim_time_s"]) and last["decided"] == 6
    frame = result.frame()  # a row per robot per sample
    at_end = frame[frame["tick"] == frame["tick"].max()]
    assert list(at_end["robot"]) == list(range(6))
    assert list(at_end["trips"]) == [robot["trips"] for robot in result.summary["per_robot"]]
    decided = [robot["decided_site"] for robot in result.summary["per_robot"]]
    assert list(at_end["decided_site"]) == decided
    assert result.summary["config"]["drop"] == 0.2
    robots = result.robots()
    assert list(robots["id"]) == list(range(6))


def test_a_run_over_zenoh_keeps_no_time_series_and_says_where_it_is() -> None:
    with pytest.raises(ValueError, match="one over Zenoh keeps it in its recording"):
        api.RunResult({"ended": "consensus"}).frame()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"pooling": "nope"}, r"^no pooling plug-in 'nope' \(--pooling\)"),
        ({"robots": -3}, r"--robots"),
        ({"no_such_option": 1}, r"^unrecognized arguments: --no-such-option 1$"),
        ({"engine": "quantum"}, r"^engine must be one of inprocess, zenoh"),
    ],
)
def test_what_swarm_run_would_refuse_is_a_one_line_value_error(
    options: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValueError, match=message) as refused:
        api.run(**options)
    assert "\n" not in str(refused.value)


def test_a_sweep_is_one_row_per_run_with_its_plugins_and_resumes(tmp_path: Path) -> None:
    grid = {"pooling": ["mprodop", "loglinear"]}
    fixed: dict[str, Any] = {"robots": 6, "sites": 4, "alpha": 0.1, "threshold": 0.99}
    table = api.sweep(grid, seeds=2, parallel=2, root=tmp_path, timeout=600, **fixed)
    assert list(table["key"]) == [
        "pooling=mprodop seed=0",
        "pooling=mprodop seed=1",
        "pooling=loglinear seed=0",
        "pooling=loglinear seed=1",
    ]
    assert set(table["plugins.pooling.name"]) == {"mprodop", "loglinear"}
    assert set(table["plugins.pooling.distribution"]) == {"bestofn-swarm"}
    one = reference_run([*_options()[:4], "--seed", "1", "--timeout", "600", "--alpha", "0.1",
                         "--threshold", "0.99", "--pooling", "loglinear"])  # fmt: skip
    assert table.iloc[3]["digest"] == one["digest"]
    results = tmp_path / "sweep.jsonl"
    made = results.read_text()
    again = api.sweep(grid, seeds=2, parallel=2, root=tmp_path, timeout=600, **fixed)
    assert results.read_text() == made  # nothing was missing, nothing made again
    assert list(again["digest"]) == list(table["digest"])
    with pytest.raises(ValueError, match="no pooling plug-in 'nope'"):
        api.sweep({"pooling": ["nope"]}, seeds=1, root=tmp_path / "refused")
    assert not (tmp_path / "refused" / "sweep.jsonl").exists()
