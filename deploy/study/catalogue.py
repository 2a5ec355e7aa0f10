"""Every declared study, by name (``swarm study --list``), and studies declared in a file
of one's own (``swarm study NAME --declared FILE``: a Python file that sets ``STUDY``, or
``STUDIES``, a list of them)."""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Sequence
from pathlib import Path

from deploy.study.declare import Study

MODULES = (
    "deploy.study.strategies",
    "deploy.study.byzantine",
    "deploy.study.defence",
    "deploy.study.robustness",
    "deploy.study.section5_settings",
    "deploy.study.scale",
)


def studies(declared: Sequence[Path] = ()) -> dict[str, Study]:
    """The studies by name: the project's, then those of the ``declared`` files; ValueError
    for a file that declares none, or a name declared twice."""
    found: dict[str, Study] = {}
    for study in [importlib.import_module(name).STUDY for name in MODULES] + [
        study for path in declared for study in _declared_in(path)
    ]:
        if study.name in found:
            raise ValueError(f"two studies are named {study.name!r}")
        found[study.name] = study
    return found


def _declared_in(path: Path) -> list[Study]:
    spec = importlib.util.spec_from_file_location(f"declared_study_{abs(hash(path))}", path)
    if spec is None or spec.loader is None or not path.is_file():
        raise ValueError(f"--declared {path}: no such Python file")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    declared = getattr(module, "STUDIES", None) or [getattr(module, "STUDY", None)]
    if not all(isinstance(study, Study) for study in declared):
        raise ValueError(f"--declared {path}: set STUDY (or STUDIES) to deploy.study.declare.Study")
    return list(declared)


def study_named(name: str, declared: Sequence[Path] = ()) -> Study:
    """The study called ``name``; ValueError naming the studies there are."""
    found = studies(declared)
    if name not in found:
        raise ValueError(f"no study {name!r} (there are {', '.join(found)})")
    return found[name]
