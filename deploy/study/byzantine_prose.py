"""The numbers docs/byzantine.md's and docs/security.md's text read from the study
``byzantine``, checked against its runs (``prose.Claim``), and the table of security.md's
section on Byzantine robots, rendered from the runs."""

from __future__ import annotations

import statistics
from typing import Any

from deploy.analysis import effects
from deploy.analysis.prose import Claim, fixed
from deploy.analysis.wilson import share
from deploy.study import byzantine_runs as study
from deploy.study import tables
from deploy.study.declare import Records

PAPER, A005, A01, LOGLINEAR = (defence.key for defence in study.DEFENCES)
DISTRUST = (A005, A01, LOGLINEAR)


def _cells(records: Records) -> dict[tuple[str, int, str], dict[str, Any]]:
    return {(row["mode"], row["count"], row["defence"]): row for row in study.cells(records)}


def _complete(cells: dict[tuple[str, int, str], dict[str, Any]]) -> bool:
    wanted = len(study.MODES) * (study.MAX_BYZANTINE + 1) * len(study.DEFENCES)
    return len(cells) == wanted


def security_table(records: Records) -> str:
    """security.md's table: per Byzantine robots and defence, the runs in which every
    honest robot decided the best site, with their 95% interval."""
    cells = _cells(records)
    lines = [
        "| Byzantine robots (of 10) | "
        + " | ".join(defence.label for defence in study.DEFENCES)
        + " |",
        "|---|" + "---:|" * len(study.DEFENCES),
    ]
    for mode in study.MODES:
        for count in range(1, study.MAX_BYZANTINE + 1):
            found = [cells.get((mode, count, defence.key)) for defence in study.DEFENCES]
            if any(row is None for row in found):
                continue
            name = f"{count} {mode}" + ("s" if mode == "liar" and count > 1 else "")
            lines.append(
                f"| {name} | "
                + " | ".join(share(row["correct"], row["runs"]) for row in found if row)
                + " |"
            )
    return "\n".join(lines)


def _times(cells: dict[tuple[str, int, str], dict[str, Any]]) -> list[str]:
    """The median consensus time without Byzantine robots, per defence."""
    return [
        fixed(statistics.median(cells["liar", 0, defence.key]["times"].values()))
        for defence in study.DEFENCES
    ]


def _ratios(cells: dict[tuple[str, int, str], dict[str, Any]], mode: str, count: int) -> list[str]:
    found = []
    for defence in DISTRUST:
        ratio = effects.paired_median_ratio(
            cells[mode, count, defence]["times"], cells[mode, count, PAPER]["times"]
        )
        found.append("-" if ratio is None else fixed(ratio.value, 2))
    return found


