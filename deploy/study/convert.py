"""The results files of the scripts the study runner replaced, as study results files.

``python -m deploy.study.convert`` reads ``docs/strategies-runs.jsonl`` (made at commit
4cd2cd5), ``docs/byzantine-defence-runs.jsonl`` (0bb308b) and ``docs/scale-runs.json``
(each run at the commit that first published it, read from git) and writes their runs to
``docs/studies/strategies.jsonl``, ``defence.jsonl`` and ``scale.jsonl``, keyed as the
studies key them, with the commit they were made at and the hash of the run lock of that
commit. Those old files kept less than a study's run does (no per-robot results, no
radio counts, no digest): a converted run has only the fields its page reads, and a check
that makes it again reports the fields it lacks.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from deploy.study import results
from deploy.study.catalogue import study_named
from deploy.study.grid import key_of

STRATEGIES_COMMIT = "4cd2cd5"
DEFENCE_COMMIT = "0bb308b"


def _git(root: Path, *args: str) -> str:
    return subprocess.run(
        ["git", *args], cwd=root, capture_output=True, text=True, check=True
    ).stdout


def lock_at(root: Path, commit: str) -> str:
    """The run lock's hash at ``commit`` (as ``results.lock_hash`` gives it)."""
    text = _git(root, "show", f"{commit}:{results.RUN_LOCK}")
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _record(
    root: Path, study: str, params: dict[str, Any], seed: int, result: dict[str, Any],
    *, wall: float | None, commit: str,
) -> dict[str, Any]:  # fmt: skip
    key = key_of(params, seed)
    declared = {run.key: run for run in study_named(study).runs()}
    run = declared.get(key)
    return {
        "key": key,
        "params": params,
        "seed": seed,
        "kind": run.kind if run else None,
        "command": run.command() if run else None,
        "result": result,
        "wall_s": wall,
        "commit": commit,
        "dirty": False,
        "lock": lock_at(root, commit),
        "converted": True,
    }


def _swarm_result(verdict: str, **fields: Any) -> dict[str, Any]:
    return {
        "consensus": verdict in ("correct", "wrong"),
        "correct": verdict == "correct",
        "verdict": verdict,
        **fields,
    }


def strategies(root: Path, lines: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    found = []
    for old in lines:
        if old["kind"] == "wellstirred":
            params = {"part": "wellstirred", "strategy": old["strategy"], "options": old["options"]}
            fields = ("agents", "group", "steps_limit", "times", "success")
            result = {name: old[name] for name in fields}
        else:
            params = {
                "part": "swarm",
                "robots": old["robots"],
                "sites": old["sites"],
                "drop": float(old["drop"]),
                "strategy": old["strategy"],
            }
            result = _swarm_result(
                old["verdict"], ended=old["ended"], sim_time_s=old["sim_time_s"],
                slowest_steps=old["steps"],
            )  # fmt: skip
        found.append(
            _record(
                root,
                "strategies",
                params,
                old["seed"],
                result,
                wall=old["wall_s"],
                commit=STRATEGIES_COMMIT,
            )
        )
    return found


def defence(root: Path, lines: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    found = []
    for old in lines:
        params = {"robots": old["robots"], "liars": old["liars"], "defence": old["defence"]}
        result = _swarm_result(
            old["verdict"], sim_time_s=old["sim_time_s"], liar_won=old["liar_won"],
            liar_site_decided=old["liar_site_decided"],
        )  # fmt: skip
        found.append(
            _record(
                root,
                "defence",
                params,
                old["seed"],
                result,
                wall=old["wall_s"],
                commit=DEFENCE_COMMIT,
            )
        )
    return found


def scale(root: Path, runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each run with the commit that first published it as it is now."""
    history = _git(root, "log", "--reverse", "--format=%h", "--", "docs/scale-runs.json").split()
    first: dict[str, str] = {}
    for commit in history:
        for old in json.loads(_git(root, "show", f"{commit}:docs/scale-runs.json")):
            first.setdefault(json.dumps(old, sort_keys=True), commit)
    found = []
    for old in runs:
        engine = "inprocess" if old["mode"] == "in-process" else "zenoh"
        params = {"engine": engine, "robots": old["robots"]}
        fields = ("ended", "consensus", "correct", "sim_time_s", "timed_out", "undecided")
        result = {name: old[name] for name in fields}
        result |= {
            "slowest_steps": old["slowest_steps"],
            "stalls": old["stalls"],
            "departures": old["departures"],
        }
        commit = first[json.dumps(old, sort_keys=True)]
        found.append(
            _record(
                root, "scale", params, old["seed"], result, wall=old["wall_time_s"], commit=commit
            )
        )
    return found


def _jsonl(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def main(root: Path) -> None:
    converted = {
        "strategies": strategies(root, _jsonl(root / "docs/strategies-runs.jsonl")),
        "defence": defence(root, _jsonl(root / "docs/byzantine-defence-runs.jsonl")),
        "scale": scale(root, json.loads((root / "docs/scale-runs.json").read_text())),
    }
    for name, records in converted.items():
        path = root / study_named(name).results
        with results.Appender(path) as appender:
            for record in records:
                appender.add(record)
        print(f"{path}: {len(records)} runs", file=sys.stderr)


if __name__ == "__main__":
    main(Path.cwd())
