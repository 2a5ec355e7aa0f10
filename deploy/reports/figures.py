"""The report's figures: Figures 4 and 5 (steps to decision, pool sizes), one panel per
group of runs (``conditions.py``) with each run named by its id; the swarm over time
(robots decided, each site's share of the swarm's opinion: the mean over a group's runs
with a band from the lowest to the highest); one robot's opinion over time (cf. Figure 2)
and the robots' trajectories."""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bestofn_swarm.plumbing.private_files import open_private
from deploy.reports.collect import Recording
from deploy.reports.rows import pools_of, steps_of

FIGURES = (
    "fig4.png",
    "fig5.png",
    "decided.png",
    "shares.png",
    "fig2.png",
    "trajectories.png",
)

# A group of runs as the figures take it: its label and its runs' summaries.
Group = tuple[str, list[dict[str, Any]]]


# --- figures -------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _natural(text: str) -> list[Any]:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def save_figure(figure: Any, path: Path, *, private: bool = True) -> None:
    """A figure as a PNG; only its owner can read it, like everything a report writes,
    unless it is for publishing (``swarm section5``'s figures in docs/)."""
    if not private:
        figure.savefig(path, dpi=120)
        return
    with open_private(path, "wb") as stream:
        figure.savefig(stream, dpi=120, format="png")


def size_groups(summaries: Sequence[dict[str, Any]]) -> list[Group]:
    """Runs grouped by swarm size and sites alone (``swarm section5``'s panels)."""
    found: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for summary in summaries:
        found.setdefault((summary["num_robots"], summary["num_sites"]), []).append(summary)
    return [(f"n = {sites}, N = {robots}", runs) for (robots, sites), runs in sorted(found.items())]


def plot_boxes(
    groups: Sequence[Group],
    path: Path,
    *,
    pools: bool,
    private: bool = True,
    numbered: bool = False,
) -> None:
    """Figure 4 (steps to decision, with the n/2 line) or Figure 5 (pool sizes): one panel
    per group, one box per run, named by its run id (``numbered``: 1, 2, ..., as the
    paper's figures and ``swarm section5``'s)."""
    plt = _pyplot()
    panels = [(label, sorted(runs, key=lambda s: _natural(s["run_id"]))) for label, runs in groups]
    columns = max(len(panels), 1)
    width = max(5.5, max((0.55 * len(runs) + 1.5 for _, runs in panels), default=5.5))
    if numbered:
        width = 5.5
    height = 4.2 if numbered else 4.6
    figure, axes = plt.subplots(1, columns, figsize=(width * columns, height), squeeze=False)
    for index, (label, runs) in enumerate(panels):
        axis = axes[0][index]
        sites = runs[0]["num_sites"]
        data = [pools_of(run) if pools else steps_of(run) for run in runs]
        labels = [
            (str(number) if numbered else run["run_id"])
            + ("" if run.get("ended") == "consensus" and run["complete"] else "*")
            for number, run in enumerate(runs, start=1)
        ]
        axis.boxplot(
            [[float(value) for value in values] or [math.nan] for values in data],
            tick_labels=labels,
            flierprops={"markersize": 3},
        )
        if not numbered:
            axis.tick_params(axis="x", labelrotation=35, labelsize="small")
            for tick in axis.get_xticklabels():
                tick.set_horizontalalignment("right")
        if pools:
            axis.set_ylabel("pool size k")
        else:
            axis.axhline(sites / 2, linestyle="--", color="tab:red", label=f"n/2 = {sites / 2:g}")
            axis.set_ylabel("time steps (trips) to decision")
            axis.legend(loc="upper right")
        title = f"({chr(ord('a') + index)}) {label}"
        if numbered:
            axis.set_title(title)
        else:
            axis.set_title(title, fontsize="medium")
        axis.set_xlabel(
            "run"
            + ("  (* did not end in consensus, or cut short)" if "*" in "".join(labels) else "")
        )
        axis.set_ylim(bottom=0)
        axis.yaxis.get_major_locator().set_params(integer=True)
    if not panels:
        axes[0][0].text(0.5, 0.5, "no runs", ha="center", va="center")
    figure.tight_layout()
    save_figure(figure, path, private=private)
    plt.close(figure)


def _curve(curves: Any, column: str) -> tuple[Any, Any]:
    """A run's curve: sim times and values of a swarm column (``world_server/observer/frame``)."""
    import numpy

    names = [name for name, _ in curves.columns]
    times = numpy.asarray(curves.values[names.index("t")], dtype=float)
    values = numpy.asarray(curves.values[names.index(column)], dtype=float)
    return times, values


def _on_grid(runs: Sequence[tuple[Any, Any]], grid: Any) -> Any:
    """Runs' curves on a common grid of sim times: each run's value at a time is its last
    before it (held after its end)."""
    import numpy

    rows = []
    for times, values in runs:
        at = numpy.searchsorted(times, grid, side="right") - 1
        row = numpy.where(at >= 0, values[numpy.clip(at, 0, len(values) - 1)], numpy.nan)
        rows.append(row)
    return numpy.vstack(rows)


