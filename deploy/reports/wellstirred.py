"""``swarm wellstirred``: the paper's Section 4 model, its Figure 1 table and Figures 1-2;
with ``--strategy dmvd|dmmd|dc``, a strategy it is compared with in the same model
(``robot_agent/wellstirred/voting.py``, docs/strategies.md).

Prints one table per n (rows per pool size k, the n/2 exhaustive-search baseline and
k*, the smallest k whose mean is at or below n/2) or, with ``--json``, exactly one JSON
array on stdout. A progress bar runs on stderr while the sweep runs (when stderr is a
terminal). ``--plot`` writes Figure 1 (box plots), ``--plot-opinion`` Figure 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.cliargs import UsageError
from robot_agent.core.voting import STRATEGIES
from robot_agent.wellstirred.model import (
    FIGURE1_OPTIONS,
    FIGURE1_POOLS,
    MAX_EXACT_OPTIONS,
    MAX_EXACT_POOL,
    Cell,
    Model,
    cell_rng,
    opinion_trace,
    optimal_pool,
    sweep,
)
from robot_agent.wellstirred.voting import vote_sweep

# Figure 2 of the paper: one agent's opinion for these pool sizes.
FIGURE2_POOLS = (2, 3)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # A one-line usage, so that a bad value gives two short lines rather than a screenful.
    parser.usage = "%(prog)s [options]  (see --help)"
    parser.add_argument(
        "--options",
        type=cliargs.int_range(2),
        nargs="+",
        default=list(FIGURE1_OPTIONS),
        metavar="N",
        help="numbers of options n (default: %(default)s)",
    )
    parser.add_argument(
        "--pool",
        type=cliargs.positive_int,
        nargs="+",
        default=list(FIGURE1_POOLS),
        metavar="K",
        help="pool sizes k (default: %(default)s)",
    )
    parser.add_argument(
        "--runs",
        type=cliargs.positive_int,
        default=1000,
        help="independent runs per (n, k) (default: %(default)s)",
    )
    parser.add_argument(
        "--steps",
        type=cliargs.positive_int,
        default=100,
        help="step limit; a run that fails counts as this (default: %(default)s)",
    )
    parser.add_argument(
        "--alpha",
        type=cliargs.alpha,
        default=0.0,
        help="evidence unreliability alpha in [0, 0.5] (default: %(default)s)",
    )
    parser.add_argument("--seed", type=cliargs.seed, default=0, help="(default: %(default)s)")
    parser.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default="paper",
        help="paper: negative updating and pooling (Section 4); dmvd, dmmd, dc: the voter, "
        "majority and direct-comparison strategies in the same model, k the group of "
        "dmmd (docs/strategies.md) (default: %(default)s)",
    )
    parser.add_argument(
        "--population",
        type=cliargs.positive_int,
        default=None,
        metavar="N",
        help="agents, shuffled into pools of k each step (default: the pool size, "
        "one pool as in the paper); must be at least every k",
    )
    parser.add_argument(
        "--threshold",
        type=cliargs.threshold,
        default=1.0,
        help="an agent has decided when an option reaches this probability, in (0, 1] "
        "(default: %(default)s, certainty)",
    )
    parser.add_argument(
        "--exact",
        action="store_true",
        help="add the exact expected time (alpha = 0; defined where population = pool)",
    )
    parser.add_argument(
        "--method",
        choices=["auto", "opinions"],
        default="auto",
        help="auto: fastest exact way; opinions: simulate every agent's full opinion "
        "(the slow reference) (default: %(default)s)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON array on stdout")
    parser.add_argument(
        "--plot", type=Path, metavar="PNG", help="write Figure 1 (box plots) to this file"
    )
    parser.add_argument(
        "--plot-opinion",
        type=Path,
        metavar="PNG",
        help="write Figure 2 (one agent's opinion, k = 2 and 3, n = first --options) here",
    )


def run(args: argparse.Namespace) -> int:
    options = sorted(set(args.options))
    pools = sorted(set(args.pool))
    _check(args, pools)
    if args.strategy != "paper" and pools[0] < 2:
        pools = [k for k in pools if k >= 2]
        print("swarm wellstirred: k = 1 left out (an agent alone hears nobody)", file=sys.stderr)
    cells = _run_sweep(args, options, pools)
    if args.json:
        print(json.dumps([_record(cell, args.exact) for cell in cells]))
    else:
        _print_tables(cells, options, args.exact)
    if args.plot is not None:
        _plot_figure1(cells, options, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.plot_opinion is not None:
        _plot_figure2(args, args.options[0], args.plot_opinion)
        print(f"wrote {args.plot_opinion}", file=sys.stderr)
    return 0


def _check(args: argparse.Namespace, pools: Sequence[int]) -> None:
    """Checks that need more than one argument: one line, exit code 2."""
    if args.population is not None and args.population < pools[-1]:
        raise UsageError(f"--population {args.population} is smaller than --pool {pools[-1]}")
    if args.strategy != "paper":
        _check_voting(args, pools)
    if args.exact and args.alpha != 0.0:
        raise UsageError("--exact needs --alpha 0: with alpha > 0 there is no exact chain")
    # The exact chain exists where the population is the pool; refuse what it cannot do
    # before numpy is asked for its (n + 1)^2 transition matrix.
    exact_pools = [k for k in pools if args.population in (None, k)] if args.exact else []
    if exact_pools and max(args.options) > MAX_EXACT_OPTIONS:
        n = max(args.options)
        raise UsageError(
            f"--exact supports up to {MAX_EXACT_OPTIONS} options, got --options {n}: its "
            f"transition matrix of (n + 1)^2 numbers would take {8 * (n + 1) ** 2 / 2**30:.1f} GiB"
        )
    if exact_pools and exact_pools[-1] > MAX_EXACT_POOL:
        raise UsageError(
            f"--exact supports pools up to {MAX_EXACT_POOL}, got --pool {exact_pools[-1]}"
        )
    for flag, path in (("--plot", args.plot), ("--plot-opinion", args.plot_opinion)):
        if path is not None and not path.resolve().parent.is_dir():
            raise UsageError(f"{flag}: directory {path.parent} does not exist")


def _check_voting(args: argparse.Namespace, pools: Sequence[int]) -> None:
    """What a voting strategy does not have: evidence reliability, a decision threshold,
    an exact chain, full opinions to trace."""
    for given, flag in (
        (args.alpha != 0.0, "--alpha"),
        (args.threshold != 1.0, "--threshold"),
        (args.exact, "--exact"),
        (args.method != "auto", "--method"),
        (args.plot_opinion is not None, "--plot-opinion"),
    ):
        if given:
            raise UsageError(f"{flag} is for --strategy paper: a vote is one option")
    if pools[-1] < 2:
        raise UsageError(
            f"--strategy {args.strategy} needs a --pool of 2 or more: an agent and at "
            "least one neighbour"
        )


def _run_sweep(args: argparse.Namespace, options: list[int], pools: list[int]) -> list[Cell]:
    console = Console(stderr=True)
    progress = Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=not console.is_terminal,
    )
    with progress:
        task = progress.add_task("well-stirred sweep", total=len(options) * len(pools))

        def advance(cell: Cell) -> None:
            done = f"done n={cell.model.options}, k={cell.model.pool}"
            progress.update(task, advance=1, description=f"well-stirred sweep ({done})")

        if args.strategy != "paper":
            return vote_sweep(
                args.strategy,
                options,
                pools,
                runs=args.runs,
                seed=args.seed,
                population=args.population,
                steps=args.steps,
                on_cell=advance,
            )
        return sweep(
            options,
            pools,
            runs=args.runs,
            seed=args.seed,
            population=args.population,
            alpha=args.alpha,
            steps=args.steps,
            threshold=args.threshold,
            exact=args.exact,
            method=args.method,
            on_cell=advance,
        )


def _record(cell: Cell, with_exact: bool) -> dict[str, Any]:
    model, summary = cell.model, cell.summary
    strategy = getattr(model, "strategy", "paper")
    record: dict[str, Any] = {} if strategy == "paper" else {"strategy": strategy}
    record |= {
        "options": model.options,
        "pool": model.pool,
        "population": model.agents,
        "alpha": model.alpha,
        "runs": cell.outcome.runs,
        "mean": summary.mean,
        "median": summary.median,
        "q1": summary.q1,
        "q3": summary.q3,
        "success_rate": summary.success_rate,
    }
    if with_exact:
        # null where no exact value exists (population larger than the pool).
        record["exact_mean"] = None if cell.exact is None else cell.exact.mean
    return record


def _print_tables(cells: Sequence[Cell], options: Sequence[int], with_exact: bool) -> None:
    console = Console()
    for n in options:
        k_star = optimal_pool(cells, n)
        heading = (
            f"n = {n}: exhaustive search n/2 = {n / 2:g} steps; "
            f"k* = {k_star if k_star is not None else 'none of the k tried'}"
        )
        # A line of its own, never wrapped to the table's width.
        console.print(heading, soft_wrap=True, highlight=False, markup=False)
        table = Table()
        for column in ("k", "agents", "mean", "median", "q1", "q3", "max", "success"):
            table.add_column(column, justify="right")
        if with_exact:
            table.add_column("exact mean", justify="right")
        for cell in (cell for cell in cells if cell.model.options == n):
            summary = cell.summary
            mark = " *" if cell.model.pool == k_star else ""
            row = [
                f"{cell.model.pool}{mark}",
                str(cell.model.agents),
                f"{summary.mean:.2f}",
                f"{summary.median:g}",
                f"{summary.q1:g}",
                f"{summary.q3:g}",
                str(summary.maximum),
                f"{summary.success_rate:.1%}",
            ]
            if with_exact:
                row.append("-" if cell.exact is None else f"{cell.exact.mean:.2f}")
            table.add_row(*row)
        console.print(table)


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_figure1(cells: Sequence[Cell], options: Sequence[int], path: Path) -> None:
    """Box plots of the time to consensus against pool size, one panel per n."""
    plt = _pyplot()
    columns = 1 if len(options) == 1 else 2
    rows = -(-len(options) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(6 * columns, 4 * rows), squeeze=False)
    for index, n in enumerate(options):
        axis = axes[index // columns][index % columns]
        row = [cell for cell in cells if cell.model.options == n]
        axis.boxplot(
            [cell.outcome.times for cell in row],
            tick_labels=[str(cell.model.pool) for cell in row],
            flierprops={"markersize": 3},
        )
        axis.axhline(n / 2, linestyle="--", color="tab:red", label=f"n/2 = {n / 2:g}")
        axis.set_title(f"({chr(ord('a') + index)}) n = {n}")
        axis.set_xlabel("pool size k")
        axis.set_ylabel("time steps to consensus")
        axis.legend(loc="upper right")
    for index in range(len(options), rows * columns):
        axes[index // columns][index % columns].set_visible(False)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _plot_figure2(args: argparse.Namespace, n: int, path: Path) -> None:
    """One agent's opinion of every option over time, for k = 2 and k = 3."""
    plt = _pyplot()
    figure, axes = plt.subplots(1, len(FIGURE2_POOLS), figsize=(12, 4), squeeze=False)
    colours = plt.get_cmap("viridis")
    for index, k in enumerate(FIGURE2_POOLS):
        model = Model(
            n,
            k,
            max(k, args.population or k),
            alpha=args.alpha,
            steps=args.steps,
            threshold=args.threshold,
        )
        trace = opinion_trace(model, cell_rng(args.seed, model))
        axis = axes[0][index]
        for option in range(n):
            label = f"option {option + 1}" if n <= 10 or option == 0 else None
            axis.plot(
                range(len(trace)),
                trace[:, option],
                marker=".",
                color=colours(option / (n - 1)),
                linewidth=2.5 if option == 0 else 1.0,
                label=label,
            )
        axis.set_title(f"({chr(ord('a') + index)}) k = {k}, n = {n}")
        axis.set_xlabel("time step")
        axis.set_ylabel("agent 1's probability")
        axis.set_ylim(-0.02, 1.02)
        axis.legend(fontsize="small", ncols=2)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
