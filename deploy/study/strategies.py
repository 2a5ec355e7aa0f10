"""The study ``strategies``: the paper's strategy against its rivals (docs/strategies.md).

Two parts, one results file:

* ``part=wellstirred``: the Section 4 model for the paper's strategy (N = 100 agents
  shuffled into pools of k = 3) and for DMVD, DMMD and DC (the same 100 agents, dmmd's
  group of 3: itself and 2 neighbours), n = 5, 10, 20, 50 and 100, one cell of 100 runs
  per point (``make.make_wellstirred``);
* ``part=swarm``: whole lockstep runs, every ``--strategy``, n = 5, 8, 10 and 20 sites,
  without and with 20% message loss (``--drop 0.2``), 10 robots (seeds 0-19) and 50
  robots (seeds 0-9), timeout 2400 sim s: ``swarm run --robots R --sites n --strategy S
  --drop D --seed S --timeout 2400``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from deploy.analysis import effects
from deploy.analysis.wilson import share
from deploy.study import strategies_prose, tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point, product
from deploy.study.make import WELLSTIRRED_AGENTS
from deploy.study.strategies_runs import (
    DROPS,
    SEEDS,
    SITES,
    STRATEGIES,
    TIMEOUT,
    WELLSTIRRED_OPTIONS,
    swarm_rows,
    wellstirred_rows,
)

COST = {10: 6.0, 50: 42.0}  # wall seconds a run takes, about (the mean of earlier runs)


def points() -> list[Point]:
    found = [
        Point(
            {"part": "wellstirred", "strategy": strategy, "options": n},
            (0,),
            "wellstirred",
            cost=5.0,
        )
        for strategy in STRATEGIES
        for n in WELLSTIRRED_OPTIONS
    ]
    for robots, seeds in SEEDS.items():
        for axes in product(sites=SITES, drop=DROPS, strategy=STRATEGIES):
            params = {"part": "swarm", "robots": robots, **axes}
            options = [
                "--robots", str(robots), "--sites", str(axes["sites"]),
                "--strategy", str(axes["strategy"]), "--drop", f"{axes['drop']:g}",
            ]  # fmt: skip
            found.append(Point(params, seeds, options=options, timeout=TIMEOUT, cost=COST[robots]))
    return found


# --- the page ------------------------------------------------------------------------------


def _baseline(rows: list[dict[str, Any]], row: dict[str, Any], *keys: str) -> dict[str, Any]:
    """The paper's row at the same point as ``row`` (the same ``keys``)."""
    return next(
        other
        for other in rows
        if other["strategy"] == "paper" and all(other[key] == row[key] for key in keys)
    )


def _against_paper(rows: list[dict[str, Any]], row: dict[str, Any], *keys: str) -> str:
    if row["strategy"] == "paper":
        return "1 (the baseline)"
    # The swarm's runs are paired by seed; the well-stirred cells' runs are not.
    times = "by_seed" if "by_seed" in row else "times"
    return tables.compare_times(row[times], _baseline(rows, row, *keys)[times])


def wellstirred_table(records: Records) -> str:
    lines = [
        "| strategy | n | right consensus (95% interval) | steps to consensus, median (IQR), "
        "right runs | steps against the paper's: ratio of medians (95% interval) |",
        "|---|---:|---:|---|---:|",
    ]
    rows = wellstirred_rows(records)
    for row in rows:
        lines.append(
            f"| {row['strategy']} | {row['n']} | {share(row['correct'], row['runs'])} "
            f"| {tables.number(row['median'], 1)} ({tables.number(row['q1'], 1)}-"
            f"{tables.number(row['q3'], 1)}) | {_against_paper(rows, row, 'n')} |"
        )
    return "\n".join(lines)


