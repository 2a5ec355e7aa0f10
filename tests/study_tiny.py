"""A tiny study, declared in a file of its own as a user would (``swarm study tiny
--declared tests/study_tiny.py``): 10 robots, 5 sites, runs given up at 120 sim s, 3 seeds
without and 3 with 20% loss in one process, and seed 0 over Zenoh with a recording, given
up at 600 sim s (it reaches consensus long before). Its
page is ``tiny.md`` under the root it is rendered into."""

from __future__ import annotations

import json
from pathlib import Path

from deploy.study import tables
from deploy.study.declare import Output, Page, Records, Study
from deploy.study.grid import Point

OPTIONS = ["--robots", "10", "--sites", "5"]
PAGE = "tiny.md"


def points() -> list[Point]:
    return [
        Point(
            {"engine": "inprocess", "drop": 0.0},
            range(3),
            options=[*OPTIONS, "--drop", "0"],
            timeout=120.0,
        ),
        Point(
            {"engine": "inprocess", "drop": 0.2},
            range(3),
            options=[*OPTIONS, "--drop", "0.2"],
            timeout=120.0,
        ),
        Point(
            {"engine": "zenoh", "drop": 0.0},
            range(1),
            "zenoh",
            options=[*OPTIONS, "--drop", "0"],
            timeout=600.0,
            cost=30.0,
            record=True,
        ),
    ]


def table(records: Records) -> str:
    lines = ["| engine | drop | seed | ended | sim s |", "|---|---:|---:|---|---:|"]
    for record in records.runs:
        result = tables.result(record)
        params = record["params"]
        lines.append(
            f"| {params['engine']} | {params['drop']:g} | {record['seed']} | {result['ended']} "
            f"| {result['sim_time_s']:.1f} |"
        )
    return "\n".join(lines)


def write_times(records: Records, path: Path) -> None:
    times = {record["key"]: tables.result(record)["sim_time_s"] for record in records.runs}
    path.write_text(json.dumps(times, indent=1) + "\n")


STUDY = Study(
    name="tiny",
    title="a tiny study",
    about="10 robots, 120 sim s",
    points=points,
    source="tests/study_tiny.py",
    pages=(Page(PAGE, lambda records: {"table": table(records)}),),
    outputs=(Output("tiny.json", write_times),),
)


def page_text() -> str:
    """The page, with the markers of its blocks and nothing in them."""
    from deploy.study import page

    blocks = [
        f"{page.begin_marker(STUDY, name)}\n{page.end_marker(STUDY, name)}"
        for name in ("made", "table")
    ]
    return "# A tiny study\n\n" + "\n\n".join(blocks) + "\n"
