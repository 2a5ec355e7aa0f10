"""The study ``section5-settings``: how the settings the paper leaves open move time to
consensus, and why the last robot lags (docs/section5.md, "Why the last robot lags" and
"The settings the paper leaves open"; docs/section5-lag.png and docs/section5-lag.json).

Ten robots, n = 5, 8 and 10, seeds 0-99, the default timeout (1800 sim s), for each
*setting*: one change from the defaults, ``field=value``: ``dwell``, ``broadcast_period``,
``beacon_period`` and ``beacon_range`` are ``swarm run`` options (``--dwell`` ...), the
robot's top speed ``max_wheel_speed`` is a field of the world's e-puck (``spec``), which no
option sets. The ``default`` runs are observed (``make.make_lag``: every pooling and
decision), and the lag tables are made from them (``lag.py``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from deploy.analysis import effects
from deploy.analysis.wilson import percent_bound, share
from deploy.study import lag, section5_prose, tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point, Scalar
from deploy.study.section5_settings_runs import (
    ROBOTS,
    SEEDS,
    SETTINGS,
    SITES,
    TIMEOUT,
    lag_analyses,
    lag_summaries,
    row,
)

OPTIONS = ("dwell", "broadcast_period", "beacon_period", "beacon_range")  # swarm run's
SPEC = ("max_wheel_speed",)  # the e-puck's, no option
COST = 4.0  # wall seconds a run takes, about


def setting_of(setting: str) -> tuple[list[str], dict[str, Scalar]]:
    """A setting as ``swarm run`` options and config overrides; ValueError if unknown."""
    if setting == "default":
        return [], {}
    name, sep, value = setting.partition("=")
    if not sep:
        raise ValueError(f"setting {setting!r} is not field=value")
    if name in OPTIONS:
        return ["--" + name.replace("_", "-"), value], {}
    if name in SPEC:
        return [], {f"spec.{name}": float(value)}
    raise ValueError(f"no setting named {name!r} (it has {', '.join(OPTIONS + SPEC)})")


def points() -> list[Point]:
    found = []
    for setting in SETTINGS:
        options, configs = setting_of(setting)
        for n in SITES:
            found.append(
                Point(
                    {"setting": setting, "sites": n},
                    SEEDS,
                    "lag" if setting == "default" else "inprocess",
                    options=["--robots", str(ROBOTS), "--sites", str(n), *options],
                    timeout=TIMEOUT,
                    configs=configs,
                    cost=COST * (2 if configs else 1),
                )
            )
    return found


# --- the settings table --------------------------------------------------------------------


def _steps(r: dict[str, Any]) -> str:
    """The swarm steps' median and IQR, ``-`` without a run in consensus."""
    if math.isnan(r["median"]):
        return "-"
    return f"{r['median']:g} ({r['q1']:g}-{r['q3']:g})"


def describe(setting: str) -> str:
    return "defaults" if setting == "default" else f"`{setting}`"