def swarm_table(records: Records) -> str:
    lines = [
        "| robots | n | message loss | strategy | runs | right (95% interval) | wrong | split "
        "| undecided | sim s to consensus, median (right runs) | against the paper's: ratio "
        "of medians (95% interval) | trips of the last robot, median |",
        "|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    rows = swarm_rows(records)
    for row in rows:
        runs = row["runs"]
        lines.append(
            f"| {row['robots']} | {row['n']} | {row['drop']:.0%} | {row['strategy']} "
            f"| {runs} | {share(row['correct'], runs)} | {tables.counted(row['wrong'], runs)} "
            f"| {tables.counted(row['split'], runs)} "
            f"| {tables.counted(row['undecided'], runs)} | {tables.number(row['median'])} "
            f"| {_against_paper(rows, row, 'robots', 'n', 'drop')} "
            f"| {tables.number(row['steps'], 1)} |"
        )
    return "\n".join(lines)


def blocks(records: Records) -> dict[str, str]:
    return {"wellstirred": wellstirred_table(records), "swarm": swarm_table(records)}


COLOURS = {"paper": "tab:red", "dmvd": "tab:blue", "dmmd": "tab:orange", "dc": "tab:green"}


def plot(records: Records, path: Path) -> None:
    """Accuracy (with its 95% interval) and time against n: well-stirred, then the swarm
    at each size."""
    plt = tables.pyplot()
    well = wellstirred_rows(records)
    swarm = swarm_rows(records)
    robots = sorted(SEEDS)
    figure, axes = plt.subplots(2, 1 + len(robots), figsize=(5 * (1 + len(robots)), 7.5))
    for strategy in STRATEGIES:
        mine = [row for row in well if row["strategy"] == strategy]
        _accuracy(axes[0][0], mine, "o-", COLOURS[strategy])
        _times(axes[1][0], mine, "o-", COLOURS[strategy], strategy)
    if not well:
        tables.no_runs_yet(axes[0][0])
    axes[0][0].set_title(f"well-stirred, N = {WELLSTIRRED_AGENTS}, group 3")
    axes[1][0].set_ylabel("steps to consensus, median of right runs")
    axes[0][0].set_ylabel("share of runs: consensus on the best")
    axes[1][0].set_yscale("log")
    for column, count in enumerate(robots, start=1):
        drawn = False
        for strategy in STRATEGIES:
            for drop, style in ((0.0, "o-"), (0.2, "s--")):
                mine = [
                    row
                    for row in swarm
                    if row["robots"] == count
                    and row["strategy"] == strategy
                    and row["drop"] == drop
                ]
                if not mine:
                    continue
                drawn = True
                _accuracy(axes[0][column], mine, style, COLOURS[strategy])
                _times(
                    axes[1][column], mine, style, COLOURS[strategy], f"{strategy}, {drop:.0%} loss"
                )
        if not drawn:
            tables.no_runs_yet(axes[0][column])
        axes[0][column].set_title(f"swarm, {count} robots")
        axes[1][column].set_ylabel("sim s to consensus, median of right runs")
    for axis in axes[1]:
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize="x-small", ncols=2)
    for axis in axes[0]:
        axis.set_ylim(-0.05, 1.05)
    for axis in [*axes[0], *axes[1]]:
        axis.set_xlabel("n (options / sites)")
        axis.grid(alpha=0.3)
    figure.suptitle(
        "bars: 95% Wilson interval of the share of runs (top), 95% bootstrap interval of the "
        f"median (bottom; none with fewer than {effects.MIN_RUNS} right runs)",
        fontsize="small",
    )
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _times(axis: Any, rows: list[dict[str, Any]], style: str, colour: str, label: str) -> None:
    """The median time of the right runs of each row and its 95% bootstrap interval."""
    bars = [tables.median_bar(row["times"]) for row in rows]
    tables.plot_bars(
        axis, [row["n"] for row in rows], bars, fmt=style, color=colour, capsize=2, label=label
    )


def _accuracy(axis: Any, rows: list[dict[str, Any]], style: str, colour: str) -> None:
    bars = [tables.error_bar(row["correct"], row["runs"]) for row in rows]
    tables.plot_bars(axis, [row["n"] for row in rows], bars, fmt=style, color=colour, capsize=2)


STUDY = Study(
    name="strategies",
    title="rivals in the swarm",
    about="the paper's strategy against DMVD, DMMD and DC: well-stirred and in the swarm",
    points=points,
    source="deploy/study/strategies.py",
    pages=(Page("docs/strategies.md", blocks, claims=strategies_prose.claims),),
    outputs=(Output("docs/strategies.png", plot),),
    kinds=lambda run: (
        "a well-stirred cell"
        if run.param("part") == "wellstirred"
        else f"a {run.param('robots')}-robot swarm"
    ),
)
