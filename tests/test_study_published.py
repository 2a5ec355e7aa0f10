"""The published runs of every study are what today's code gives: a sample of each
study's results file made again (``swarm study NAME --check``: one run of each kind of run
the study has, drawn at random within a budget), every field of each compared.
``make check-published`` runs it (``pytest --published``) with the seed of the draw in
``STUDY_CHECK_SEED`` (the Makefile sets the day's date), and each study's sample, with
the command that draws it again, is printed."""

from __future__ import annotations

import os

import pytest

from deploy.cli import main
from deploy.study import check
from deploy.study.catalogue import studies

SEED = int(os.environ.get("STUDY_CHECK_SEED") or check.todays_seed())


@pytest.mark.timeout(900)
@pytest.mark.parametrize("name", sorted(studies()))
def test_a_sample_of_the_published_runs_is_what_the_code_gives(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["study", name, "--check", "--sample-seed", str(SEED), "--parallel", "2"])
    printed = capsys.readouterr().out
    with capsys.disabled():  # the sample and how to draw it again, in the log
        print(f"\n{printed.strip()}")
    assert code == 0, printed
