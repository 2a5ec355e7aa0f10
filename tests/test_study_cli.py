"""``swarm study`` without runs: ``--list``, ``--status`` (its last line ``N done, M
missing``), ``--render`` from a results file, and bad arguments (exit code 2, one line)."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from deploy.cli import main
from deploy.study import lock, results
from deploy.study.catalogue import study_named

REPO = Path(__file__).resolve().parent.parent

TINY = REPO / "tests" / "study_tiny.py"


def _tiny_root(tmp_path: Path, made: int) -> Path:
    """A root with the tiny study's page and ``made`` of its runs in its results file."""
    import study_tiny

    (tmp_path / study_tiny.PAGE).write_text(study_tiny.page_text())
    study = study_named("tiny", [TINY])
    with results.Appender(tmp_path / study.results) as appender:
        for run in study.runs()[:made]:
            result = {"ended": "timeout", "sim_time_s": 60.0, "verdict": "undecided"}
            appender.add({"key": run.key, "params": dict(run.params), "seed": run.seed,
                          "result": result, "wall_s": 1.0, "commit": "abc1234",
                          "dirty": False, "lock": "0123456789ab"})  # fmt: skip
    return tmp_path


def _study(root: Path, *arguments: str) -> int:
    return main(["study", *arguments, "--root", str(root), "--declared", str(TINY)])


def test_status_ends_with_done_and_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=2)
    assert _study(root, "tiny", "--status") == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1] == "2 done, 5 missing"
    assert "  drop: 0 2/4, 0.2 0/3" in lines
    assert "  made at: abc1234 (2)" in lines
    assert _study(root, "tiny", "--status", "--only", "drop=0.2") == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == "0 done, 3 missing"


def test_status_counts_parameters_that_only_some_points_have(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["study", "strategies", "--status"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    # only the swarm runs have a message loss: 4 strategies x 4 n x 30 seeds each
    assert any(re.fullmatch(r"  drop: 0 \d+/480, 0.2 \d+/480", line) for line in lines)
    assert re.fullmatch(r"\d+ done, \d+ missing", lines[-1])


def test_status_warns_of_a_torn_last_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=1)
    with (root / "docs" / "studies" / "tiny.jsonl").open("a") as file:
        file.write('{"key": "drop=0 eng')
    assert _study(root, "tiny", "--status") == 0
    captured = capsys.readouterr()
    assert captured.out.strip().splitlines()[-1] == "1 done, 6 missing"
    assert "its last line is not a whole run" in captured.err


def test_list_names_every_study_with_its_size(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=3)
    assert _study(root, "--list") == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    assert names == [
        "strategies",
        "byzantine",
        "defence",
        "robustness",
        "section5-settings",
        "scale",
        "tiny",
    ]
    assert lines[-1].split()[1:7] == ["7", "runs,", "3", "done,", "4", "missing"]


def test_render_writes_the_blocks_and_files_from_the_results_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=2)
    assert _study(root, "tiny", "--render") == 0
    page = (root / "tiny.md").read_text()
    assert "2 of the 7 runs the study declares" in page
    assert "**5 runs are missing**" in page
    assert "| inprocess | 0 | 1 | timeout | 60.0 |" in page
    assert len(json.loads((root / "tiny.json").read_text())) == 2
    assert "5 of the 7 runs of tiny are missing" in capsys.readouterr().err.replace("\n", " ")


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["nosuch"], "no study 'nosuch' (there are strategies, byzantine"),
        ([], "give a study's name"),
        (["tiny", "--sample", "2"], "--sample goes with --check"),
        (["tiny", "--sample-seed", "2"], "--sample-seed goes with --check"),
        (["tiny", "--status", "--sample-budget", "9"], "--sample-budget goes with --check"),
        (["tiny", "--only", "robots=10"], "--only robots=...: no such parameter"),
        (["tiny", "--only", "drop=0.5"], "--only drop=0.5: no run has it (drop: 0, 0.2)"),
        (["tiny", "--only", "drop"], "give NAME=VALUE"),
        (["--check", "--only", "drop=0"], "--only goes with a study's name"),
        (["--list", "--only", "drop=0"], "--list names every study: it takes no --only"),
        (["tiny", "--render", "--only", "seed=1"], "--render writes the whole study's pages"),
    ],
)
def test_bad_arguments_exit_with_code_2_and_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], arguments: list[str], message: str
) -> None:
    root = _tiny_root(tmp_path, made=0)
    with pytest.raises(SystemExit) as exit_info:
        _study(root, *arguments)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert message in lines[-1] and sum("error" in line for line in lines) == 1