def settings_table(records: Records) -> str:
    lines = [
        "| setting | n | runs | right (95% interval) | swarm steps median (IQR) | mean | within "
        "n/2 (95% interval) | strictly below | mean pool | runs with mean pool > 3 | pooled "
        "alone (95% interval) | sim s to consensus: mean / median | median time against the "
        "defaults: ratio (95% interval) |",
        "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for setting in SETTINGS:
        for n in SITES:
            runs = records.where(setting=setting, sites=n)
            if not runs:
                continue
            r = row(runs, n)
            defaults = records.where(setting="default", sites=n)
            against = (
                "1 (the baseline)"
                if setting == "default"
                else tables.compare_times(
                    r["times"], row(defaults, n)["times"], tables.CONSENSUS_RUNS
                )
                if defaults
                else "-"
            )
            missing = r["runs"] - r["consensus"]
            right = share(r["correct"], r["runs"]) + (
                f" ({missing} without consensus)" if missing else ""
            )
            lines.append(
                f"| {describe(setting)} | {n} | {r['runs']} | {right} "
                f"| {_steps(r)} | "
                f"{tables.number(r['mean_swarm'], 2)} "
                f"| {share(r['within'], r['runs'])} | {share(r['below'], r['runs'])} "
                f"| {tables.number(r['pool_mean'], 2)} "
                f"| {tables.counted(r['run_pool_over3'], r['runs'])} "
                f"| {_pct(r['alone'])} ({_interval(r['alone_interval'])}) "
                f"| {tables.number(r['time'])} / "
                f"{tables.number(tables.median(r['times'].values()))} "
                f"| {against} |"
            )
    return "\n".join(lines)


def _interval(found: effects.Estimate | None) -> str:
    """``22-28%``: a share's 95% bootstrap interval in whole percent, rounded outwards."""
    if found is None:
        return "-"
    return f"{percent_bound(found.low, upper=False)}-{percent_bound(found.high, upper=True)}%"


# --- why the last robot lags ---------------------------------------------------------------


def lag_intervals(analysed: list[dict[str, Any]]) -> dict[str, effects.Estimate | None]:
    """The 95% intervals of the lag table's shares of events (poolings, decisions), each
    by resampling whole runs: the events of one run are not independent."""

    def alone(key: str) -> effects.Estimate | None:
        return effects.clustered_share(
            [sum(size == 1 for _, size in run[key]) for run in analysed],
            [len(run[key]) for run in analysed],
        )

    return {
        "last_alone": alone("last_pools_by_trip"),
        "other_alone": alone("other_pools_by_trip"),
        "at_nest": effects.clustered_share(
            [int(run["last_phases"].get(lag.GROUPS[0], 0)) for run in analysed],
            [sum(int(count) for count in run["last_phases"].values()) for run in analysed],
        ),
    }


def lag_tables(records: Records) -> str:
    summaries = lag_summaries(records)
    if not summaries:
        return "The observed runs of the default settings are not made yet."
    lines = [
        "| n | runs | runs over n/2 (95% interval) | last robot: mean pool, pooled alone "
        "(95% interval) | the others: mean pool, pooled alone (95% interval) | last robot at "
        "the nest when another decided (95% interval) | runs the last robot finished alone "
        "(95% interval) | its trips after all others decided (mean) |",
        "|---|---:|---:|---|---|---:|---:|---:|",
    ]
    for s in summaries:
        shares = lag_intervals(lag_analyses(records, s["n"]))
        lines.append(
            f"| {s['n']} | {s['runs']} | {share(s['late_runs'], s['runs'])} "
            f"| {_f(s['last_pool_mean'])}, {_pct(s['last_alone'])} "
            f"({_interval(shares['last_alone'])}) "
            f"| {_f(s['other_pool_mean'])}, {_pct(s['other_alone'])} "
            f"({_interval(shares['other_alone'])}) "
            f"| {s['last_phases'].get('at the nest', 0.0):.0%} ({_interval(shares['at_nest'])}) "
            f"| {share(s['runs_with_lone_finish'], s['runs'])} "
            f"| {_f(s['trips_after_others_mean'])} |"
        )
    lines += ["", "Mean pool size by trip (pool sizes over time), the last robot (the others):", ""]
    for s in summaries:
        cells = ", ".join(
            f"{trip}: {size:.2f} ({_f(s['other_pool_by_trip'].get(trip))})"
            for trip, size in s["last_pool_by_trip"].items()
        )
        lines.append(f"* n = {s['n']}, trip {cells or '-: no trip with 20 poolings yet'}")
    lines += [
        "",
        "Non-best sites that no undecided robot has ruled out (the undecided robots all "
        "together; in brackets, one undecided robot on its own), after the k-th decision:",
        "",
    ]
    for s in summaries:
        cells = ", ".join(
            f"{order}: {_f(s['undecided_missing'][order])} ({_f(s['own_missing'][order])})"
            for order in sorted(s["undecided_missing"])
        )
        lines.append(f"* n = {s['n']}, k = {cells}")
    return "\n".join(lines)


def _f(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{value:.0%}"


def write_lag_json(records: Records, path: Path) -> None:
    path.write_text(json.dumps(lag_summaries(records), indent=1) + "\n")


def plot_lag(records: Records, path: Path) -> None:
    plt = tables.pyplot()
    summaries = lag_summaries(records)
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for index, summary in enumerate(summaries):
        orders = sorted(summary["undecided_missing"])
        colour = f"C{index}"  # one colour per n: solid together, dashed alone
        left.plot(
            orders, [summary["undecided_missing"][order] for order in orders], color=colour,
            marker="o", label=f"n = {summary['n']}: all undecided together",
        )  # fmt: skip
        left.plot(
            orders, [summary["own_missing"][order] for order in orders], color=colour,
            linestyle="--", marker=".", label=f"n = {summary['n']}: an undecided robot alone",
        )  # fmt: skip
    left.set_xlabel("robots decided (and gone)")
    left.set_ylabel("non-best sites still held possible")
    left.set_title("(a) evidence left among the undecided robots")
    left.set_ylim(bottom=0)
    width = 0.25
    for index, summary in enumerate(summaries):
        shares = [summary["last_phases"].get(group, 0.0) for group in lag.GROUPS]
        right.bar(
            [position + (index - 1) * width for position in range(len(lag.GROUPS))], shares,
            width, color=f"C{index}", label=f"n = {summary['n']}",
        )  # fmt: skip
    right.set_xticks(range(len(lag.GROUPS)), lag.GROUPS)
    right.set_ylabel("share of the other robots' decisions")
    right.set_title("(b) where the last robot was when another decided")
    if summaries:
        left.legend(fontsize=7)
        right.legend()
    else:
        tables.no_runs_yet(left)
        tables.no_runs_yet(right)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


STUDY = Study(
    name="section5-settings",
    title="Section 5: the settings the paper leaves open, and why the last robot lags",
    about="dwell, broadcast and beacon periods, nest size and speed; the last robot's lag",
    points=points,
    source="deploy/study/section5_settings.py",
    pages=(
        Page(
            "docs/section5.md",
            lambda records: {"lag": lag_tables(records), "settings": settings_table(records)},
            claims=section5_prose.claims,
        ),
    ),
    outputs=(
        Output("docs/section5-lag.png", plot_lag),
        Output("docs/section5-lag.json", write_lag_json),
    ),
    kinds=lambda run: (
        "the defaults, observed for the lag"
        if run.kind == "lag"
        else "a setting no option has (the e-puck's speed)"
        if run.configs
        else "a setting of swarm run"
    ),
)
