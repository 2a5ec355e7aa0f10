"""``swarm wellstirred``: table, JSON, figures and argument errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from deploy.cli import main

KEYS = {
    "options",
    "pool",
    "population",
    "alpha",
    "runs",
    "mean",
    "median",
    "q1",
    "q3",
    "success_rate",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def swarm_command() -> list[str]:
    """The installed ``swarm`` script next to this interpreter, else the module."""
    script = Path(sys.executable).parent / "swarm"
    return [str(script)] if script.exists() else [sys.executable, "-m", "deploy.cli"]


def run_json(capsys: pytest.CaptureFixture[str], *arguments: str) -> list[dict[str, Any]]:
    assert main(["wellstirred", *arguments, "--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert isinstance(records, list)
    return records


def test_json_is_one_array_with_the_documented_keys(capsys: pytest.CaptureFixture[str]) -> None:
    records = run_json(capsys, "--options", "20", "10", "--pool", "3", "2", "--runs", "200")
    assert [(r["options"], r["pool"]) for r in records] == [(10, 2), (10, 3), (20, 2), (20, 3)]
    for record in records:
        assert set(record) == KEYS
        assert record["population"] == record["pool"]
        assert record["runs"] == 200 and record["alpha"] == 0.0
        assert record["q1"] <= record["median"] <= record["q3"]
        assert record["success_rate"] == 1.0


def test_exact_mean_is_added_on_request(capsys: pytest.CaptureFixture[str]) -> None:
    records = run_json(capsys, "--options", "100", "--pool", "3", "5", "--runs", "300", "--exact")
    assert [record["exact_mean"] for record in records] == pytest.approx([35.28, 22.40], abs=0.01)
    # The simulated means are close to the paper's (about 35 and about 23).
    assert records[0]["mean"] == pytest.approx(35.28, abs=0.3)
    assert records[1]["mean"] == pytest.approx(22.40, abs=0.3)


def test_exact_mean_is_null_where_population_exceeds_the_pool(
    capsys: pytest.CaptureFixture[str],
) -> None:
    records = run_json(
        capsys,
        "--options",
        "10",
        "--pool",
        "2",
        "4",
        "--population",
        "4",
        "--runs",
        "50",
        "--exact",
    )
    assert records[0]["population"] == 4 and records[0]["exact_mean"] is None
    assert records[1]["exact_mean"] == pytest.approx(3.60, abs=0.01)


def test_same_seed_same_output(capsys: pytest.CaptureFixture[str]) -> None:
    arguments = (
        "--options",
        "10",
        "--pool",
        "2",
        "--runs",
        "100",
        "--alpha",
        "0.2",
        "--threshold",
        "0.9",
        "--population",
        "3",
        "--seed",
        "5",
    )
    assert run_json(capsys, *arguments) == run_json(capsys, *arguments)
    assert run_json(capsys, *arguments) != run_json(capsys, *arguments[:-1], "6")


def test_table_shows_baseline_and_k_star(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["wellstirred", "--options", "100", "--pool", "2", "3", "--runs", "200"]) == 0
    out = capsys.readouterr().out
    assert "n = 100: exhaustive search n/2 = 50 steps; k* = 3" in out
    no_winner = ["wellstirred", "--options", "20", "--pool", "1", "--runs", "10"]
    assert main(no_winner) == 0
    assert "k* = none of the k tried" in capsys.readouterr().out


@pytest.mark.timeout(60)
def test_figures_are_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    figure1, figure2 = tmp_path / "fig1.png", tmp_path / "fig2.png"
    code = main(
        [
            "wellstirred",
            "--options",
            "10",
            "20",
            "--pool",
            "1",
            "2",
            "3",
            "--runs",
            "50",
            "--json",
            "--plot",
            str(figure1),
            "--plot-opinion",
            str(figure2),
        ]
    )
    assert code == 0
    captured = capsys.readouterr()
    assert len(json.loads(captured.out)) == 6  # the figures do not disturb stdout
    assert figure1.read_bytes().startswith(PNG_MAGIC)
    assert figure2.read_bytes().startswith(PNG_MAGIC)
    assert "wrote" in captured.err


def test_figures_are_written_on_a_machine_where_matplotlib_never_ran(tmp_path: Path) -> None:
    """The fast tier's test of the figures in a fresh pytest with an empty HOME and caches:
    matplotlib builds its font list there by starting fontconfig, which the fast tier's
    guard refuses inside a test (tests/conftest.py makes it before)."""
    empty = {name: tmp_path / name.lower() for name in ("HOME", "XDG_CACHE_HOME", "MPLCONFIGDIR")}
    for folder in empty.values():
        folder.mkdir()
    test = "tests/test_wellstirred_cli.py::test_figures_are_written"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", test],
        cwd=Path(__file__).resolve().parent.parent,
        env={**os.environ, **{name: str(folder) for name, folder in empty.items()}},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout[-3000:]
    assert any(empty["MPLCONFIGDIR"].iterdir()), "matplotlib kept no font list there"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--options", "1"], "--options: 1 is outside [2, inf)"),
        (["--pool", "0"], "--pool: 0 is outside [1, inf)"),
        (["--runs", "0"], "--runs: 0 is outside [1, inf)"),
        (["--steps", "0"], "--steps: 0 is outside [1, inf)"),
        (["--alpha", "0.6"], "--alpha: 0.6 is outside [0.0, 0.5]"),
        (["--alpha", "-0.1"], "--alpha: -0.1 is outside [0.0, 0.5]"),
        (["--alpha", "nan"], "--alpha: 'nan' is not a finite number"),
        (["--threshold", "0"], "--threshold: 0 is outside (0.0, 1.0]"),
        (["--threshold", "1.01"], "--threshold: 1.01 is outside (0.0, 1.0]"),
        (["--pool", "5", "--population", "3"], "--population 3 is smaller than --pool 5"),
        (["--exact", "--alpha", "0.1"], "--exact needs --alpha 0"),
        (["--plot", "/no/such/dir/fig.png"], "--plot: directory /no/such/dir does not exist"),
        (["--pool", "1001", "--exact"], "--exact supports pools up to 1000, got --pool 1001"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as raised:
        main(["wellstirred", "--runs", "5", *arguments])
    assert raised.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    error_lines = [line for line in captured.err.splitlines() if "error" in line]
    assert len(error_lines) == 1
    assert error_lines[0].startswith("swarm wellstirred: error:")
    assert message in error_lines[0]
    assert len(captured.err.splitlines()) <= 2  # at most a one-line usage before it


@pytest.mark.timeout(60)
def test_installed_command(tmp_path: Path) -> None:
    ok = subprocess.run(
        [
            *swarm_command(),
            "wellstirred",
            "--options",
            "10",
            "--pool",
            "2",
            "--runs",
            "20",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert ok.returncode == 0, ok.stderr
    assert [record["pool"] for record in json.loads(ok.stdout)] == [2]
    assert ok.stderr == ""  # no progress bar when stderr is not a terminal
    bad = subprocess.run(
        [*swarm_command(), "wellstirred", "--alpha", "0.7"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert bad.returncode == 2
    assert bad.stdout == ""
    assert bad.stderr.splitlines()[-1] == (
        "swarm wellstirred: error: argument --alpha: 0.7 is outside [0.0, 0.5]"
    )


@pytest.mark.timeout(60)
def test_an_exact_chain_too_large_for_memory_is_refused_up_front() -> None:
    """n = 100000 would ask numpy for a 74.5 GiB transition matrix."""
    done = subprocess.run(
        [*swarm_command(), "wellstirred", "--options", "100000", "--pool", "3", "--exact"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.splitlines() == [
        "swarm wellstirred: error: --exact supports up to 5000 options, got --options 100000: "
        "its transition matrix of (n + 1)^2 numbers would take 74.5 GiB"
    ]
