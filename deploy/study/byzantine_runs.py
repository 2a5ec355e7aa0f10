"""What the study ``byzantine`` runs and what its runs give, read by its table, figure and
text (``byzantine.py``, ``byzantine_prose.py``): the modes, counts and defences of its
grid, and its table's cells (per mode, number of Byzantine robots and defence)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from deploy.study import tables
from deploy.study.declare import Records

MODES = ("liar", "inverted", "silent")
MAX_BYZANTINE = 3
ROBOTS = 10
SITES = 10
SEEDS = range(40)
TIMEOUT = 1200.0  # sim seconds


@dataclass(frozen=True)
class Defence:
    """A controller set-up, as ``swarm run`` options."""

    key: str
    label: str
    options: tuple[str, ...]


DEFENCES = (
    Defence("paper", "alpha = 0, MProdOp (paper)", ()),
    Defence("a005", "alpha = 0.05, MProdOp", ("--alpha", "0.05", "--threshold", "0.99")),
    Defence("a01", "alpha = 0.1, MProdOp", ("--alpha", "0.1", "--threshold", "0.99")),
    Defence(
        "loglinear",
        "alpha = 0.1, log-linear pool",
        ("--alpha", "0.1", "--threshold", "0.99", "--pooling", "loglinear"),
    ),
)
LABELS = {defence.key: defence.label for defence in DEFENCES}


def cells(records: Records) -> list[dict[str, Any]]:
    """Per (mode, count, defence); the runs without Byzantine robots count for every mode
    at count 0."""
    grouped: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for record in records.runs:
        params = record["params"]
        for mode in MODES if params["mode"] == "none" else [params["mode"]]:
            grouped.setdefault((mode, params["byzantine"], params["defence"]), []).append(record)
    order = [defence.key for defence in DEFENCES]
    rows = []
    for (mode, count, defence), runs in sorted(
        grouped.items(),
        key=lambda item: (MODES.index(item[0][0]), item[0][1], order.index(item[0][2])),
    ):
        results = [tables.result(run) for run in runs]
        rows.append(
            {
                "mode": mode,
                "count": count,
                "defence": defence,
                "runs": len(runs),
                **{verdict: tables.count(runs, verdict) for verdict in tables.VERDICTS},
                "liar_won": sum(bool(result.get("liar_won")) for result in results),
                "times": {
                    run["seed"]: result["sim_time_s"]
                    for run, result in zip(runs, results, strict=True)
                    if result["verdict"] in ("correct", "wrong")
                },
            }
        )
    return rows
