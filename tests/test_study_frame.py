"""A study's runs as a pandas DataFrame (``deploy.study.frame``), and the one-line error
that says how to install pandas when it is not there."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import deploy.study
from deploy.study import results
from deploy.study.catalogue import study_named
from deploy.study.dataframe import flatten

REPO = Path(__file__).resolve().parent.parent


def test_a_run_is_one_row_of_parameters_and_result_fields() -> None:
    record = {
        "key": "drop=0.2 robots=10 seed=3",
        "params": {"drop": 0.2, "robots": 10},
        "seed": 3,
        "result": {"verdict": "correct", "robots": {"steps": [3, 4]}, "sim_time_s": 100.5},
        "wall_s": 2.5,
        "commit": "abc1234",
        "lock": "0123456789ab",
    }
    row = flatten(record)
    assert row["drop"] == 0.2 and row["robots"] == 10 and row["seed"] == 3
    assert row["verdict"] == "correct" and row["sim_time_s"] == 100.5
    assert row["robots.steps"] == [3, 4]
    assert row["wall_s"] == 2.5 and row["commit"] == "abc1234" and row["dirty"] is None


def test_without_pandas_the_call_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now fails
    with pytest.raises(
        ImportError, match=r"^deploy.study.frame needs pandas: pip install -e '\.\[analysis\]'$"
    ):
        deploy.study.frame("scale")


def test_a_studys_runs_load_into_a_data_frame(tmp_path: Path) -> None:
    pandas = pytest.importorskip("pandas", reason="pandas is the optional extra 'analysis'")
    study = study_named("scale")
    runs = {run.key: run for run in study.runs()}
    with results.Appender(tmp_path / study.results) as appender:
        for key in ("engine=inprocess robots=10 seed=0", "engine=inprocess robots=50 seed=1"):
            run = runs[key]
            appender.add(
                {
                    "key": key,
                    "params": dict(run.params),
                    "seed": run.seed,
                    "kind": run.kind,
                    "result": {"consensus": True, "sim_time_s": 100.0 + run.seed},
                    "wall_s": 1.0,
                    "commit": "abc1234",
                    "dirty": False,
                    "lock": "l",
                }
            )
    frame = deploy.study.frame("scale", tmp_path)
    assert isinstance(frame, pandas.DataFrame)
    assert list(frame["robots"]) == [10, 50]
    assert list(frame["sim_time_s"]) == [100.0, 101.0]
    assert {"key", "engine", "seed", "consensus", "wall_s", "commit", "lock"} <= set(frame.columns)
    assert len(deploy.study.frame("scale", REPO)) == len(results.load(REPO / study.results).runs)
    # A root given as a string is the same root.
    assert deploy.study.frame("scale", str(tmp_path)).equals(frame)
