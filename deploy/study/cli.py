"""``swarm study``: the studies whose runs make the published pages, each declared as
data (``deploy/study/catalogue.py``), each with a results file (``docs/studies/NAME.jsonl``).

    swarm study --list                      # the studies, their size, how many runs are done
    swarm study NAME --status               # what is done and missing; last line: N done, M missing
    swarm study NAME [--parallel J|--dask]  # make the missing runs (resumable, longest first)
    swarm study NAME --only robots=500      # part of the grid (with any of the above)
    swarm study NAME --render               # the pages, tables and figures, from the results file
    swarm study NAME --check [--sample K]   # K runs of each kind made again and compared
    swarm study --check [--sample-seed S]   # the same for every study (make check-published)

Rendering never runs a swarm; with runs missing it renders what is there and says how many
are missing, on the page and here. docs/studies.md says more.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console

from bestofn_swarm.plumbing import checkout, cliargs
from bestofn_swarm.plumbing.cliargs import UsageError
from deploy.reports import sweep
from deploy.study import check, grid, lock, page, results, runner
from deploy.study.catalogue import studies, study_named
from deploy.study.declare import Study
from deploy.study.state import State, state_of

DEFAULT_SAMPLE = 1  # runs of each kind


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", nargs="?", metavar="NAME", help="the study (--list names them)")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--list", action="store_true", help="name the studies, their size and runs done"
    )
    mode.add_argument(
        "--status",
        action="store_true",
        help="what is done and missing; its last line: N done, M missing",
    )
    mode.add_argument(
        "--render",
        action="store_true",
        help="write the study's page blocks, figures and data files from its results file (runs "
        "nothing)",
    )
    mode.add_argument(
        "--check",
        action="store_true",
        help="make a sample of the runs again and compare them with the results file (exit 1 if "
        "any differs)",
    )
    parser.add_argument(
        "--sample",
        type=cliargs.int_range(1, 100_000),
        default=None,
        metavar="K",
        help=f"with --check: how many runs of each kind of run the study has (default: "
        f"{DEFAULT_SAMPLE}), drawn at random within the budget",
    )
    parser.add_argument(
        "--sample-seed",
        type=cliargs.int_range(0, 2**63),
        default=None,
        metavar="S",
        help="with --check: the seed of the sample's draw (default: today's date, 20250314; "
        "each check prints its seed)",
    )
    parser.add_argument(
        "--sample-budget",
        type=cliargs.float_range(0.0, low_open=True),
        default=None,
        metavar="SECONDS",
        help=f"with --check: the recorded wall seconds a study's sample may take (default: "
        f"{check.BUDGET:g} for each run of a kind); a kind with no run within it is named, "
        "not made",
    )
    parser.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="only the runs whose parameter NAME (or seed) has this value; VALUE may be A,B; "
        "repeatable",
    )
    parser.add_argument(
        "--root",
        type=Path,
        default=None,
        help="the repository whose results files and pages are read and written (default: the "
        "checkout this code runs from)",
    )
    parser.add_argument(
        "--declared",
        type=Path,
        action="append",
        default=[],
        metavar="FILE",
        help="a Python file that declares more studies (STUDY or STUDIES); repeatable",
    )
    parser.add_argument(
        "--recordings",
        type=Path,
        default=None,
        metavar="DIR",
        help="where recorded runs over Zenoh write their MCAP files (default: ROOT/runs/studies)",
    )
    parser.add_argument(
        "--new",
        action="store_true",
        help="ROOT may be a new folder (made if need be) without the study's results file or "
        "pages; without it such a ROOT is refused",
    )
    parser.add_argument(
        "--wait",
        action="store_true",
        help="when another runner is making the study's runs into the same results file, wait "
        "for it to end (without it: exit 2, naming the runner)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    sweep.add_executor_options(parser)


def run(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    if args.root is None:  # an installed copy has no results files or pages
        args.root = checkout.needed("swarm study", "give --root CHECKOUT")
    try:
        if args.list:
            if args.only:
                raise UsageError("--list names every study: it takes no --only")
            check_root(args.root, args.new)
            return list_studies(args)
        if args.name is None and args.check:
            check_root(args.root, args.new)
            return check_every_study(args, console)
        if args.name is None:
            raise UsageError("give a study's name (swarm study --list names them)")
        study = study_named(args.name, args.declared)
        only = grid.parse_only(args.only)
        for option in ("sample", "sample_seed", "sample_budget"):
            if getattr(args, option) is not None and not args.check:
                raise UsageError(f"--{option.replace('_', '-')} goes with --check")
        if args.render and only:
            raise UsageError(
                "--render writes the whole study's pages: it takes no --only (--status shows "
                "part of it)"
            )
        check_root(args.root, args.new, study)
        state = state_of(study, args.root, only)
    except ValueError as error:
        raise UsageError(str(error)) from None
    except OSError as error:  # the results file cannot be read
        raise UsageError(f"{error.filename}: {error.strerror}") from None
    for warning in state.loaded.skipped:
        console.print(f"[yellow]warning[/]: {warning}")
    if args.status:
        return status(state)
    if args.render:
        return render(state, args.root, console)
    executor = sweep.executor_from_args(args)
    if args.check:
        return check_runs(state, executor, Draw.of(args), console)
    recordings = args.recordings or args.root / "runs" / "studies"

    def waiting(holder: str) -> None:
        console.print(f"{study.results} is being made by {holder}: waiting for it to end")

    try:
        with lock.holding(args.root / study.results, wait=args.wait, waiting=waiting):
            state = state_of(study, args.root, only)  # what is missing once the lock is ours
            failures = runner.run_missing(
                state, args.root, executor, recordings, console, quiet=args.quiet
            )
    except lock.BusyError as error:
        raise UsageError(str(error)) from None
    except OSError as error:  # the results file cannot be written
        raise UsageError(f"{error.filename or study.results}: {error.strerror}") from None
    for line in runner.failures_text(failures):
        print(f"failed: {line}", file=sys.stderr)
    after = state_of(study, args.root, only)
    print(f"{len(after.done)} done, {len(after.missing)} missing")
    return 1 if failures else 0


def check_root(root: Path, new: bool, study: Study | None = None) -> None:
    """UsageError unless ``root`` is a folder that holds the study's results file or its
    pages (a repository with the study), or ``new`` says a new one is meant (then made)."""
    if new:
        root.mkdir(parents=True, exist_ok=True)
        return
    if not root.is_dir():
        raise UsageError(f"--root {root}: no such folder (--new starts a new one there)")
    if study is None:
        return
    held = [study.results, *(page.path for page in study.pages)]
    if not any((root / path).exists() for path in held):
        raise UsageError(
            f"--root {root} holds none of study {study.name}'s files ({', '.join(held)}): "
            "not a checkout with this study (--new starts a new one there)"
        )


def list_studies(args: argparse.Namespace) -> int:
    try:
        found = studies(args.declared)
    except ValueError as error:
        raise UsageError(str(error)) from None
    width = max(len(name) for name in found)
    for name, study in found.items():
        state = state_of(study, args.root)
        print(
            f"{name:<{width}}  {len(state.runs):>5} runs, {len(state.done):>5} done, "
            f"{len(state.missing):>5} missing  {study.title}: {study.about}"
        )
    return 0


def status(state: State) -> int:
    """Per parameter value, runs done of declared; the commits and locks of the runs; what
    the file holds that is not declared; and, last, ``N done, M missing``."""
    study = state.study
    print(f"{study.name}: {study.title}; results in {study.results}")
    done = {run.key for run in state.done}
    for name, values in grid.summarise_params(state.runs).items():
        cells = []
        for value in values:
            mine = [
                run
                for run in state.runs
                if name in dict(run.params) and grid.text(run.param(name)) == value
            ]
            made = sum(run.key in done for run in mine)
            cells.append(f"{value} {made}/{len(mine)}")
        print(f"  {name}: " + ", ".join(cells))
    if state.done:
        records = state.records()
        print(
            "  made at: "
            + ", ".join(f"{c} ({n})" for c, n in results.made_with(list(records.runs)).items())
        )
        print(
            "  run lock: "
            + ", ".join(f"{c} ({n})" for c, n in results.locks(list(records.runs)).items())
        )
    if state.undeclared:
        print(
            f"  {len(state.undeclared)} runs in the file are not declared (ignored), e.g. "
            f"{state.undeclared[0]}"
        )
    if state.missing:
        walls = state.walls()
        left = sum(grid.estimate(run, walls) for run in state.missing)
        print(f"  the missing runs take {runner.describe_seconds(left)[6:]} of one core, about")
    print(f"{len(state.done)} done, {len(state.missing)} missing")
    return 0


def render(state: State, root: Path, console: Console) -> int:
    """Write what the study publishes from its results file; say what is missing."""
    study = state.study
    records = state.records()
    try:
        written = page.write(study, records, root)
    except (OSError, ValueError) as error:
        raise UsageError(str(error)) from None
    for path in written:
        console.print(f"wrote {path}")
    for problem in page.stale_prose(study, records, root):  # prose is written by hand
        console.print(f"[yellow]the prose is stale[/]: {problem}")
    if records.missing:
        console.print(
            f"[yellow]{records.missing} of the {records.declared} runs of {study.name} are "
            "missing[/]: "
            f"the pages show the {len(records.runs)} made (swarm study {study.name} makes the rest)"
        )
    return 0


def check_every_study(args: argparse.Namespace, console: Console) -> int:
    """``swarm study --check``: a sample of every study's runs; 1 if any differs."""
    try:
        found = studies(args.declared)
        only = grid.parse_only(args.only)
        if only:
            raise UsageError("--only goes with a study's name")
    except ValueError as error:
        raise UsageError(str(error)) from None
    executor = sweep.executor_from_args(args)
    draw = Draw.of(args)
    worst = 0
    for study in found.values():
        state = state_of(study, args.root)
        worst = max(worst, check_runs(state, executor, draw, console))
    return worst


