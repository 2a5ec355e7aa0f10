"""The study ``byzantine``: Byzantine robots against the swarm's defences
(docs/byzantine.md, the main table and docs/byzantine.png).

10 robots, n = 10, seeds 0-39, timeout 1200 sim s, for 0 to 3 Byzantine robots of each
mode (``liar``: broadcasts certainty of one site, the same non-best site for every liar of
a run; ``inverted``: eliminates the better site of each pair; ``silent``: never
broadcasts), under four defences: the paper's controller (alpha = 0, MProdOp); distrust,
alpha = 0.05 and 0.1 with threshold 0.99 (MProdOp); distrust with the diluting pool
(alpha = 0.1, ``--pooling loglinear``). Which robots misbehave is a seeded draw per run
(``byzantine_ids``), nested: the 2 Byzantine robots of a seed include its 1, and its 3
include those 2. The runs without Byzantine robots (``mode=none``) count for every mode.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bestofn_swarm.wire.rng import Stream
from deploy.analysis.wilson import share
from deploy.study import byzantine_prose, tables
from deploy.study.byzantine_runs import (
    DEFENCES,
    LABELS,
    MAX_BYZANTINE,
    MODES,
    ROBOTS,
    SEEDS,
    SITES,
    TIMEOUT,
    cells,
)
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point


def byzantine_ids(seed: int, robots: int, count: int) -> list[int]:
    """The ``count`` Byzantine robots of run ``seed``: a seeded draw, nested in ``count``."""
    drawn = Stream.named(seed, "benchmark", "byzantine").sample(range(robots), MAX_BYZANTINE)
    return sorted(drawn[:count])


def switches(mode: str, count: int, robots: int = ROBOTS) -> Any:
    """The ``--byzantine ID:MODE`` options of a run, as a function of its seed."""

    def of_seed(seed: int) -> list[str]:
        found = []
        for robot in byzantine_ids(seed, robots, count):
            found += ["--byzantine", f"{robot}:{mode}"]
        return found

    return of_seed


def points() -> list[Point]:
    found = []
    for defence in DEFENCES:
        for mode, count in [("none", 0)] + [
            (m, c) for m in MODES for c in range(1, MAX_BYZANTINE + 1)
        ]:
            found.append(
                Point(
                    {"mode": mode, "byzantine": count, "defence": defence.key},
                    SEEDS,
                    options=["--robots", str(ROBOTS), "--sites", str(SITES), *defence.options],
                    timeout=TIMEOUT,
                    cost=5.0,
                    per_seed=switches(mode, count),
                )
            )
    return found


# --- the page ------------------------------------------------------------------------------


def table(records: Records) -> str:
    lines = [
        "| n | mode | Byzantine | defence | correct (95% interval) | wrong consensus | split "
        "| undecided at timeout | median consensus time (sim s) | against the paper's "
        "controller: ratio of medians (95% interval) |",
        "|---:|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    rows = cells(records)
    for row in rows:
        runs = row["runs"]
        wrong = tables.counted(row["wrong"], runs)
        if row["mode"] == "liar" and row["count"] > 0:
            wrong += f", {row['liar_won']} the liars' site"
        paper = next(
            other
            for other in rows
            if other["defence"] == "paper"
            and (other["mode"], other["count"]) == (row["mode"], row["count"])
        )
        against = (
            "1 (the baseline)"
            if row["defence"] == "paper"
            else tables.compare_times(row["times"], paper["times"], tables.CONSENSUS_RUNS)
        )
        lines.append(
            f"| {SITES} | {row['mode']} | {row['count']} | {LABELS[row['defence']]} "
            f"| {share(row['correct'], runs)} | {wrong} | {tables.counted(row['split'], runs)} "
            f"| {tables.counted(row['undecided'], runs)} "
            f"| {tables.number(tables.median(row['times'].values()))} | {against} |"
        )
    return "\n".join(lines)


def results_block(records: Records) -> str:
    hit = sum(tables.result(record)["verdict"] == "undecided" for record in records.runs)
    return "\n".join(
        [
            "",
            f"{tables.runs(len(records.runs))}: {ROBOTS} robots, n = {SITES}, seeds "
            f"{SEEDS.start}-{SEEDS.stop - 1} per row, timeout {TIMEOUT:g} sim s ({hit} "
            f"run{'' if hit == 1 else 's'} hit it). The rows with 0 Byzantine robots are the "
            "same runs in every mode.",
            "",
            table(records),
            "",
        ]
    )


COLOURS = {"paper": "tab:red", "a005": "tab:orange", "a01": "tab:blue", "loglinear": "tab:green"}
MARKERS = {"paper": "o", "a005": "v", "a01": "s", "loglinear": "^"}


def plot(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    rows = cells(records)
    figure, axes = plt.subplots(1, len(MODES), figsize=(4.2 * len(MODES), 3.8), sharey=True)
    for axis, mode in zip(axes, MODES, strict=True):
        for number, defence in enumerate(DEFENCES):
            # Each defence a little to the side, so that equal shares stay visible.
            nudge = (number - (len(DEFENCES) - 1) / 2) * 0.06
            mine = [row for row in rows if row["mode"] == mode and row["defence"] == defence.key]
            bars = [tables.error_bar(row["correct"], row["runs"]) for row in mine]
            tables.plot_bars(
                axis,
                [row["count"] + nudge for row in mine],
                bars,
                fmt="-",
                color=COLOURS[defence.key],
                marker=MARKERS[defence.key],
                capsize=2,
                label=defence.label,
            )
        if not rows:
            tables.no_runs_yet(axis)
        axis.set_title(f"{mode}, n = {SITES}")
        axis.set_xticks(range(MAX_BYZANTINE + 1))
        axis.set_ylim(-0.05, 1.05)
        axis.grid(alpha=0.3)
        axis.set_xlabel(f"Byzantine robots (of {ROBOTS})")
    axes[0].set_ylabel("share of runs: honest robots all chose the best")
    axes[0].legend(loc="lower left", fontsize="small")
    seeds = len(SEEDS)
    figure.suptitle(
        f"Byzantine robots: {seeds} seeds per point, {ROBOTS} robots; bars: 95% interval"
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


STUDY = Study(
    name="byzantine",
    title="Byzantine robots, the main table",
    about="liars, inverted and silent robots against alpha > 0 and the log-linear pool",
    points=points,
    source="deploy/study/byzantine.py",
    pages=(
        Page(
            "docs/byzantine.md",
            lambda records: {"results": results_block(records)},
            claims=byzantine_prose.claims,
        ),
        Page(
            "docs/security.md",
            lambda records: {"byzantine": byzantine_prose.security_table(records)},
            made=False,
            claims=byzantine_prose.security_claims,
        ),
    ),
    outputs=(Output("docs/byzantine.png", plot),),
    kinds=lambda run: (
        "no Byzantine robot" if run.param("mode") == "none" else f"{run.param('mode')} robots"
    ),
)
