"""The run a recording is of (``RunDescription``) and what its metadata records say about
it beside that: the layout and the versions of everything that shaped the run."""

from __future__ import annotations

import contextlib
import importlib.metadata
import json
import platform
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar

from msgspec import Meta

from bestofn_swarm.wire import names, protocol, settings, shape
from bestofn_swarm.wire.settings import Flag
from world_server.core.layout import Layout


def json_object(text: str) -> dict[str, Any]:
    """``--config-json``: a JSON object, or ValueError."""
    settings.check_text_size(text)
    try:
        value = json.loads(text)
    except ValueError as error:
        raise ValueError(f"not JSON: {error}") from None
    if not isinstance(value, dict):
        raise ValueError("not a JSON object")
    return value


@dataclass(frozen=True)
class RunDescription:
    """The run a recording is of: what the recorder is configured with (its options, or
    ``--config``, which is how ``swarm run`` hands it over)."""

    FLAG_GROUP: ClassVar[str] = "run"

    run_id: Annotated[names.Name, Meta(description="the run id")] = "run"
    seed: Annotated[shape.Seed, Meta(description="run seed"), Flag()] = shape.DEFAULT_SEED
    robots: Annotated[
        shape.Robots, Meta(description="swarm size of the run, for its layout"), Flag()
    ] = shape.DEFAULT_ROBOTS
    sites: Annotated[shape.Sites, Meta(description="number of sites of the run"), Flag()] = (
        shape.DEFAULT_SITES
    )
    config: Annotated[
        dict[str, Any],
        Meta(description="the run's full configuration, kept in the metadata record"),
        Flag(name="config-json", metavar="JSON", parse=json_object, default_text="{}"),
    ] = field(default_factory=dict)

    def __post_init__(self) -> None:
        settings.check(self)


def versions() -> dict[str, str]:
    """Versions of everything that shapes a run, for the metadata record."""
    found = {
        "protocol": str(protocol.VERSION),
        "python": platform.python_version(),
        "platform": platform.platform(),
    }
    for package in (
        "bestofn-swarm",
        "eclipse-zenoh",
        "mcap",
        "msgspec",
        "numpy",
        "pymunk",
        "opencv-python-headless",
    ):
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            found[package] = importlib.metadata.version(package)
    source = Path(__file__).resolve().parent.parent
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        commit = subprocess.run(
            ["git", "-C", str(source), "describe", "--always", "--dirty", "--abbrev=12"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        if commit:
            found["git"] = commit
    return found


def layout_description(layout: Layout) -> dict[str, Any]:
    return {
        "arena_radius": layout.arena_radius,
        "nest_radius": layout.nest_radius,
        "best_site": layout.best_site,
        "sites": [
            {
                "id": site.id,
                "x": site.x,
                "y": site.y,
                "angle": site.angle,
                "quality": site.quality,
                "rank": site.rank,
            }
            for site in layout.sites
        ],
    }