def _grid(runs: Sequence[tuple[Any, Any]]) -> Any:
    import numpy

    end = max(float(times[-1]) for times, _ in runs)
    steps = [numpy.diff(times) for times, _ in runs if len(times) > 1]
    step = float(numpy.median(numpy.concatenate(steps))) if steps else 1.0
    return numpy.arange(0.0, end + step / 2, max(step, 1e-3))


def _band(axis: Any, grid: Any, table: Any, colour: Any, *, label: str, width: float) -> None:
    import numpy

    with numpy.errstate(all="ignore"):
        mean = numpy.nanmean(table, axis=0)
        low, high = numpy.nanmin(table, axis=0), numpy.nanmax(table, axis=0)
    axis.plot(grid, mean, color=colour, linewidth=width, label=label)
    if len(table) > 1:
        axis.fill_between(grid, low, high, color=colour, alpha=0.18, linewidth=0)


def plot_decided(groups: Sequence[tuple[str, Sequence[Recording]]], path: Path) -> None:
    """Robots decided over sim time: per group, the mean over its runs with a band from the
    lowest to the highest."""
    plt = _pyplot()
    figure, axis = plt.subplots(figsize=(8, 4.4))
    colours = plt.get_cmap("tab10")
    drawn = 0
    for index, (label, recordings) in enumerate(groups):
        runs = _curves(recordings, "decided")
        if not runs:
            continue
        grid = _grid(runs)
        table = _on_grid(runs, grid)
        _band(axis, grid, table, colours(index % 10), label=f"{label} ({len(runs)} runs)", width=2)
        drawn += 1
    if not drawn:
        axis.text(0.5, 0.5, "no world states recorded", ha="center", transform=axis.transAxes)
    else:
        axis.legend(fontsize="small", loc="lower right")
    axis.set_xlabel("sim time (s)")
    axis.set_ylabel("robots decided")
    axis.set_ylim(bottom=0)
    axis.set_title("robots decided over time (mean over runs; band: lowest to highest)")
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def plot_shares(groups: Sequence[tuple[str, Sequence[Recording]]], path: Path) -> None:
    """Each site's share of the swarm's opinion over sim time (the mean of the robots'
    probabilities for it): one panel per group, the mean over its runs with a band from
    the lowest to the highest. A seed places the qualities at other sites, so sites are
    matched across runs by quality (the best, the next ...), each drawn in the colour its
    rank has in the palette, labelled with its quality."""
    plt = _pyplot()
    columns = max(len(groups), 1)
    figure, axes = plt.subplots(1, columns, figsize=(6.2 * columns, 4.4), squeeze=False)
    for index, (label, recordings) in enumerate(groups):
        axis = axes[0][index]
        with_curves = [r for r in recordings if _has_curves(r)]
        if not with_curves:
            axis.text(0.5, 0.5, "no world states recorded", ha="center", transform=axis.transAxes)
            continue
        ranked = [_by_quality(recording) for recording in with_curves]
        sites = min(len(order) for order in ranked)
        colours = _site_colours(None, sites)
        for rank in range(sites):
            runs = [
                _curve(recording.curves.swarm, f"share_{order[rank][0]}")
                for recording, order in zip(with_curves, ranked, strict=True)
                if recording.curves is not None
            ]
            grid = _grid(runs)
            quality = ranked[0][rank][1]
            name = (
                f"site of ρ {quality:.2f}" + (" (best)" if rank == 0 else "")
                if quality is not None
                else f"site {ranked[0][rank][0]}"
            )
            table = _on_grid(runs, grid)
            _band(axis, grid, table, colours[rank], label=name, width=2.6 if rank == 0 else 1.3)
        axis.set_ylim(0, 1)
        axis.set_xlabel("sim time (s)")
        axis.set_ylabel("share of the swarm's opinion")
        axis.set_title(
            f"({chr(ord('a') + index)}) {label}, {len(with_curves)} runs", fontsize="medium"
        )
        axis.legend(fontsize="x-small", ncols=2, loc="upper left")
    figure.suptitle(
        "each site's share of the swarm's opinion, sites by quality "
        "(mean over runs; band: lowest to highest)",
        fontsize="medium",
    )
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def _by_quality(recording: Recording) -> list[tuple[int, float | None]]:
    """A run's sites from the best to the worst: (id, quality); by id, without a layout."""
    layout = recording.layout
    if layout:
        ordered = sorted(layout["sites"], key=lambda site: (-site["quality"], site["id"]))
        return [(site["id"], site["quality"]) for site in ordered]
    sites = recording.curves.sites if recording.curves is not None else 0
    return [(site, None) for site in range(sites)]


