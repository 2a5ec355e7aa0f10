"""The study ``robustness``: the swarm's decision against radio loss and camera noise
(docs/robustness.md, its tables and docs/robustness_drop.png, docs/robustness_noise.png).

10 robots, 10 sites, timeout 1800 sim s, every run observed (``make.make_comparisons``:
each site comparison judged against the true qualities):

* ``sweep=drop``: iid radio loss 0, 0.1, ..., 0.8, the paper's controller (alpha = 0,
  MProdOp), seeds 0-9; drop 0 against 0.3 is the 30% loss claim;
* ``sweep=noise``: Gaussian pixel noise (``--camera-noise SIGMA``) 0, 100, 120 and 140
  (seeds 0-9) and 150 to 180 (seeds 0-39), and per-site lighting (``--lighting 0.3``) at
  SIGMA 0 and 100 (seeds 0-9), for three controllers: the paper's, distrust (alpha = 0.1,
  threshold 0.99) and distrust with the diluting pool (``--pooling loglinear``);
* ``sweep=sensing``: no swarm: the best and second-best site of seed 0's layout, 300
  frames each, at each pixel noise level (``make.make_sensing``);
* ``sweep=processes``: the 30% loss claim with real processes (``swarm run`` over
  Zenoh), drop 0 and 0.3, seeds 0-9, compared run by run with the runs in one process.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

from deploy.analysis import effects
from deploy.analysis.wilson import interval, share
from deploy.study import robustness_prose, tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point, text
from deploy.study.robustness_runs import (
    CLAIM_DROP,
    DROPS,
    FAILING,
    LABELS,
    LIGHTING,
    LIGHTING_SIGMAS,
    MORE_SEEDS,
    ROBOTS,
    SEEDS,
    SENSING_SIGMAS,
    SETUPS,
    SIGMAS,
    SITES,
    TIMEOUT,
    claim_numbers,
    summarise,
)

BASE = ("--robots", str(ROBOTS), "--sites", str(SITES))
# The kinds of run, by sweep (``swarm study robustness --check`` makes one of each).
KINDS = {
    "drop": "radio loss, observed",
    "noise": "camera noise, observed",
    "sensing": "the camera alone",
    "processes": "over Zenoh",
}


def points() -> list[Point]:
    found = [
        Point(
            {"sweep": "drop", "drop": level, "controller": "alpha0"},
            SEEDS,
            "comparisons",
            options=[*BASE, "--drop", text(level)],
            timeout=TIMEOUT,
            cost=6.0,
        )
        for level in DROPS
    ]
    noise = [(sigma, 0.0) for sigma in SIGMAS] + [(sigma, LIGHTING) for sigma in LIGHTING_SIGMAS]
    for (sigma, lighting), setup in itertools.product(noise, SETUPS):
        lit = ["--lighting", text(lighting)] if lighting else []
        found.append(
            Point(
                {"sweep": "noise", "sigma": sigma, "lighting": lighting, "controller": setup.key},
                MORE_SEEDS if sigma in FAILING and not lighting else SEEDS,
                "comparisons",
                options=[*BASE, "--camera-noise", text(sigma), *lit, *setup.options],
                timeout=TIMEOUT,
                cost=10.0,
            )
        )
    found += [
        Point({"sweep": "sensing", "sigma": sigma, "lighting": 0.0}, (0,), "sensing", cost=10.0)
        for sigma in SENSING_SIGMAS
    ]
    found += [
        Point(
            {"sweep": "processes", "drop": level},
            SEEDS,
            "zenoh",
            options=[*BASE, "--drop", text(level)],
            timeout=TIMEOUT,
            cost=20.0,
        )
        for level in (0.0, CLAIM_DROP)
    ]
    return found


# --- the page ------------------------------------------------------------------------------


def _times(row: dict[str, Any]) -> str:
    return " / ".join(tables.number(row[name]) for name in ("time_mean", "time_median", "time_max"))


def drop_table(records: Records) -> str:
    lines = [
        "| drop | correct (95% interval) | consensus time s: mean / median / max | median "
        "time against drop 0: ratio (95% interval) | comparisons/run |",
        "|---|---|---|---:|---|",
    ]
    clean = records.where(sweep="drop", drop=0.0)
    baseline = summarise(clean)["by_seed"] if clean else {}
    for level in DROPS:
        runs = records.where(sweep="drop", drop=level)
        if runs:
            row = summarise(runs)
            against = (
                "1 (the baseline)"
                if level == 0.0
                else tables.compare_times(row["by_seed"], baseline, tables.CONSENSUS_RUNS)
            )
            lines.append(
                f"| {text(level)} | {share(row['correct'], row['runs'])} | {_times(row)} "
                f"| {against} | {row['comparisons']:.1f} |"
            )
    return "\n".join(lines)


def claim(records: Records) -> str:
    """The 30% claim: drop 0.3 against drop 0, seed by seed, in one process and with real
    processes."""
    found = claim_numbers(records)
    if found is None:
        return "The runs of drop 0 and 0.3 are not made yet."
    seeds = found["seeds"]
    low, high = found["per_seed"]
    lines = [
        f"**The 30 % claim** ({ROBOTS} robots, {SITES} sites, {tables.seeds(seeds)}, drop "
        f"0.3 against drop 0): right consensus in {share(found['right_clean'], len(seeds))} "
        f"runs without loss and {share(found['right_lossy'], len(seeds))} with 30 % loss. "
        f"Median consensus time {found['median_clean']:.1f} s without loss, "
        f"{found['median_lossy']:.1f} s with: ratio of medians "
        f"{effects.estimate_text(found['ratio'])} (95% interval), per seed from {low:.2f} to "
        f"{high:.2f}."
    ]
    processes = records.where(sweep="processes")
    if processes:
        memory = {
            (run["params"]["drop"], run["seed"]): tables.result(run)
            for run in records.where(sweep="drop")
        }
        fields = ("correct", "sim_time_s", "slowest_steps", "digest")
        same = sum(
            (twin := memory.get((run["params"]["drop"], run["seed"]))) is not None
            and all(twin[name] == tables.result(run)[name] for name in fields)
            for run in processes
        )
        walls = [float(run.get("wall_s") or 0.0) for run in processes]
        lines.append(
            f"The same runs with real processes (`swarm run --robots {ROBOTS} --sites {SITES} "
            "--seed S "
            f"--drop D --json`, D = 0 and 0.3, over Zenoh) gave the same outcome, consensus time "
            f"and per-robot results as in one process in {same} of {len(processes)} runs "
            f"({min(walls):.1f} to {max(walls):.1f} s of wall time each)."
        )
    return "\n".join(lines)


def sensing_table(records: Records) -> str:
    runs = {run["params"]["sigma"]: tables.result(run) for run in records.where(sweep="sensing")}
    first = next(iter(runs.values()), None)
    if first is None:
        return "The sensing runs are not made yet."
    lines = [
        f"| σ | best (ρ = {first['best_quality']:.3g}): mean (sd) | second (ρ = "
        f"{first['second_quality']:.3g}): mean (sd) | frames with no site found (95% interval) "
        "| P(best reads below second) (95% interval) |",
        "|---|---|---|---|---|",
    ]

    def cell(reading: dict[str, Any]) -> str:
        if reading["mean"] is None:
            return "-"
        return f"{reading['mean']:.3f} ({reading['sd']:.3f})"

    for sigma in SENSING_SIGMAS:
        if (found := runs.get(sigma)) is None:
            continue
        swapped = (
            "-"
            if not found["pairs"]
            else f"{100 * found['swapped'] / found['pairs']:.1f} % "
            f"({interval(found['swapped'], found['pairs'])})"
        )
        lines.append(
            f"| {text(sigma)} | {cell(found['best'])} | {cell(found['second'])} "
            f"| {100 * found['missed'] / (2 * found['frames']):.0f} % "
            f"({interval(found['missed'], 2 * found['frames'])}) | {swapped} |"
        )
    return "\n".join(lines)


def noise_rows(
    records: Records, sigmas: tuple[float, ...], lighting: float, seeds: range
) -> list[dict[str, Any]]:
    rows = []
    for sigma in sigmas:
        for setup in SETUPS:
            runs = [
                run
                for run in records.where(
                    sweep="noise", sigma=sigma, lighting=lighting, controller=setup.key
                )
                if run["seed"] in seeds
            ]
            if runs:
                rows.append({"sigma": sigma, "controller": setup.key, **summarise(runs)})
    return rows


def _percent_interval(value: float, found: effects.Estimate | None) -> str:
    """``2.7 % (1.9-3.6%)``: a share of comparisons and its 95% interval (whole runs
    resampled: the comparisons of one run are not independent)."""
    if found is None:
        return f"{100 * value:.1f} %"
    low = effects.outwards(100 * found.low, 100 * found.high, 1)
    return f"{100 * value:.1f} % ({low}%)"


def noise_table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| σ | controller | correct (95% interval) | wrong consensus | split/timeout "
        "| consensus time s: mean / median / max | median time against α = 0 at this σ: "
        "ratio (95% interval) | comparisons/run | wrong comparisons (95% interval) | best "
        "eliminated/run |",
        "|---|---|---|---|---|---|---:|---|---|---|",
    ]
    for row in rows:
        paper = next(
            other
            for other in rows
            if other["sigma"] == row["sigma"] and other["controller"] == SETUPS[0].key
        )
        against = (
            "1 (the baseline)"
            if row is paper
            else tables.compare_times(row["by_seed"], paper["by_seed"], tables.CONSENSUS_RUNS)
        )
        runs = row["runs"]
        lines.append(
            f"| {text(row['sigma'])} | {LABELS[row['controller']]} | "
            f"{share(row['correct'], runs)} "
            f"| {tables.counted(row['wrong'], runs)} | {tables.counted(row['split'], runs)} "
            f"| {_times(row)} | {against} | {row['comparisons']:.1f} "
            f"| {_percent_interval(row['wrong_share'], row['wrong_interval'])} "
            f"| {row['best_eliminated']:.2f} |"
        )
    return "\n".join(lines)


def failing_table(records: Records) -> str:
    """The failing levels with every seed they have: correct runs per controller, then the
    consensus times."""
    lines = [
        "| σ | " + " | ".join(setup.label for setup in SETUPS) + " |",
        "|---|" + "---|" * len(SETUPS),
    ]
    totals = {setup.key: [0, 0] for setup in SETUPS}
    for sigma in FAILING:
        cells = []
        for setup in SETUPS:
            runs = records.where(sweep="noise", sigma=sigma, lighting=0.0, controller=setup.key)
            right = sum(tables.result(run)["correct"] for run in runs)
            totals[setup.key][0] += right
            totals[setup.key][1] += len(runs)
            cells.append(share(right, len(runs)))
        lines.append(f"| {text(sigma)} | " + " | ".join(cells) + " |")
    lines.append("| all | " + " | ".join(share(*totals[setup.key]) for setup in SETUPS) + " |")
    lines += [
        "",
        "Consensus times of the same runs (sim s, runs with a consensus): the median, and "
        "against α = 0 at the same σ the ratio of medians (95% interval):",
        "",
        "| σ | " + " | ".join(setup.label for setup in SETUPS) + " |",
        "|---|" + "---|" * len(SETUPS),
    ]
    for sigma in FAILING:
        times = {
            setup.key: summarise(
                records.where(sweep="noise", sigma=sigma, lighting=0.0, controller=setup.key)
            )["by_seed"]
            for setup in SETUPS
            if records.where(sweep="noise", sigma=sigma, lighting=0.0, controller=setup.key)
        }
        if len(times) < len(SETUPS):
            continue
        baseline = times[SETUPS[0].key]
        cells = [f"{tables.number(tables.median(baseline.values()))}"]
        cells += [
            f"{tables.number(tables.median(times[setup.key].values()))}, "
            f"{tables.compare_times(times[setup.key], baseline, tables.CONSENSUS_RUNS)}"
            for setup in SETUPS[1:]
        ]
        lines.append(f"| {text(sigma)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def page_blocks(records: Records) -> dict[str, str]:
    return {
        **robustness_prose.blocks(records),
        "drop": drop_table(records),
        "claim": claim(records),
        "sensing": sensing_table(records),
        "noise": noise_table(noise_rows(records, SIGMAS, 0.0, SEEDS)),
        "failing": failing_table(records),
        "lighting": noise_table(noise_rows(records, LIGHTING_SIGMAS, LIGHTING, SEEDS)),
    }


# --- figures -------------------------------------------------------------------------------


def plot_drop(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    figure, (accuracy, timing) = plt.subplots(1, 2, figsize=(10, 4))
    rows = [
        (level, summarise(runs))
        for level in DROPS
        if (runs := records.where(sweep="drop", drop=level))
    ]
    if rows:
        bars = [tables.error_bar(row["correct"], row["runs"]) for _, row in rows]
        levels = [level for level, _ in rows]
        tables.plot_bars(accuracy, levels, bars, fmt="o-", color="tab:blue", capsize=2)
        for run in records.where(sweep="drop"):
            result = tables.result(run)
            if result["consensus"]:
                timing.plot(
                    run["params"]["drop"], result["sim_time_s"], ".", color="tab:grey", alpha=0.5
                )
        medians = [tables.median_bar(row["times"]) for _, row in rows]
        tables.plot_bars(
            timing, levels, medians,
            fmt="o-", color="tab:blue", capsize=3, label="median (95% bootstrap interval)",
        )  # fmt: skip
        timing.legend()
    else:
        tables.no_runs_yet(accuracy)
    accuracy.set_xlabel("iid radio loss (drop probability)")
    accuracy.set_ylabel("accuracy (share of runs: all robots chose the best)")
    accuracy.set_ylim(-0.05, 1.05)
    accuracy.grid(alpha=0.3)
    timing.set_xlabel("iid radio loss (drop probability)")
    timing.set_ylabel("consensus time (sim s, last robot decided)")
    timing.grid(alpha=0.3)
    figure.suptitle(
        f"Radio loss: α = 0, MProdOp; {len(SEEDS)} seeds per point, dots are runs; bars: 95% "
        "interval (Wilson for shares, bootstrap for median times)"
    )
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


COLOURS = {"alpha0": "tab:red", "alpha01": "tab:blue", "loglinear": "tab:green"}
MARKERS = {"alpha0": "o", "alpha01": "s", "loglinear": "^"}


def plot_noise(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    figure, (accuracy, timing, errors) = plt.subplots(1, 3, figsize=(15, 4.3))
    rows = noise_rows(records, SIGMAS, 0.0, SEEDS)
    spacing = min((b - a for a, b in itertools.pairwise(SIGMAS)), default=1.0)
    for number, setup in enumerate(SETUPS):
        # Each set-up's dots a little to the side, so that runs at one level stay apart.
        nudge = (number - (len(SETUPS) - 1) / 2) * 0.12 * spacing
        mine = [row for row in rows if row["controller"] == setup.key]
        if not mine:
            continue
        levels = [row["sigma"] for row in mine]
        style = {"color": COLOURS[setup.key], "marker": MARKERS[setup.key]}
        bars = [tables.error_bar(row["correct"], row["runs"]) for row in mine]
        nudged = [level + nudge for level in levels]
        tables.plot_bars(accuracy, nudged, bars, fmt="-", capsize=2, label=setup.label, **style)
        medians = [tables.median_bar(row["times"]) for row in mine]
        tables.plot_bars(timing, nudged, medians, fmt="-", capsize=2, label=setup.label, **style)
        errors.plot(
            levels, [100 * row["wrong_share"] for row in mine], "-", label=setup.label, **style
        )
        for run in records.where(sweep="noise", lighting=0.0, controller=setup.key):
            result = tables.result(run)
            if run["seed"] in SEEDS and result["consensus"]:
                timing.plot(
                    run["params"]["sigma"] + nudge, result["sim_time_s"], ".",
                    color=COLOURS[setup.key], alpha=0.35,
                )  # fmt: skip
    if not rows:
        tables.no_runs_yet(accuracy)
    else:
        accuracy.legend(loc="lower left")
    accuracy.set_ylabel("accuracy (share of runs: all robots chose the best)")
    accuracy.set_ylim(-0.05, 1.05)
    timing.set_ylabel("consensus time (sim s): median; dots are runs")
    errors.set_ylabel("wrong comparisons (% of all comparisons)")
    for axis in (accuracy, timing, errors):
        axis.set_xlabel("camera pixel noise sigma (0..255 scale)")
        axis.grid(alpha=0.3)
    figure.suptitle(
        f"Camera noise: {len(SEEDS)} seeds per point, {ROBOTS} robots, {SITES} sites; bars: "
        "95% interval (Wilson for shares, bootstrap for median times)"
    )
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


STUDY = Study(
    name="robustness",
    title="radio loss and camera noise",
    about="radio loss, camera noise and lighting against alpha > 0 and the log-linear pool",
    points=points,
    source="deploy/study/robustness.py",
    pages=(Page("docs/robustness.md", page_blocks, claims=robustness_prose.claims),),
    outputs=(
        Output("docs/robustness_drop.png", plot_drop),
        Output("docs/robustness_noise.png", plot_noise),
    ),
    kinds=lambda run: (
        KINDS[str(run.param("sweep"))]
        + (" with lighting" if dict(run.params).get("lighting") else "")
    ),
)
