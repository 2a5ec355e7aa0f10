"""What ``swarm section5`` publishes, computed from its runs (pure: no runs, no files).

A *record* is one in-process run, compact: its variant (``default`` or ``linger``), n,
seed, how it ended, whether the consensus was right, the sim time of the last decision,
and per robot its steps (trips) to decision and its pool sizes. From a list of records
this module renders the Markdown blocks of docs/section5.md and the data
behind Figures 4 and 5. The paper's own figures are quoted as text, never computed.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from typing import Any

from deploy.analysis import effects
from deploy.analysis.prose import Claim
from deploy.analysis.wilson import share

PAPER_SEEDS = 10  # the paper ran each n ten times: seeds 0..9 are "the paper's ten runs"
SITES = (5, 8, 10)
ROBOTS = 10
LINGER = 10.0  # sim seconds of the linger variant (the paper's suggested fix)
# Each variant: keyword arguments of ControllerConfig.
VARIANTS: dict[str, dict[str, Any]] = {"default": {}, "linger": {"linger": LINGER}}

# What the paper says about its ten runs per n (Section 5 text and Figures 4 and 5).
PAPER_WITHIN = {5: '"many"', 8: '"many"; worst run 6 steps', 10: "all 10; 60% strictly below"}
PAPER_POOLS = {
    5: "no run above 3",
    8: "no run above 3; run 5: 2, pools up to 6",
    10: "no run above 3",
}


# --- per-run measures ----------------------------------------------------------------------


def swarm_steps(record: dict[str, Any]) -> int | None:
    """The last robot's steps, the paper's time to consensus; None unless consensus."""
    steps = record["steps"]
    if record["ended"] != "consensus" or any(step is None for step in steps):
        return None
    return int(max(steps))


def pools(record: dict[str, Any]) -> list[int]:
    return [size for robot in record["pools"] for size in robot]


def decided_steps(record: dict[str, Any]) -> list[int]:
    return [step for step in record["steps"] if step is not None]


def select(
    records: Sequence[dict[str, Any]], variant: str, n: int, seeds: int | None = None
) -> list[dict[str, Any]]:
    """The records of one variant and n, by seed; only seeds below ``seeds`` if given."""
    chosen = [
        record
        for record in records
        if record["variant"] == variant
        and record["n"] == n
        and (seeds is None or record["seed"] < seeds)
    ]
    return sorted(chosen, key=lambda record: record["seed"])


def _number(value: float) -> str:
    return f"{value:g}" if value == int(value) else f"{value:.1f}"


def quartiles(values: Sequence[float]) -> tuple[float, float, float]:
    """Lower quartile, median, upper quartile (linear interpolation, like numpy's)."""
    if len(values) == 1:
        return values[0], values[0], values[0]
    q1, median, q3 = statistics.quantiles(values, n=4, method="inclusive")
    return q1, median, q3


# --- the summary table ---------------------------------------------------------------------


def _within(records: Sequence[dict[str, Any]], n: int) -> tuple[int, int, int]:
    """Runs within n/2 steps, runs strictly below n/2, runs."""
    steps = [swarm_steps(record) for record in records]
    within = sum(1 for value in steps if value is not None and value <= n / 2)
    below = sum(1 for value in steps if value is not None and value < n / 2)
    return within, below, len(records)


def _count(within: int, below: int, runs: int, n: int) -> str:
    """``5/10 (24-76%); 1/10 below (0.3-40%)``: runs within n/2 and strictly below, each
    with its 95% Wilson interval."""
    if n % 2:  # n/2 is not a whole number: within and strictly below are the same runs
        return share(within, runs)
    return f"{share(within, runs)}; {share(below, runs)} below"


def _steps_distribution(records: Sequence[dict[str, Any]]) -> str:
    values = [value for record in records if (value := swarm_steps(record)) is not None]
    if not values:
        return "-"
    q1, median, q3 = quartiles(values)
    return f"{_number(median)} ({_number(q1)}-{_number(q3)})"


def _pool_summary(records: Sequence[dict[str, Any]]) -> str:
    """Mean pool size over every pooling, then the highest run mean and the runs above 3
    (with the 95% interval of their share)."""
    every = [size for record in records for size in pools(record)]
    run_means = [statistics.fmean(sizes) for record in records if (sizes := pools(record))]
    if not every:
        return "-"
    over = sum(1 for mean in run_means if mean > 3)
    return (
        f"{statistics.fmean(every):.2f} (highest run {max(run_means):.2f}; "
        f"{share(over, len(run_means))} above 3)"
    )


def _right(records: Sequence[dict[str, Any]]) -> str:
    return share(sum(1 for record in records if record["correct"]), len(records))


def seeds_of(records: Sequence[dict[str, Any]]) -> int:
    """How many seeds per (variant, n) the records hold (the smallest group)."""
    counts = [
        len(select(records, variant, n))
        for variant in VARIANTS
        for n in SITES
        if select(records, variant, n)
    ]
    return min(counts) if counts else 0


def summary_table(records: Sequence[dict[str, Any]], meta: dict[str, Any]) -> str:
    """The Section 5 summary table: the paper, its ten seeds here, and the distribution.

    Rows for all seeds appear only when there are more than the paper's ten.
    """
    seeds = seeds_of(records)
    header = "| | " + " | ".join(f"n = {n} (n/2 = {n / 2:g})" for n in SITES) + " |"
    lines = [header, "|---|" + "---|" * len(SITES)]

    def row(label: str, cell: Any) -> None:
        lines.append(f"| {label} | " + " | ".join(cell(n) for n in SITES) + " |")

    def ten(variant: str, n: int) -> list[dict[str, Any]]:
        return select(records, variant, n, PAPER_SEEDS)

    def every(variant: str, n: int) -> list[dict[str, Any]]:
        return select(records, variant, n)

    row("**paper**, its 10 runs: within n/2 steps", lambda n: PAPER_WITHIN[n])
    row("**paper**, its 10 runs: a run's mean pool size", lambda n: PAPER_POOLS[n])
    row(
        "seeds 0-9: the swarm's steps, run 1 to 10",
        lambda n: " ".join(
            "-" if (value := swarm_steps(record)) is None else str(value)
            for record in ten("default", n)
        ),
    )
    row(
        "seeds 0-9: within n/2 (strictly below)",
        lambda n: _count(*_within(ten("default", n), n), n),
    )
    row("seeds 0-9: mean pool size", lambda n: _pool_summary(ten("default", n)))
    if seeds > PAPER_SEEDS:
        label = f"{seeds} seeds"
        row(
            f"{label}: the swarm's steps, median (IQR)",
            lambda n: _steps_distribution(every("default", n)),
        )
        row(
            f"{label}: within n/2 (strictly below)",
            lambda n: _count(*_within(every("default", n), n), n),
        )
        row(f"{label}: mean pool size", lambda n: _pool_summary(every("default", n)))
    every_label = f"{seeds} seeds" if seeds > PAPER_SEEDS else "seeds 0-9"
    row(f"{every_label}: right consensus", lambda n: _right(every("default", n)))
    linger = f"`--linger {LINGER:g}`"
    row(
        f"{linger}, seeds 0-9: within n/2 (strictly below)",
        lambda n: _count(*_within(ten("linger", n), n), n),
    )
    if seeds > PAPER_SEEDS:
        row(
            f"{linger}, {seeds} seeds: steps median (IQR); within n/2 (below)",
            lambda n: (
                f"{_steps_distribution(every('linger', n))}; "
                f"{_count(*_within(every('linger', n), n), n)}"
            ),
        )
        row(
            f"{linger}, {seeds} seeds: mean pool size",
            lambda n: _pool_summary(every("linger", n)),
        )
    else:
        row(f"{linger}, seeds 0-9: mean pool size", lambda n: _pool_summary(ten("linger", n)))
    lines.append("")
    lines.append(provenance(meta))
    return "\n".join(lines)


def provenance(meta: dict[str, Any]) -> str:
    """Where the table comes from. The commit is the one in the runs file's ``meta`` (the
    code that ran), so ``--check`` renders the same line after any later commit."""
    commit = meta.get("commit") or "unknown"
    dirty = " with uncommitted changes" if meta.get("dirty") else ""
    return (
        f"Made by `{meta.get('command', 'swarm section5')}` (runs at commit {commit}{dirty}; "
        f"in-process lockstep runs, {meta.get('robots', ROBOTS)} robots, default settings "
        "unless named). `swarm section5 --check` (`make check-published`, run by CI) runs "
        "every one of these runs again and fails if anything here differs; "
        "`swarm section5 --check --sample` does the same for seeds 0-9."
    )


# --- robots and time, per variant ----------------------------------------------------------


def robots_within(records: Sequence[dict[str, Any]], n: int) -> effects.Estimate | None:
    """The share of the robots that decided within n/2 trips, and its 95% interval by
    resampling whole runs (the robots of one run are not independent)."""
    return effects.clustered_share(
        [sum(1 for step in decided_steps(record) if step <= n / 2) for record in records],
        [len(decided_steps(record)) for record in records],
    )


def times_by_seed(records: Sequence[dict[str, Any]]) -> dict[int, float]:
    """Sim time to consensus by seed, the runs in consensus."""
    return {
        int(record["seed"]): float(record["sim_time_s"])
        for record in records
        if swarm_steps(record) is not None
    }


def share_interval(found: effects.Estimate) -> str:
    """``63.2% (60.3-66.1%)``: a share to a tenth of a percent and its interval, rounded
    outwards to a tenth (as the share is shown)."""
    low, high = _tenth(found.low, down=True), _tenth(found.high, down=False)
    return f"{found.value:.1%} ({low}-{high}%)"


def _tenth(value: float, *, down: bool) -> str:
    """A share in percent to a tenth, rounded outwards."""
    scaled = value * 1000
    rounded = math.floor(scaled + 1e-9) if down else math.ceil(scaled - 1e-9)
    return f"{rounded / 10:.1f}"


def time_against_default(records: Sequence[dict[str, Any]], variant: str, n: int) -> str:
    """The variant's median time over the default's at n (runs paired by seed), with its
    95% bootstrap interval."""
    if variant == "default":
        return "1 (the baseline)"
    found = effects.paired_median_ratio(
        times_by_seed(select(records, variant, n)), times_by_seed(select(records, "default", n))
    )
    if found is None:
        return f"no time to compare (fewer than {effects.MIN_RUNS} runs in consensus)"
    return effects.estimate_text(found)


def detail_table(records: Sequence[dict[str, Any]]) -> str:
    """Per variant and n over every seed: the typical robot, time, the largest pool."""
    lines = [
        "| variant | n | runs | robots within n/2 (95% interval) | robot steps median | swarm "
        "steps mean | sim s to consensus: mean / median | median time against the default: "
        "ratio (95% interval) | largest pool |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for variant in VARIANTS:
        label = "default" if variant == "default" else f"`--linger {LINGER:g}`"
        for n in SITES:
            chosen = select(records, variant, n)
            steps = [step for record in chosen for step in decided_steps(record)]
            swarm = [value for record in chosen if (value := swarm_steps(record)) is not None]
            times = [record["sim_time_s"] for record in chosen if swarm_steps(record) is not None]
            sizes = [size for record in chosen for size in pools(record)]
            within = robots_within(chosen, n)
            if not chosen or not steps or not swarm or within is None:
                continue
            lines.append(
                f"| {label} | {n} | {len(chosen)} | {share_interval(within)} "
                f"| {_number(statistics.median(steps))} | {statistics.fmean(swarm):.2f} "
                f"| {statistics.fmean(times):.0f} / {statistics.median(times):.0f} "
                f"| {time_against_default(records, variant, n)} "
                f"| {max(sizes) if sizes else '-'} |"
            )
    return "\n".join(lines)


# --- the per-run table ---------------------------------------------------------------------


def runs_table(records: Sequence[dict[str, Any]], variant: str = "default") -> str:
    """Every run of the paper's ten seeds, one line each."""
    lines = [
        "| run (seed) | ended | swarm steps | robot steps median | mean | robots within n/2 "
        "| pool mean | median | max | sim s |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for n in SITES:
        for record in select(records, variant, n, PAPER_SEEDS):
            steps = decided_steps(record)
            sizes = pools(record)
            swarm = swarm_steps(record)
            within = sum(1 for step in steps if step <= n / 2)
            cells = [
                f"n{n}-r{record['seed'] + 1:02d} ({record['seed']})",
                record["ended"],
                "-" if swarm is None else str(swarm),
                _number(statistics.median(steps)) if steps else "-",
                f"{statistics.fmean(steps):.1f}" if steps else "-",
                f"{within}/{len(record['steps'])}",
                f"{statistics.fmean(sizes):.2f}" if sizes else "-",
                _number(statistics.median(sizes)) if sizes else "-",
                str(max(sizes)) if sizes else "-",
                f"{record['sim_time_s']:.0f}",
            ]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# --- the data behind the figures -----------------------------------------------------------


def figure_data(records: Sequence[dict[str, Any]], variant: str, figure: int) -> dict[str, Any]:
    """Figure 4 (per robot steps to decision) or 5 (pool sizes), per run of seeds 0-9."""
    panels = []
    for n in SITES:
        runs = []
        for record in select(records, variant, n, PAPER_SEEDS):
            values = decided_steps(record) if figure == 4 else pools(record)
            runs.append({"run": record["seed"] + 1, "seed": record["seed"], "values": values})
        panels.append({"n": n, "half_n": n / 2, "runs": runs})
    return {
        "figure": figure,
        "what": "steps (trips) to decision of each robot"
        if figure == 4
        else "size of each pooling (the robot's own opinion included)",
        "variant": variant,
        "settings": VARIANTS[variant],
        "robots": ROBOTS,
        "panels": panels,
    }


def distribution(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Runs by the swarm's steps, per variant and n (None: no consensus)."""
    result: dict[str, Any] = {}
    for variant in VARIANTS:
        for n in SITES:
            counts: dict[str, int] = {}
            for record in select(records, variant, n):
                value = swarm_steps(record)
                key = "none" if value is None else str(value)
                counts[key] = counts.get(key, 0) + 1
            result[f"{variant}-n{n}"] = dict(sorted(counts.items(), key=lambda item: item[0]))
    return result


def blocks(records: Sequence[dict[str, Any]], meta: dict[str, Any]) -> dict[str, str]:
    """Every generated Markdown block by name."""
    return {
        "summary": summary_table(records, meta),
        "detail": detail_table(records),
        "runs": runs_table(records, "default"),
    }


# --- the numbers docs/section5.md's prose reads from the runs ------------------------------


def claims(records: Sequence[dict[str, Any]]) -> list[Claim]:
    """The numbers of docs/section5.md's hand-written text that these runs give (the text
    of the settings study's sections is checked by that study)."""
    if not select(records, "default", SITES[-1]) or not select(records, "linger", SITES[-1]):
        return []
    found = []
    every_right = all(record["correct"] for record in records)
    found.append(
        Claim(
            "Every run, of {}, reaches consensus on the best site"
            if every_right
            else "Not every run, of {}, reaches consensus on the best site",
            (str(len(records)),),
        )
    )
    defaults = {n: select(records, "default", n) for n in SITES}
    means = [statistics.fmean(pools_of(runs)) for runs in defaults.values()]
    largest = max(max(pools_of(runs)) for runs in defaults.values())
    found.append(
        Claim(
            "about {} to {} opinions on average (the table), at most {} of the ten robots",
            (f"{min(means):.1f}", f"{max(means):.1f}", str(largest)),
        )
    )
    shares = {n: robots_within(runs, n) for n, runs in defaults.items()}
    medians = {n: statistics.median(_robot_steps(runs)) for n, runs in defaults.items()}
    found.append(
        Claim(
            "({}% and {}% of robots; the median robot needs {} and {} trips)",
            (
                _whole(shares[8]),
                _whole(shares[10]),
                _number(medians[8]),
                _number(medians[10]),
            ),
        )
    )
    ten = select(records, "default", SITES[-1], PAPER_SEEDS)
    found.append(Claim("from our seeds 0-9 ({}/10 for n = 10)", (str(_within(ten, SITES[-1])[0]),)))
    found.append(Claim("Most robots manage it ({}%)", (_whole(shares[5]),)))
    linger = {n: select(records, "linger", n) for n in SITES}
    counted = {n: _within(runs, n) for n, runs in linger.items()}
    run_means = [statistics.fmean(pools(record)) for record in linger[10] if pools(record)]
    found.append(
        Claim(
            "with `--linger 10` the defaults give n = 10 within n/2 in {}% of {} runs and {}% "
            "strictly below, with a mean pool of {} ({} runs of {} average above 3, since "
            "decided robots join pools), n = 8 in {}% and n = 5 in {}% (first table)",
            (
                _percent_of(counted[10][0], counted[10][2]),
                str(counted[10][2]),
                _percent_of(counted[10][1], counted[10][2]),
                f"{statistics.fmean(pools_of(linger[10])):.2f}",
                str(sum(mean > 3 for mean in run_means)),
                str(len(run_means)),
                _percent_of(counted[8][0], counted[8][2]),
                _percent_of(counted[5][0], counted[5][2]),
            ),
        )
    )
    return found


def pools_of(records: Sequence[dict[str, Any]]) -> list[int]:
    return [size for record in records for size in pools(record)]


def _robot_steps(records: Sequence[dict[str, Any]]) -> list[int]:
    return [step for record in records for step in decided_steps(record)]


def _whole(found: effects.Estimate | None) -> str:
    return "-" if found is None else f"{100 * found.value:.0f}"


def _percent_of(count: int, total: int) -> str:
    return f"{100 * count / total:.0f}" if total else "-"