def _curves(recordings: Sequence[Recording], column: str) -> list[tuple[Any, Any]]:
    """The curve of ``column`` of each recording that has the swarm's curves."""
    return [
        _curve(recording.curves.swarm, column)
        for recording in recordings
        if recording.curves is not None and len(recording.curves.swarm)
    ]


def _has_curves(recording: Recording) -> bool:
    return recording.curves is not None and len(recording.curves.swarm) > 0


def _site_colours(layout: dict[str, Any] | None, sites: int) -> dict[int, tuple[float, ...]]:
    """Each site's colour (the run's categorical palette: world_server/core/palette.py),
    for legends and the arena; its quality goes in the label."""
    from world_server.core.palette import site_palette

    count = len(layout["sites"]) if layout else sites
    return dict(enumerate(site_palette(count)))


def plot_opinion(recording: Recording, robot: int, path: Path) -> None:
    """One robot's opinion of every site over sim time, poolings marked."""
    plt = _pyplot()
    statuses = recording.opinions if robot == recording.opinion_robot else []
    figure, axis = plt.subplots(figsize=(8, 4.2))
    layout = recording.layout
    if statuses:
        sites = len(statuses[0].opinion)
        colours = _site_colours(layout, sites)
        qualities = {s["id"]: s["quality"] for s in layout["sites"]} if layout else {}
        best = layout["best_site"] if layout else None
        times = [status.t for status in statuses]
        for site in range(sites):
            label = f"site {site}" + (f" (rho {qualities[site]:.2f})" if site in qualities else "")
            axis.step(
                times,
                [status.opinion[site] for status in statuses],
                where="post",
                color=colours.get(site, (0.5, 0.5, 0.5, 1.0)),
                linewidth=2.5 if site == best else 1.2,
                label=label,
            )
        for previous, status in itertools.pairwise(statuses):
            if status.poolings > previous.poolings:
                axis.axvline(status.t, color="grey", linestyle=":", linewidth=0.8)
        axis.legend(fontsize="small", ncols=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
    else:
        axis.text(
            0.5, 0.5, f"no status messages of robot {robot}", ha="center", transform=axis.transAxes
        )
    axis.set_ylim(-0.02, 1.02)
    axis.set_xlabel("sim time (s); dotted lines: poolings at the nest")
    axis.set_ylabel(f"robot {robot}'s probability")
    axis.set_title(f"run {recording.run_id}: robot {robot}'s opinion")
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def plot_trajectories(recording: Recording, path: Path) -> None:
    """The robots' paths in the arena, with sites in their colours and the nest."""
    plt = _pyplot()
    from matplotlib.patches import Circle, Wedge

    figure, axis = plt.subplots(figsize=(8, 6.5))
    layout = recording.layout
    radius = layout["arena_radius"] if layout else 1.0
    axis.add_patch(Circle((0, 0), radius, fill=False, color="0.4", linewidth=1.5))
    if layout:
        colours = _site_colours(layout, len(layout["sites"]))
        axis.add_patch(Circle((0, 0), layout["nest_radius"], color=(1.0, 0.85, 0.3), alpha=0.4))
        half = 3.14159 / len(layout["sites"]) * 0.7
        for site in layout["sites"]:
            angle = site["angle"]
            axis.add_patch(
                Wedge(
                    (0, 0),
                    radius * 1.04,
                    _degrees(angle - half),
                    _degrees(angle + half),
                    width=radius * 0.04,
                    color=colours[site["id"]],
                )
            )
            axis.annotate(
                f"{site['id']}\nrho {site['quality']:.2f}",
                (1.14 * site["x"], 1.14 * site["y"]),
                ha="center",
                va="center",
                fontsize=7,
            )
    trails = {robot: trace.trail for robot, trace in recording.robots_heard.items()}
    robots = sorted(robot for robot, trail in trails.items() if trail.last is not None)
    cmap = plt.get_cmap("tab10" if len(robots) <= 10 else "viridis")
    for index, robot in enumerate(robots):
        colour = cmap(index % 10 if len(robots) <= 10 else index / max(len(robots) - 1, 1))
        xs, ys = trails[robot].points()
        axis.plot(
            xs,
            ys,
            color=colour,
            linewidth=0.6,
            alpha=0.8,
            label=f"robot {robot}" if len(robots) <= 10 else None,
        )
        axis.plot(xs[:1], ys[:1], "o", color=colour, markersize=3)
        axis.plot(xs[-1:], ys[-1:], "x", color=colour, markersize=5)
    if not robots:
        axis.text(0, 0, "no robot poses recorded", ha="center")
    axis.set_xlim(-1.3 * radius, 1.3 * radius)
    axis.set_ylim(-1.3 * radius, 1.3 * radius)
    axis.set_aspect("equal")
    axis.set_xlabel("x (m)")
    axis.set_ylabel("y (m)")
    axis.set_title(f"run {recording.run_id}: trajectories (o start, x end)")
    if 0 < len(robots) <= 10:
        axis.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def _degrees(radians: float) -> float:
    return radians * 180.0 / 3.141592653589793
