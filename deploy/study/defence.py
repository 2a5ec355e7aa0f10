"""The study ``defence``: trimmed pooling (``--defence trimmed --trim F``) against liars
(docs/byzantine.md, the defence table and docs/byzantine-defence.png).

n = 10, timeout 2400 sim s: 0, 1, 2 and 3 liars among 10 robots (seeds 0-19) with the
paper's pooling and with F = 1; 0, 5 and 10 liars among 50 robots (10% and 20%; seeds
0-9) with the paper's pooling, F = 5 and F = 10. Each liar claims the run's liar site
(``--byzantine ID:liar``); which robots lie is a seeded draw per run (``liar_ids``): with
10 robots the Byzantine robots of the main study (``byzantine.byzantine_ids``), else 20%
of the robots drawn once, nested in the count.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bestofn_swarm.wire.rng import Stream
from deploy.analysis import effects
from deploy.analysis.prose import Claim, fixed
from deploy.analysis.wilson import percent_bound, share, wilson
from deploy.study import tables
from deploy.study.byzantine import byzantine_ids
from deploy.study.byzantine_runs import MAX_BYZANTINE
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point

SITES = 10
TIMEOUT = 2400.0  # sim seconds
# Liars per swarm size: 0-3 of 10; 10% and 20% of 50.
LIARS = {10: (0, 1, 2, 3), 50: (0, 5, 10)}
# The defences per swarm size: the paper's pooling, and trimmed pooling with F the liars it
# is set to tolerate (one of 10; 10% of 50, and 20% of 50).
DEFENCES = {10: ("none", "trimmed:1"), 50: ("none", "trimmed:5", "trimmed:10")}
SEEDS = {10: range(20), 50: range(10)}
COST = {10: 23.0, 50: 75.0}  # wall seconds a run takes, about (the mean of earlier runs)
ORDER = ("none", "trimmed:1", "trimmed:5", "trimmed:10")


def liar_ids(seed: int, robots: int, count: int) -> list[int]:
    """The liars of run ``seed``: ``byzantine_ids`` for 10 robots (the same robots as the
    main study), else a seeded draw of 20% of the robots, nested in ``count``."""
    if robots == 10 and count <= MAX_BYZANTINE:
        return byzantine_ids(seed, robots, count)
    most = max(count, robots // 5)
    drawn = Stream.named(seed, "benchmark", "liars").sample(range(robots), most)
    return sorted(drawn[:count])


def defence_options(defence: str) -> list[str]:
    """The defence as ``swarm run`` options."""
    if defence == "none":
        return []
    name, _, trim = defence.partition(":")
    return ["--defence", name, "--trim", trim]


def liars(robots: int, count: int) -> Any:
    def of_seed(seed: int) -> list[str]:
        found = []
        for robot in liar_ids(seed, robots, count):
            found += ["--byzantine", f"{robot}:liar"]
        return found

    return of_seed


def points() -> list[Point]:
    return [
        Point(
            {"robots": robots, "liars": count, "defence": defence},
            SEEDS[robots],
            options=["--robots", str(robots), "--sites", str(SITES), *defence_options(defence)],
            timeout=TIMEOUT,
            cost=COST[robots],
            per_seed=liars(robots, count),
        )
        for robots in LIARS
        for count in LIARS[robots]
        for defence in DEFENCES[robots]
    ]


# --- the page ------------------------------------------------------------------------------


def rows(records: Records) -> list[dict[str, Any]]:
    grouped = tables.groups(records.runs, "robots", "liars", "defence")
    found = []
    for (robots, count, defence), runs in grouped.items():
        results = [tables.result(run) for run in runs]
        times = [result["sim_time_s"] for result in results if result["verdict"] == "correct"]
        found.append(
            {
                "robots": robots,
                "liars": count,
                "defence": defence,
                "runs": len(runs),
                **{verdict: tables.count(runs, verdict) for verdict in tables.VERDICTS},
                "liar_won": sum(bool(result.get("liar_won")) for result in results),
                "times": {
                    run["seed"]: result["sim_time_s"]
                    for run, result in zip(runs, results, strict=True)
                    if result["verdict"] == "correct"
                },
                "median": tables.median(times),
                "mean": tables.mean(times),
            }
        )
    return sorted(found, key=lambda r: (r["robots"], r["liars"], ORDER.index(r["defence"])))


def label(defence: str) -> str:
    if defence == "none":
        return "none (the paper's pooling)"
    return f"trimmed, F = {defence.partition(':')[2]}"


def table(records: Records) -> str:
    lines = [
        "| robots | liars | defence | runs | correct (95% interval) | wrong consensus "
        "| split | undecided | sim s to consensus, median (mean), correct runs | against no "
        "defence: ratio of medians (95% interval) |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---|---:|",
    ]
    found = rows(records)
    for row in found:
        timing = (
            "-"
            if row["median"] is None
            else f"{tables.number(row['median'])} ({tables.number(row['mean'])})"
        )
        bare = next(
            other
            for other in found
            if other["defence"] == "none"
            and (other["robots"], other["liars"]) == (row["robots"], row["liars"])
        )
        against = (
            "1 (the baseline)"
            if row["defence"] == "none"
            else tables.compare_times(row["times"], bare["times"])
        )
        runs = row["runs"]
        lines.append(
            f"| {row['robots']} | {row['liars']} | {label(row['defence'])} | {runs} "
            f"| {share(row['correct'], runs)} | {tables.counted(row['wrong'], runs)}, "
            f"{row['liar_won']} the liars' site | {tables.counted(row['split'], runs)} "
            f"| {tables.counted(row['undecided'], runs)} | {timing} | {against} |"
        )
    return "\n".join(lines)


def defence_claims(records: Records) -> list[Claim]:
    """The numbers of byzantine.md's findings on trimmed pooling."""
    found = {(row["robots"], row["liars"], row["defence"]): row for row in rows(records)}
    wanted = sum(len(LIARS[r]) * len(DEFENCES[r]) for r in LIARS)
    if len(found) < wanted:
        return []

    def right(robots: int, liars: int, name: str) -> tuple[str, str]:
        row = found[robots, liars, name]
        return str(row["correct"]), str(row["runs"])

    def cost(robots: int, name: str) -> tuple[str, str, str]:
        row, bare = found[robots, 0, name], found[robots, 0, "none"]
        ratio = effects.paired_median_ratio(row["times"], bare["times"])
        assert ratio is not None
        low, high = effects.outwards(ratio.low, ratio.high, 2).split("-")
        return fixed(ratio.value, 2), low, high

    small, large = sorted(LIARS)
    lowest = {
        runs: percent_bound(wilson(runs, runs)[0], upper=False)
        for runs in (SEEDS[small].stop, SEEDS[large].stop)
    }
    split_one = found[small, 1, "none"]["split"]
    return [
        Claim(
            "{} of {} correct is consistent with a rate as low as {}%, {} of {} with {}%",
            (
                str(SEEDS[small].stop),
                str(SEEDS[small].stop),
                lowest[SEEDS[small].stop],
                str(SEEDS[large].stop),
                str(SEEDS[large].stop),
                lowest[SEEDS[large].stop],
            ),
        ),
        Claim(
            "One liar among 10: {} of {} runs correct with trimmed pooling (F = 1), against {} "
            "of {} with the paper's pooling (the other {} split). 10% liars among 50 (5 "
            "liars): {} of {} correct with F = 5 and with F = 10, against {} of {} (all split) "
            "with the paper's pooling.",
            (
                *right(small, 1, "trimmed:1"),
                *right(small, 1, "none"),
                str(split_one),
                *right(large, 5, "trimmed:5"),
                *right(large, 5, "none"),
            ),
        ),
        Claim(
            "10 robots, {} s with F = 1 against {} s ({} times, 95% interval {}-{}); 50 robots, "
            "{} s with F = 5 ({} times, {}-{}) and {} s with F = 10 ({} times, {}-{}) against "
            "{} s.",
            (
                fixed(found[small, 0, "trimmed:1"]["median"]),
                fixed(found[small, 0, "none"]["median"]),
                *cost(small, "trimmed:1"),
                fixed(found[large, 0, "trimmed:5"]["median"]),
                *cost(large, "trimmed:5"),
                fixed(found[large, 0, "trimmed:10"]["median"]),
                *cost(large, "trimmed:10"),
                fixed(found[large, 0, "none"]["median"]),
            ),
        ),
        Claim(
            "With F = 1 among 10, 2 liars (20%) leave {} of {} runs correct and 3 liars (30%) "
            "{} of {}, most of the others split; with F = 5 among 50, 10 liars (20%) leave {} "
            "of {}. Set to F = 10, the 50-robot swarm was correct in {} of {} runs with 10 "
            "liars",
            (
                *right(small, 2, "trimmed:1"),
                *right(small, 3, "trimmed:1"),
                *right(large, 10, "trimmed:5"),
                *right(large, 10, "trimmed:10"),
            ),
        ),
    ]