def claims(records: Records) -> list[Claim]:
    """The numbers of byzantine.md's short answers and measurement notes."""
    cells = _cells(records)
    if not _complete(cells):
        return []
    runs = cells["liar", 1, PAPER]["runs"]

    def right(mode: str, count: int, defence: str) -> str:
        return str(cells[mode, count, defence]["correct"])

    def won(count: int, defence: str) -> str:
        return str(cells["liar", count, defence]["liar_won"])

    distrust_one = max(cells["liar", 1, key]["correct"] for key in DISTRUST)
    distrust_two = max(cells["liar", 2, key]["correct"] for key in DISTRUST)
    same_alpha = cells["inverted", 1, A005]["correct"] == cells["inverted", 1, A01]["correct"]
    silent = min(
        cells["silent", count, key]["correct"] for count in range(1, 4) for key in study.LABELS
    )
    slower = []
    for defence in study.DEFENCES:
        ratio = effects.paired_median_ratio(
            cells["silent", study.MAX_BYZANTINE, defence.key]["times"],
            cells["silent", 0, defence.key]["times"],
        )
        assert ratio is not None
        slower.append(ratio.value)
    three = [int(won(3, key)) for key in DISTRUST]
    undecided = sum(int(tables.result(record)["verdict"] == "undecided") for record in records.runs)
    example = next(
        (
            tables.result(record)
            for record in records.runs
            if record["key"] == "byzantine=1 defence=a01 mode=liar seed=7"
        ),
        None,
    )
    found = [
        Claim(
            "left the honest robots all on the best site in {} of {} runs with the paper's "
            "controller (alpha = 0, MProdOp), and in {} of {} with any alpha > 0"
            if distrust_one == 0
            else "left the honest robots all on the best site in {} of {} runs with the "
            "paper's controller (alpha = 0, MProdOp), and in at most {} of {} with alpha > 0",
            (right("liar", 1, PAPER), str(runs), str(distrust_one), str(runs)),
        ),
        Claim(
            "With two liars: {} of {} (alpha = 0), {} of {} (the rest); with alpha > 0 most of "
            "those runs became a consensus on the liars' site ({}, {} and {} of {} with two "
            "liars, {} to {} of {} with three).",
            (
                right("liar", 2, PAPER),
                str(runs),
                str(distrust_two),
                str(runs),
                *(won(2, key) for key in DISTRUST),
                str(runs),
                str(min(three)),
                str(max(three)),
                str(runs),
            ),
        ),
        Claim(
            "One inverted robot: {} of {} runs right with alpha = 0, {} of {} with alpha = "
            + ("0.05 or 0.1" if same_alpha else "0.05 (and another count with 0.1)")
            + ", {} of {} with the log-linear pool at alpha = 0.1. Three inverted robots: {}, "
            "{}, {} and {} of {}.",
            (
                right("inverted", 1, PAPER),
                str(runs),
                right("inverted", 1, A005),
                str(runs),
                right("inverted", 1, LOGLINEAR),
                str(runs),
                *(right("inverted", 3, defence.key) for defence in study.DEFENCES),
                str(runs),
            ),
        ),
        Claim(
            "without Byzantine robots the median consensus takes {} s (alpha = 0), {} s "
            "(0.05), {} s (0.1) and {} s (log-linear): {}, {} and {} times alpha = 0's",
            (*_times(cells), *_ratios(cells, "liar", 0)),
        ),
        Claim(
            (
                "**A silent robot is harmless:** {} of {} right with up to three, for every defence"
                if silent == runs
                else "**A silent robot is not harmless:** at least {} of {} right"
            )
            + "; the swarm is a little slower (smaller pools; with three, median times {} to "
            "{} times those without)",
            (str(silent), str(runs), fixed(min(slower), 2), fixed(max(slower), 2)),
        ),
        Claim(
            "not a stall: none of the {} runs hit the {} s timeout."
            if undecided == 0
            else "not a stall: {} of the runs hit the {} s timeout.",
            (str(len(records.runs) if undecided == 0 else undecided), f"{study.TIMEOUT:g}"),
        ),
        Claim(
            "The findings above were read from the {} runs of the results file",
            (str(len(records.runs)),),
        ),
    ]
    if example is not None:
        found.append(
            Claim(
                "this run ends at {} s with the nine honest robots on the liar's site {}, "
                f"digest `{example['digest']}`",
                (fixed(example["sim_time_s"], 1), str(example["chosen_site"])),
            )
        )
    return found


def security_claims(records: Records) -> list[Claim]:
    """The numbers of security.md's section on Byzantine robots."""
    cells = _cells(records)
    if not _complete(cells):
        return []
    runs = cells["liar", 1, PAPER]["runs"]

    def won(count: int) -> list[str]:
        return [str(cells["liar", count, key]["liar_won"]) for key in DISTRUST]

    return [
        Claim("{} in-process lockstep runs made by", (str(len(records.runs)),)),
        Claim(
            "the swarm mostly splits ({} of {} runs with one liar)",
            (str(cells["liar", 1, PAPER]["split"]), str(runs)),
        ),
        Claim(
            "on the liars' site in {}, {} and {} of {} runs with one liar (alpha = 0.05, alpha "
            "= 0.1, log-linear), {}, {} and {} with two, {}, {} and {} with three",
            (*won(1), str(runs), *won(2), *won(3)),
        ),
        Claim(
            "median consensus takes {} s (paper), {} s, {} s and {} s (log-linear): {}, {} and "
            "{} times the paper's",
            (*_times(cells), *_ratios(cells, "liar", 0)),
        ),
    ]
