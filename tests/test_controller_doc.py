"""docs/controller.md says what the code does: its tables of settings, of the navigator's
parameters and of fixed constants give every value the code has, and its table of
transitions is ``phases.TRANSITIONS``. Where the page and the code disagree, this says
which row."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import re
from pathlib import Path
from typing import Any

import pytest

from robot_agent.core import navigation, phases
from robot_agent.core.controller_config import ControllerConfig
from robot_agent.core.navigation import NavParams

PAGE = Path(__file__).resolve().parent.parent / "docs" / "controller.md"
BODY = {  # the navigator's parameters that are the body's, from the map
    "max_speed": "WorldInfo.max_wheel_speed",
    "wheel_base": "WorldInfo.wheel_base",
    "robot_radius": "WorldInfo.robot_radius",
    "control_period": "WorldInfo.dt",
}


def table(header: str) -> list[list[str]]:
    """The rows (cells, stripped) of the page's table whose header row is ``header``."""
    lines = PAGE.read_text(encoding="utf-8").splitlines()
    starts = [index for index, line in enumerate(lines) if line.strip() == header]
    assert len(starts) == 1, f"one table headed {header!r} on the page"
    rows = []
    for line in lines[starts[0] + 2 :]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def name(cell: str) -> str:
    found = re.fullmatch(r"`([^`]+)`", cell)
    assert found, f"{cell!r} is not a `name`"
    return found.group(1)


def value(cell: str) -> Any:
    """A value cell: a number or tuple as Python writes it, or a `string`."""
    found = re.fullmatch(r"`([^`]+)`", cell)
    if found:
        return found.group(1)
    return ast.literal_eval(cell)


def same(written: Any, actual: Any) -> bool:
    """Equal, and of the same kind (2 is not 2.0: an integer setting stays one)."""
    if isinstance(actual, tuple):
        return (
            isinstance(written, tuple)
            and len(written) == len(actual)
            and all(same(a, b) for a, b in zip(written, actual, strict=True))
        )
    return type(written) is type(actual) and written == actual


def test_the_settings_table_is_controller_config() -> None:
    rows = table("| setting | default | unit | what it is |")
    written = {name(row[0]): value(row[1]) for row in rows}
    fields = {field.name: field.default for field in dataclasses.fields(ControllerConfig)}
    assert written.keys() == fields.keys(), "a setting missing from the page, or one too many"
    wrong = {
        key: (written[key], fields[key]) for key in fields if not same(written[key], fields[key])
    }
    assert not wrong, f"the page's default, the code's: {wrong}"


def test_the_navigators_table_is_nav_params() -> None:
    rows = table("| parameter | default | unit | what it is |")
    written = {name(row[0]): row[1] for row in rows}
    fields = {field.name: field for field in dataclasses.fields(NavParams)}
    assert written.keys() == fields.keys(), "a parameter missing from the page, or one too many"
    for key, field in fields.items():
        cell = written[key]
        if key in BODY:
            assert cell == f"`{BODY[key]}`", f"{key}: the body's, from the map"
            continue
        if key == "prox_angles":
            assert cell == "`EPUCK_PROX_ANGLES`"
            assert field.default == navigation.EPUCK_PROX_ANGLES
            continue
        assert same(value(cell), field.default), f"{key}: page {cell}, code {field.default!r}"


def test_the_fixed_constants_are_the_codes() -> None:
    rows = table("| constant | value | unit | what it is |")
    assert rows
    for row in rows:
        module_name, _, attribute = name(row[0]).rpartition(".")
        module = importlib.import_module(f"robot_agent.core.{module_name}")
        actual = getattr(module, attribute)
        assert same(value(row[1]), actual), f"{row[0]}: page {row[1]}, code {actual!r}"


def test_the_transitions_table_is_the_phase_table() -> None:
    rows = table("| phase | event | next phase | when |")
    written = [(name(row[0]), name(row[1]), name(row[2])) for row in rows]
    code = [
        (phase, event, entered)
        for phase, leaving in phases.TRANSITIONS.items()
        for event, entered in leaving.items()
    ]
    assert sorted(written) == sorted(code), (
        f"only on the page: {sorted(set(written) - set(code))}; "
        f"only in the code: {sorted(set(code) - set(written))}"
    )
    assert len(written) == len(set(written)), "a transition twice on the page"
    assert all(row[3] for row in rows), "every transition says when"


def test_every_phase_says_what_entering_it_does() -> None:
    rows = table("| phase | on entry |")
    assert [name(row[0]) for row in rows] == list(phases.TRANSITIONS)


@pytest.mark.parametrize(
    "link",
    ["porting.md#conformance-vectors", "porting.md#checking-a-port-swarm-conformance"],
)
def test_the_page_and_porting_md_point_at_each_other(link: str) -> None:
    assert f"({link})" in PAGE.read_text(encoding="utf-8")
    porting = (PAGE.parent / "porting.md").read_text(encoding="utf-8")
    assert "(controller.md)" in porting
    assert "the code is the specification" not in porting.lower()
