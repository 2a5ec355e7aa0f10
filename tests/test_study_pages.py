"""Every published block is what its study's results file gives (``swarm study NAME
--render`` writes it; the figures are drawn from the same records and not compared), and
the "Made by" block says how many runs are missing and what made the others."""

from __future__ import annotations

from pathlib import Path

import pytest

from deploy.study import page
from deploy.study.catalogue import studies
from deploy.study.declare import Records
from deploy.study.state import state_of

REPO = Path(__file__).resolve().parent.parent

STUDIES = studies()


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_the_pages_are_what_the_results_file_gives(name: str) -> None:
    study = STUDIES[name]
    state = state_of(study, REPO)
    assert state.loaded.skipped == []
    assert page.stale_blocks(study, state.records(), REPO) == []


@pytest.mark.parametrize("name", sorted(STUDIES))
def test_every_run_in_a_results_file_is_declared(name: str) -> None:
    assert state_of(STUDIES[name], REPO).undeclared == []


def test_the_made_block_says_what_is_missing_and_what_made_the_rest() -> None:
    study = STUDIES["scale"]
    records = [
        {"key": "k0", "commit": "abc1234", "dirty": False, "lock": "0123456789ab"},
        {"key": "k1", "commit": "abc1234", "dirty": True, "lock": "0123456789ab"},
    ]
    text = page.made_block(study, Records(records, 5))
    assert "`swarm study scale --render`" in text
    assert "2 of the 5 runs" in text
    assert "**3 runs are missing**" in text
    assert "commit abc1234 (1 run), commit abc1234 with uncommitted changes (1 run)" in text
    assert "0123456789ab (2 runs)" in text
    assert "missing" not in page.made_block(study, Records(records, 2))


def test_a_block_without_its_markers_names_the_lines_to_add() -> None:
    study = STUDIES["scale"]
    with pytest.raises(ValueError, match="add the lines"):
        page.replace_block("no markers here", study, "runs", "x")
    marked = f"{page.begin_marker(study, 'runs')}\nold\n{page.end_marker(study, 'runs')}"
    replaced = page.replace_block(marked, study, "runs", "new")
    assert page.read_block(replaced, study, "runs") == "new"