def plot(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    found = rows(records)
    sizes = sorted(LIARS)
    figure, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 3.8), squeeze=False)
    for axis, robots in zip(axes[0], sizes, strict=True):
        for defence in DEFENCES[robots]:
            mine = [r for r in found if r["robots"] == robots and r["defence"] == defence]
            if not mine:
                continue
            bars = [tables.error_bar(r["correct"], r["runs"]) for r in mine]
            liars = [100 * r["liars"] / robots for r in mine]
            tables.plot_bars(axis, liars, bars, fmt="o-", capsize=2, label=label(defence))
        if not any(r["robots"] == robots for r in found):
            tables.no_runs_yet(axis)
        axis.axhline(0.9, linestyle=":", color="grey")
        axis.set_title(f"{robots} robots, n = {SITES}")
        axis.set_xlabel("liars (% of the robots)")
        axis.set_ylabel("share of runs: honest robots all chose the best")
        axis.set_ylim(-0.05, 1.05)
        axis.grid(alpha=0.3)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize="small")
    figure.suptitle("bars: 95% Wilson interval of the share of runs", fontsize="small")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


STUDY = Study(
    name="defence",
    title="the defence against liars",
    about="trimmed pooling against 0-3 liars of 10 and 10% and 20% liars of 50",
    points=points,
    source="deploy/study/defence.py",
    pages=(
        Page(
            "docs/byzantine.md",
            lambda records: {"defence": "\n" + table(records) + "\n"},
            claims=defence_claims,
        ),
    ),
    outputs=(Output("docs/byzantine-defence.png", plot),),
    kinds=lambda run: (
        f"a {run.param('robots')}-robot swarm, "
        + ("the paper's pooling" if run.param("defence") == "none" else "trimmed pooling")
    ),
)
