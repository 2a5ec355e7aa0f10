"""Runs the jobs of a JSON file in this interpreter and prints one JSON line per job.

    python -m portable.probe JOBS.json

``make check-portable`` starts it natively and under each emulator (portable/check.py),
always as one process that starts no other: under qemu-user a program that this one
started would run on the real CPU (or not at all, for another architecture). It needs
the packages of requirements/run.lock and the repository on its path, nothing else.

Every published run is made again by the function that made it for its file (Section 5:
``deploy.reports.section5.run_task``; a study's runs: ``deploy.study.make.make``), so the
record it gives has the published form; the run's summary, for its digest and per-robot
results, is taken on its way out of ``deploy.inprocess.engine.run_in_process``.

Lines, in order: ``{"about": ...}`` (the machine as this interpreter sees it), one
``{"key": ..., "record": ..., "run": ..., "seconds": ...}`` per job (the record without
its wall times, which are the machine's; or ``{"key": ...,
"error": ...}``), then ``{"done": ...}`` with the modules of this repository that were
loaded from compiled extensions rather than from their ``.py`` files.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import io
import json
import platform
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TextIO

from portable.published import without_wall

REPO = Path(__file__).resolve().parent.parent
PROJECT_PACKAGES = (
    "bestofn_swarm",
    "robot_agent",
    "world_server",
    "nest_beacon",
    "deploy",
    "benchmarks",
)
# Per robot: what the run digest covers (world_server/observer/summary.py), and its id.
ROBOT_FIELDS = ("id", "decided_site", "steps", "decision_time_s", "pool_sizes")


def run_result(summary: dict[str, Any]) -> dict[str, Any]:
    """What a run decided: its digest, ending, sim time, radio counts, per-robot results."""
    return {
        "digest": summary["digest"],
        "ended": summary["ended"],
        "sim_time_s": summary["sim_time_s"],
        "radio": summary.get("radio"),
        "per_robot": [[robot[name] for name in ROBOT_FIELDS] for robot in summary["per_robot"]],
    }


@contextlib.contextmanager
def summaries() -> Iterator[list[dict[str, Any]]]:
    """The summaries of the in-process runs made inside the block, in order."""
    from deploy.inprocess import engine

    original = engine.run_in_process
    seen: list[dict[str, Any]] = []

    def keeping(*args: Any, **kwargs: Any) -> dict[str, Any]:
        summary: dict[str, Any] = original(*args, **kwargs)
        seen.append(summary)
        return summary

    engine.run_in_process = keeping
    try:
        yield seen
    finally:
        engine.run_in_process = original


def _one_run(make: Callable[[], Any]) -> tuple[Any, dict[str, Any]]:
    with summaries() as seen:
        record = make()
    if len(seen) != 1:
        raise RuntimeError(f"{len(seen)} in-process runs where one was expected")
    return record, run_result(seen[0])


def section5(args: dict[str, Any]) -> tuple[Any, dict[str, Any] | None]:
    from deploy.reports.section5 import Task, run_task

    return _one_run(lambda: run_task(Task(args["variant"], args["n"], args["seed"])))


def study(args: dict[str, Any]) -> tuple[Any, dict[str, Any] | None]:
    """A run of a study, made by the study runner's own function (deploy/study/make.py):
    the result its results file holds, and the run's digest when it is a swarm."""
    from deploy.study import catalogue, make

    runs = {run.key: run for run in catalogue.study_named(args["study"]).runs()}
    with summaries() as seen:
        made = make.make(runs[args["key"]])
    return made["result"], run_result(seen[0]) if len(seen) == 1 else None


def _swarm(argv: list[str]) -> tuple[int, str]:
    """``swarm ARGV`` in this process: its exit code and standard output."""
    from deploy import cli

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = cli.main(argv)
    return code, out.getvalue()


def wellstirred(args: dict[str, Any]) -> tuple[Any, dict[str, Any] | None]:
    code, out = _swarm(["wellstirred", "--exact", "--json"])
    if code != 0:
        raise RuntimeError(f"swarm wellstirred --exact --json: exit code {code}")
    return json.loads(out), None


def run(args: dict[str, Any]) -> tuple[Any, dict[str, Any] | None]:
    """``swarm run`` in process (its exit code says how the run ended; any ending is a
    result to compare)."""
    argv = ["run", "--engine", "inprocess", "--no-record", "--json", "--quiet", *args["options"]]
    return None, run_result(json.loads(_swarm(argv)[1]))


def kernel(args: dict[str, Any]) -> tuple[Any, dict[str, Any] | None]:
    """tests/portable_probe.py's digest of the kernel's functions on a grid of inputs and
    its Section 4 results (simulated survivors and opinions, a voting rival, the exact
    chain)."""
    spec = importlib.util.spec_from_file_location(
        "portable_probe", REPO / "tests" / "portable_probe.py"
    )
    if spec is None or spec.loader is None:
        raise RuntimeError("tests/portable_probe.py cannot be loaded")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {"kernel": module.kernel_digest(), "section4": module.section4_results()}, None


# By a job's source; any other source is a study (portable/published.py SOURCES).
JOBS: dict[str, Callable[[dict[str, Any]], tuple[Any, dict[str, Any] | None]]] = {
    "section5": section5,
    "wellstirred": wellstirred,
    "run": run,
    "kernel": kernel,
}


def about() -> dict[str, Any]:
    """The machine as numpy and OpenCV see it, and the interpreter."""
    import cv2
    import numpy

    umath = importlib.import_module("numpy._core._multiarray_umath")
    return {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "numpy_simd": [name for name in umath.__cpu_dispatch__ if umath.__cpu_features__[name]],
        "opencv_simd": [
            token[1:]
            for token in cv2.getCPUFeaturesLine().split()
            if token.startswith("*") and not token.endswith("?")
        ],
    }


def compiled_modules() -> list[str]:
    """The modules of this repository loaded from compiled extensions (mypyc builds)."""
    return sorted(
        name
        for name, module in list(sys.modules.items())
        if name.split(".")[0] in PROJECT_PACKAGES
        and str(getattr(module, "__file__", "") or "").endswith((".so", ".pyd"))
    )


def emit(out: TextIO, line: dict[str, Any]) -> None:
    out.write(json.dumps(line, separators=(",", ":")) + "\n")
    out.flush()


def main(argv: list[str] | None = None) -> int:
    arguments = sys.argv[1:] if argv is None else argv
    if len(arguments) != 1:
        print("usage: python -m portable.probe JOBS.json", file=sys.stderr)
        return 2
    specs = json.loads(Path(arguments[0]).read_text())
    out = sys.stdout
    emit(out, {"about": about()})
    for spec in specs:
        started = time.perf_counter()
        try:
            with contextlib.redirect_stdout(sys.stderr):
                record, result = JOBS.get(spec["source"], study)(spec["args"])
        except Exception:
            emit(out, {"key": spec["key"], "error": traceback.format_exc()[-3000:]})
            continue
        seconds = round(time.perf_counter() - started, 1)
        if isinstance(record, dict):
            record = without_wall(record)
        emit(out, {"key": spec["key"], "record": record, "run": result, "seconds": seconds})
    emit(out, {"done": {"compiled": compiled_modules()}})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
