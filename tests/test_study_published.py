"""The published runs of every study are what today's code gives: a sample of each
study's results file made again (``swarm study NAME --check``, cheap runs first, spread
over its points), every field of each compared. ``make check-published`` runs it
(``pytest --published``)."""

from __future__ import annotations

import pytest

from deploy.cli import main
from deploy.study.catalogue import studies

SAMPLE = 3  # runs per study


@pytest.mark.timeout(900)
@pytest.mark.parametrize("name", sorted(studies()))
def test_a_sample_of_the_published_runs_is_what_the_code_gives(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["study", name, "--check", "--sample", str(SAMPLE), "--parallel", "2"])
    assert code == 0, capsys.readouterr().out
