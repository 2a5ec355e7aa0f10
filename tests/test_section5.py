"""The checks that the published Section 5 (docs/section5.md, the figures' data) is what
the code gives: ``make check-published`` runs ``swarm section5 --check`` on every published
run (in CI, after ``make test``); these tests show that the check finds what it must, on
copies of the published files."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from swarm_helpers import REPO

from deploy.analysis import section5_tables as tables
from deploy.cli import main
from deploy.reports import section5


def _published() -> tuple[dict[str, Any], list[dict[str, Any]]]:
    data = json.loads((REPO / section5.RUNS_FILE).read_text())
    return data["meta"], data["runs"]


def _paper_seeds(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [record for record in runs if record["seed"] < tables.PAPER_SEEDS]


def _copy_published(into: Path) -> Path:
    """The published files in a scratch repository, to be spoiled by a test."""
    for relative in section5.published_paths():
        source = REPO / relative
        if source.exists() and source.suffix in (".json", ".md"):
            (into / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(source, into / relative)
    return into


def test_check_finds_a_run_that_changed(tmp_path: Path) -> None:
    root = _copy_published(tmp_path)
    _, runs = _published()
    fresh = copy.deepcopy(_paper_seeds(runs))
    assert section5.check_all(root, fresh) == []
    changed = next(r for r in fresh if r["variant"] == "default" and r["n"] == 10)
    changed["steps"] = [step + 1 for step in changed["steps"]]
    problems = section5.check_all(root, fresh)
    # The run itself, both figures' data (fig5 only through nothing: pools are unchanged),
    # and the tables that show its steps.
    assert any(problem.startswith("run ('default', 10, 0)") for problem in problems)
    assert "docs/fig4.json differs from the runs (or is missing)" in problems
    assert "docs/fig5.json differs from the runs (or is missing)" not in problems
    assert any("docs/section5.md: block 'summary' differs" in problem for problem in problems)
    assert any("docs/section5.md: block 'runs' differs" in problem for problem in problems)


def test_check_finds_an_edited_table_and_missing_data(tmp_path: Path) -> None:
    root = _copy_published(tmp_path)
    _, runs = _published()
    fresh = _paper_seeds(runs)
    page = root / "docs" / "section5.md"
    page.write_text(page.read_text().replace("seeds 0-9: within n/2", "seeds 0-9: ok"))
    (root / "docs" / "fig5-linger.json").unlink()
    problems = section5.check_all(root, fresh)
    assert len(problems) == 2
    assert problems[0] == "docs/fig5-linger.json differs from the runs (or is missing)"
    assert problems[1].startswith("docs/section5.md: block 'summary' differs")


def test_blocks_are_replaced_between_their_markers() -> None:
    text = (
        "before\n" + section5.begin_marker("x") + "\nold\n" + section5.end_marker("x") + "\nafter"
    )
    replaced = section5.replace_block(text, "x", "new\nlines")
    assert section5.read_block(replaced, "x") == "new\nlines"
    assert replaced.startswith("before\n") and replaced.endswith("\nafter")
    with pytest.raises(ValueError, match="no block 'y'"):
        section5.replace_block(text, "y", "new")


def test_figure_data_is_what_the_tables_count() -> None:
    meta, runs = _published()
    data = tables.figure_data(runs, "default", 4)
    assert [panel["n"] for panel in data["panels"]] == list(tables.SITES)
    for panel in data["panels"]:
        assert [run["seed"] for run in panel["runs"]] == list(range(tables.PAPER_SEEDS))
        within = sum(1 for run in panel["runs"] if max(run["values"]) <= panel["n"] / 2)
        chosen = tables.select(runs, "default", panel["n"], tables.PAPER_SEEDS)
        assert within == tables._within(chosen, panel["n"])[0]
    assert meta["robots"] == tables.ROBOTS


def test_swarm_steps_is_the_last_robot_and_only_for_consensus() -> None:
    record = {"ended": "consensus", "steps": [2, 5, 3], "pools": [[1], [2], [3]]}
    assert tables.swarm_steps(record) == 5
    assert tables.swarm_steps(record | {"ended": "stalled"}) is None
    assert tables.swarm_steps(record | {"steps": [2, None, 3]}) is None


def test_cli_needs_the_repository(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as raised:
        main(["section5", "--check", "--root", str(tmp_path)])
    assert raised.value.code == 2
    assert "has no docs/section5.md" in capsys.readouterr().err


def test_render_rewrites_the_blocks_from_the_published_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--render`` runs nothing: it puts back what the runs file says."""
    monkeypatch.setattr(section5, "plot_all", lambda root, records: [])  # PNGs: not compared
    root = _copy_published(tmp_path)
    page = root / "docs" / "section5.md"
    published = page.read_text()
    page.write_text(published.replace("seeds 0-9: within n/2", "seeds 0-9: ok"))
    assert main(["section5", "--render", "--root", str(root)]) == 0
    assert page.read_text() == published
    _, runs = _published()
    assert section5.check_all(root, _paper_seeds(runs)) == []


