"""The report's figures: Figures 4 and 5 (steps to decision, pool sizes), one robot's
opinion over time (cf. Figure 2) and the robots' trajectories."""

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

FIGURES = ("fig4.png", "fig5.png", "fig2.png", "trajectories.png")


# --- figures -------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _natural(text: str) -> list[Any]:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def _panels(summaries: Sequence[dict[str, Any]]) -> list[tuple[int, int, list[dict[str, Any]]]]:
    groups: dict[tuple[int, int], list[dict[str, Any]]] = {}
    for summary in summaries:
        groups.setdefault((summary["num_robots"], summary["num_sites"]), []).append(summary)
    return [
        (robots, sites, sorted(runs, key=lambda s: _natural(s["run_id"])))
        for (robots, sites), runs in sorted(groups.items())
    ]


def save_figure(figure: Any, path: Path, *, private: bool = True) -> None:
    """A figure as a PNG; only its owner can read it, like everything a report writes,
    unless it is for publishing (``swarm section5``'s figures in docs/)."""
    if not private:
        figure.savefig(path, dpi=120)
        return
    with open_private(path, "wb") as stream:
        figure.savefig(stream, dpi=120, format="png")


def plot_boxes(
    summaries: Sequence[dict[str, Any]], path: Path, *, pools: bool, private: bool = True
) -> None:
    """Figure 4 (steps to decision, with the n/2 line) or Figure 5 (pool sizes)."""
    plt = _pyplot()
    panels = _panels(summaries)
    figure, axes = plt.subplots(
        1, max(len(panels), 1), figsize=(5.5 * max(len(panels), 1), 4.2), squeeze=False
    )
    for index, (robots, sites, runs) in enumerate(panels):
        axis = axes[0][index]
        data = [pools_of(run) if pools else steps_of(run) for run in runs]
        labels = [
            f"{number}" + ("" if run.get("ended") == "consensus" and run["complete"] else "*")
            for number, run in enumerate(runs, start=1)
        ]
        axis.boxplot(
            [[float(value) for value in values] or [math.nan] for values in data],
            tick_labels=labels,
            flierprops={"markersize": 3},
        )
        if pools:
            axis.set_ylabel("pool size k")
        else:
            axis.axhline(sites / 2, linestyle="--", color="tab:red", label=f"n/2 = {sites / 2:g}")
            axis.set_ylabel("time steps (trips) to decision")
            axis.legend(loc="upper right")
        axis.set_title(f"({chr(ord('a') + index)}) n = {sites}, N = {robots}")
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