@dataclass(frozen=True)
class Draw:
    """How a check draws its sample: runs of each kind, the seed, the budget."""

    per_kind: int
    seed: int
    budget: float

    @classmethod
    def of(cls, args: argparse.Namespace) -> Draw:
        per_kind = args.sample or DEFAULT_SAMPLE
        seed = check.todays_seed() if args.sample_seed is None else args.sample_seed
        budget = args.sample_budget or check.BUDGET * per_kind
        return cls(per_kind, seed, budget)


def check_runs(state: State, executor: sweep.ExecutorSpec, draw: Draw, console: Console) -> int:
    """Make a sample of the study's runs again, ``draw.per_kind`` of each kind; print each
    difference by key and field, and the seed that draws the same sample again."""
    from deploy.study import make

    study = state.study
    if not state.done:
        console.print(f"{study.name}: no runs made yet: nothing to check")
        return 0
    drawn = check.sample(
        state.done,
        state.loaded.runs,
        seed=draw.seed,
        kind_of=study.kinds or check.default_kind,
        per_kind=draw.per_kind,
        budget=draw.budget,
    )
    chosen = drawn.runs
    again = f"swarm study {study.name} --check --sample-seed {draw.seed}"
    if draw.per_kind != DEFAULT_SAMPLE:
        again += f" --sample {draw.per_kind}"
    if draw.budget != check.BUDGET * draw.per_kind:
        again += f" --sample-budget {draw.budget:g}"
    print(f"{study.name}: sample seed {draw.seed} (`{again}` draws it again):")
    for kind, runs in drawn.kinds.items():
        print(f"  {kind}: {', '.join(run.key for run in runs)}")
    for kind, count in drawn.beyond.items():
        if kind not in drawn.out_of_reach:
            print(
                f"{study.name}: {kind}: {count} of its runs took more than the budget of "
                f"{draw.budget:g} s when published and are not drawn (--sample-budget, "
                "--only)"
            )
    for kind, cheapest in drawn.out_of_reach.items():
        print(
            f"{study.name}: not checked: {kind} (its cheapest run took {cheapest:.0f} s, over "
            f"the budget of {draw.budget:g} s; --sample-budget allows more)"
        )
    sys.stdout.flush()  # before the console's lines on stderr
    recorded = sum(check.wall(state.loaded.runs, run) for run in chosen)
    console.print(
        f"{study.name}: making {len(chosen)} of its {len(state.done)} runs again on "
        f"{executor.describe()} (they took {recorded:.0f} s when published)"
    )
    outcome = sweep.run_sweep(make.make, chosen, executor)
    problems = []
    for run, fresh in zip(chosen, outcome.results, strict=True):
        if fresh is None:
            continue
        found = check.differences(state.loaded.runs[run.key]["result"], fresh["result"])
        if found:
            problems.append(f"{study.name} run {run.key}: " + "; ".join(found))
    for failure in outcome.failures:
        problems.append(
            f"{study.name} run {chosen[failure.index].key}: gave no result: {failure.error}"
        )
    for problem in problems:
        print(problem)
    sys.stdout.flush()
    console.print(f"{study.name}: {len(chosen) - len(problems)} of {len(chosen)} runs as published")
    return 1 if problems else 0


__all__ = ["add_arguments", "run"]
