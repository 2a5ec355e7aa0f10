"""The sweep executor (deploy/reports/sweep.py): the same results per task in this process, on
local processes and on a local Dask cluster on loopback; a worker that dies costs only
its tasks, which are retried or reported."""

from __future__ import annotations

from pathlib import Path

import pytest
import sweep_tasks

from deploy.reports import sweep

RUNS = [("paper", 0), ("dc", 1), ("paper", 2)]


def _behaviours(tmp_path: Path, *whats: str) -> list[tuple[str, str]]:
    return [(what, str(tmp_path / f"marker-{index}")) for index, what in enumerate(whats)]


@pytest.fixture(scope="module")
def sequential() -> list[object]:
    result = sweep.run_sweep(sweep_tasks.small_run, RUNS, sweep.ExecutorSpec(parallel=1))
    assert result.failures == []
    return list(result.results)


@pytest.mark.timeout(600)
def test_local_processes_give_each_run_the_same_result_as_this_process(
    sequential: list[object],
) -> None:
    seen: list[int] = []
    result = sweep.run_sweep(
        sweep_tasks.small_run,
        RUNS,
        sweep.ExecutorSpec(parallel=2),
        progress=lambda done, total, index, failure: seen.append(done),
    )
    assert result.failures == []
    assert result.results == sequential
    assert seen == [1, 2, 3]


@pytest.mark.timeout(600)
def test_a_local_dask_cluster_gives_each_run_the_same_result(sequential: list[object]) -> None:
    pytest.importorskip("distributed", reason="Dask is an optional extra: pip install -e '.[dask]'")
    kept: dict[int, object] = {}
    result = sweep.run_sweep(
        sweep_tasks.small_run,
        RUNS,
        sweep.ExecutorSpec(parallel=2, dask=sweep.LOCAL_DASK),
        on_result=kept.__setitem__,
    )
    assert result.failures == []
    assert result.results == sequential
    assert [kept[index] for index in range(len(RUNS))] == sequential


@pytest.mark.timeout(300)
@pytest.mark.parametrize("parallel", [1, 2])
def test_a_task_that_raises_is_reported_and_the_others_finish(
    tmp_path: Path, parallel: int
) -> None:
    tasks = _behaviours(tmp_path, "ok", "raise", "ok")
    result = sweep.run_sweep(sweep_tasks.behave, tasks, sweep.ExecutorSpec(parallel=parallel))
    assert result.results == ["ok:marker-0", None, "ok:marker-2"]
    (failure,) = result.failures
    assert (failure.index, failure.attempts) == (1, 1)
    assert "the task says no" in failure.error


@pytest.mark.timeout(300)
def test_a_dead_local_worker_costs_only_its_task_which_is_retried(tmp_path: Path) -> None:
    tasks = _behaviours(tmp_path, "ok", "die-once", "ok", "ok")
    result = sweep.run_sweep(sweep_tasks.behave, tasks, sweep.ExecutorSpec(parallel=2))
    assert result.failures == []
    assert result.results == ["ok:marker-0", "die-once:marker-1", "ok:marker-2", "ok:marker-3"]


@pytest.mark.timeout(300)
def test_a_task_that_always_kills_its_local_worker_is_reported(tmp_path: Path) -> None:
    tasks = _behaviours(tmp_path, "ok", "die", "ok")
    result = sweep.run_sweep(sweep_tasks.behave, tasks, sweep.ExecutorSpec(parallel=2, retries=1))
    assert result.results == ["ok:marker-0", None, "ok:marker-2"]
    (failure,) = result.failures
    assert failure.index == 1 and failure.attempts == 2
    assert "died" in failure.error


@pytest.mark.timeout(300)
def test_on_dask_a_dead_worker_is_replaced_and_a_killer_task_reported(tmp_path: Path) -> None:
    pytest.importorskip("distributed", reason="Dask is an optional extra: pip install -e '.[dask]'")
    tasks = _behaviours(tmp_path, "ok", "die-once", "die", "ok")
    result = sweep.run_sweep(
        sweep_tasks.behave, tasks, sweep.ExecutorSpec(parallel=2, dask=sweep.LOCAL_DASK, retries=1)
    )
    assert result.results == ["ok:marker-0", "die-once:marker-1", None, "ok:marker-3"]
    (failure,) = result.failures
    assert failure.index == 2 and "KilledWorker" in failure.error


def test_dask_options_are_checked() -> None:
    import argparse

    parser = argparse.ArgumentParser()
    sweep.add_executor_options(parser)
    args = parser.parse_args(["--parallel", "3"])
    assert sweep.executor_from_args(args) == sweep.ExecutorSpec(3, None, sweep.DEFAULT_RETRIES)
    assert parser.parse_args(["--dask"]).dask == sweep.LOCAL_DASK
    pytest.importorskip("distributed", reason="Dask is an optional extra: pip install -e '.[dask]'")
    with pytest.raises(sweep.cliargs.UsageError, match="scheduler address"):
        sweep.executor_from_args(parser.parse_args(["--dask", "somewhere"]))
    spec = sweep.executor_from_args(parser.parse_args(["--dask", "tcp://127.0.0.1:8786"]))
    assert spec.dask == "tcp://127.0.0.1:8786"
