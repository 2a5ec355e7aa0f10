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

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bestofn_swarm.wire.rng import Stream
from deploy.study import tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point
from deploy.study.wilson import share

MODES = ("liar", "inverted", "silent")
MAX_BYZANTINE = 3
ROBOTS = 10
SITES = 10
SEEDS = range(40)
TIMEOUT = 1200.0  # sim seconds


@dataclass(frozen=True)
class Defence:
    """A controller set-up, as ``swarm run`` options."""

    key: str
    label: str
    options: tuple[str, ...]


DEFENCES = (
    Defence("paper", "alpha = 0, MProdOp (paper)", ()),
    Defence("a005", "alpha = 0.05, MProdOp", ("--alpha", "0.05", "--threshold", "0.99")),
    Defence("a01", "alpha = 0.1, MProdOp", ("--alpha", "0.1", "--threshold", "0.99")),
    Defence(
        "loglinear",
        "alpha = 0.1, log-linear pool",
        ("--alpha", "0.1", "--threshold", "0.99", "--pooling", "loglinear"),
    ),
)
LABELS = {defence.key: defence.label for defence in DEFENCES}


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


def cells(records: Records) -> list[dict[str, Any]]:
    """Per (mode, count, defence); the runs without Byzantine robots count for every mode
    at count 0."""
    grouped: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for record in records.runs:
        params = record["params"]
        for mode in MODES if params["mode"] == "none" else [params["mode"]]:
            grouped.setdefault((mode, params["byzantine"], params["defence"]), []).append(record)
    order = [defence.key for defence in DEFENCES]
    rows = []
    for (mode, count, defence), runs in sorted(
        grouped.items(),
        key=lambda item: (MODES.index(item[0][0]), item[0][1], order.index(item[0][2])),
    ):
        results = [tables.result(run) for run in runs]
        rows.append(
            {
                "mode": mode,
                "count": count,
                "defence": defence,
                "runs": len(runs),
                **{verdict: tables.count(runs, verdict) for verdict in tables.VERDICTS},
                "liar_won": sum(bool(result.get("liar_won")) for result in results),
                "median_time": tables.median(
                    result["sim_time_s"]
                    for result in results
                    if result["verdict"] in ("correct", "wrong")
                ),
            }
        )
    return rows


def table(records: Records) -> str:
    lines = [
        "| n | mode | Byzantine | defence | correct (95% interval) | wrong consensus | split "
        "| undecided at timeout | median consensus time (sim s) |",
        "|---:|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for row in cells(records):
        wrong = f"{row['wrong']}"
        if row["mode"] == "liar" and row["count"] > 0:
            wrong += f" ({row['liar_won']} the liars' site)"
        lines.append(
            f"| {SITES} | {row['mode']} | {row['count']} | {LABELS[row['defence']]} "
            f"| {share(row['correct'], row['runs'])} | {wrong} | {row['split']} "
            f"| {row['undecided']} | {tables.number(row['median_time'])} |"
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
            axis.errorbar(
                [row["count"] + nudge for row in mine],
                [bar[0] for bar in bars],
                yerr=[[bar[1] for bar in bars], [bar[2] for bar in bars]],
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
    pages=(Page("docs/byzantine.md", lambda records: {"results": results_block(records)}),),
    outputs=(Output("docs/byzantine.png", plot),),
)