def _fake_simulate(
    monkeypatch: pytest.MonkeyPatch, change: dict[tuple[str, int, int], dict[str, Any]]
) -> list[list[section5.Task]]:
    """``simulate`` gives the published runs, but for the fields ``change`` says; it records
    the tasks it was asked for."""
    _, runs = _published()
    by_key = {(r["variant"], r["n"], r["seed"]): r for r in runs}
    asked: list[list[section5.Task]] = []

    def simulate(tasks: list[section5.Task], parallel: int, progress: Any = None) -> Any:
        asked.append(list(tasks))
        keys = [(task.variant, task.sites, task.seed) for task in tasks]
        return [by_key[key] | change.get(key, {}) for key in keys]

    monkeypatch.setattr(section5, "simulate", simulate)
    return asked


def test_check_runs_every_published_run_and_names_each_that_differs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _copy_published(tmp_path)
    _, runs = _published()
    asked = _fake_simulate(
        monkeypatch,
        {
            ("default", 8, 58): {"sim_time_s": 1.5},
            ("linger", 5, 99): {"ended": "stalled"},
        },
    )
    assert main(["section5", "--check", "--root", str(root)]) == 1
    assert [(t.variant, t.sites, t.seed) for t in asked[0]] == [
        (r["variant"], r["n"], r["seed"]) for r in runs
    ]
    out, err = capsys.readouterr()
    drifted = [line for line in out.splitlines() if line.startswith("run ")]
    assert len(drifted) == 2
    assert drifted[0].startswith("run ('default', 8, 58): published -> now: sim_time_s ")
    assert drifted[0].endswith("-> 1.5")
    assert drifted[1] == "run ('linger', 5, 99): published -> now: ended 'consensus' -> 'stalled'"
    assert f"checked {len(runs)} of the {len(runs)} published runs" in err
    assert "NOT checked" not in err
    assert "2 of them runs" in err


def test_the_sample_checks_seeds_0_to_9_and_says_what_it_did_not_check(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _copy_published(tmp_path)
    meta, runs = _published()
    # A drifted run beyond seed 9 goes unnoticed by the sample, which says so.
    asked = _fake_simulate(monkeypatch, {("default", 8, 58): {"sim_time_s": 1.5}})
    assert main(["section5", "--check", "--sample", "--root", str(root)]) == 0
    assert len(asked[0]) == 2 * len(tables.SITES) * tables.PAPER_SEEDS
    assert {task.seed for task in asked[0]} == set(range(tables.PAPER_SEEDS))
    err = capsys.readouterr().err
    unchecked = len(runs) - len(asked[0])
    assert f"checked {len(asked[0])} of the {len(runs)} published runs" in err
    assert (
        f"NOT checked: {unchecked} published runs (seeds {tables.PAPER_SEEDS}-"
        f"{meta['seeds'] - 1} of default and linger, n = 5, 8, 10)" in err
    )
    assert "matches the code" in err


def test_a_runs_file_that_lacks_runs_or_has_other_settings_is_reported(tmp_path: Path) -> None:
    root = _copy_published(tmp_path)
    meta, runs = _published()
    kept = [r for r in runs if (r["variant"], r["n"], r["seed"]) != ("linger", 10, 42)]
    kept.append(kept[0])
    spoiled = meta | {"robots": tables.ROBOTS + 1}
    (root / section5.RUNS_FILE).write_text(section5.runs_json(kept, spoiled))
    problems = section5.coverage_problems(*section5.read_runs(root))
    assert problems == [
        f"{section5.RUNS_FILE}: meta robots {tables.ROBOTS + 1}, the code {tables.ROBOTS}",
        f"{section5.RUNS_FILE}: 1 run(s) missing: linger n=10 seed 42",
        f"{section5.RUNS_FILE}: 1 run(s) twice",
    ]
    assert section5.check_all(root, [])[:3] == problems


def test_the_published_runs_file_holds_every_run_it_promises() -> None:
    meta, runs = _published()
    assert section5.coverage_problems(meta, runs) == []
    assert len(runs) == len(tables.VARIANTS) * len(tables.SITES) * meta["seeds"]


def test_sample_goes_with_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = _copy_published(tmp_path)
    with pytest.raises(SystemExit) as raised:
        main(["section5", "--sample", "--root", str(root)])
    assert raised.value.code == 2
    assert "--sample goes with --check" in capsys.readouterr().err


def test_a_number_of_the_text_that_the_runs_do_not_give_is_named(tmp_path: Path) -> None:
    """The text's numbers are checked against the runs as the tables are: it once said 61%
    of the robots where the runs gave 63%."""
    root = _copy_published(tmp_path)
    assert section5.check_all(root, []) == []
    page = root / "docs" / "section5.md"
    page.write_text(
        page.read_text().replace("Most robots manage it (63%)", "Most robots manage it (61%)")
    )
    assert section5.check_all(root, []) == [
        "docs/section5.md: the prose says 61 where the runs give 63, in 'Most robots manage it "
        "(63%)'"
    ]
    page.write_text(page.read_text().replace("Most robots manage it (61%)", "Few manage it"))
    (problem,) = section5.check_all(root, [])
    assert "the prose no longer says 'Most robots manage it ({}%)'" in problem