def test_a_results_file_that_cannot_be_read_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=0)
    (root / "docs" / "studies" / "tiny.jsonl").unlink()
    (root / "docs" / "studies" / "tiny.jsonl").mkdir()  # a folder where the file goes
    with pytest.raises(SystemExit) as exit_info:
        _study(root, "tiny", "--parallel", "1")
    assert exit_info.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("swarm study: error: ") and "tiny.jsonl: Is a directory" in line


def test_render_without_the_pages_markers_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _tiny_root(tmp_path, made=1)
    (root / "tiny.md").write_text("# no markers\n")
    with pytest.raises(SystemExit) as exit_info:
        _study(root, "tiny", "--render")
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1
    assert "tiny.md: no block 'table': add the lines <!-- BEGIN generated by" in lines[0]


def test_render_with_only_leaves_the_pages_as_they_were(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Rendering part of a study would publish part of it as the whole: refused."""
    root = _tiny_root(tmp_path, made=3)
    assert _study(root, "tiny", "--render") == 0
    before = (root / "tiny.md").read_text(), (root / "tiny.json").read_text()
    with pytest.raises(SystemExit) as exit_info:
        _study(root, "tiny", "--render", "--only", "seed=1")
    assert exit_info.value.code == 2
    assert ((root / "tiny.md").read_text(), (root / "tiny.json").read_text()) == before
    assert "3 of the 7 runs the study declares" in before[0]


@pytest.mark.parametrize("mode", [[], ["--status"], ["--render"], ["--check"]])
def test_a_root_without_the_study_is_refused_unless_new(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: list[str]
) -> None:
    """A mistyped --root would start the whole study again in a new folder."""
    for root, says in [
        (tmp_path / "nosuch", "no such folder (--new starts a new one there)"),
        (tmp_path, "holds none of study tiny's files (docs/studies/tiny.jsonl, tiny.md)"),
    ]:
        with pytest.raises(SystemExit) as exit_info:
            _study(root, "tiny", *mode)
        assert exit_info.value.code == 2
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert line.startswith("swarm study: error: --root ") and says in line
    assert not (tmp_path / "nosuch").exists()
    with pytest.raises(SystemExit):
        _study(tmp_path / "nosuch", "--list")
    assert "no such folder" in capsys.readouterr().err
    # --new: a new folder is meant, and made.
    assert _study(tmp_path / "nosuch", "tiny", "--status", "--new") == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == "0 done, 7 missing"
    assert (tmp_path / "nosuch").is_dir()


def test_bad_arguments_print_the_line_the_docs_show(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/studies.md shows what a bad argument prints; it is what is printed."""
    docs = (REPO / "docs" / "studies.md").read_text()
    shown = re.search(r"\$ swarm study nosuch\n(swarm study: error: [^\n]*)\n", docs)
    assert shown is not None, "docs/studies.md shows no bad argument's line"
    with pytest.raises(SystemExit) as exit_info:
        main(["study", "nosuch"])
    assert exit_info.value.code == 2
    printed = capsys.readouterr().err.strip().splitlines()
    assert printed == [shown.group(1)]


def test_a_second_runner_on_one_results_file_is_refused_and_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two runners on one results file would both make every missing run."""
    root = _tiny_root(tmp_path, made=0)
    results_file = root / "docs" / "studies" / "tiny.jsonl"
    with lock.holding(results_file):  # a runner at work
        with pytest.raises(SystemExit) as exit_info:
            _study(root, "tiny", "--parallel", "1", "--quiet")
        assert exit_info.value.code == 2
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert f"is being made by pid {os.getpid()} on " in line and "give --wait" in line
    assert results.load(results_file).runs == {}  # the second runner made nothing


def test_a_check_prints_its_sample_and_the_command_that_draws_it_again(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A failure of make check-published can be made again: the check names its seed."""
    root = _tiny_root(tmp_path, made=6)  # results that the code does not give: it fails
    arguments = ["tiny", "--check", "--parallel", "1", "--sample-seed", "5", "--sample", "2"]
    assert _study(root, *arguments) == 1
    printed = capsys.readouterr().out.splitlines()
    command = "swarm study tiny --check --sample-seed 5 --sample 2"
    assert printed[0] == f"tiny: sample seed 5 (`{command}` draws it again):"
    assert printed[1].startswith("  inprocess: ")
    drawn = printed[1]
    assert len(drawn.split(", ")) == 2  # two of the kind
    assert _study(root, *command.split()[2:], "--parallel", "1") == 1
    assert capsys.readouterr().out.splitlines()[1] == drawn  # the same runs, drawn again
