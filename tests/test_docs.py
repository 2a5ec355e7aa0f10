"""The docs say what the code is: every path, module and name of the code they give
exists, README's command table names every command, the exit codes they show are the
enum's, the layer table is tests/test_layering.py's, and every generated block names the
command that writes it.

Pages that tell history (docs/history.md, old measurements in docs/performance.md) may name
what is gone only where they say "at the time"; those names are listed in ``HISTORICAL``.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from doc_references import REPO, Code, Reference, documents, problem, references, references_in
from test_layering import ALLOWED

from bestofn_swarm.wire.endings import exit_codes_help
from deploy.cli import SUBCOMMANDS
from deploy.study.catalogue import study_named

# Names of code that is gone, in pages that say so ("as they were at the time"): the
# profile of docs/performance.md was taken at 4f7c3a0, before the layers had folders.
HISTORICAL = {
    ("docs/performance.md", "robot_agent/node.py"),
    ("docs/performance.md", "RobotNode._step"),
    ("docs/performance.md", "WorldServer._open_tick"),
    ("docs/performance.md", "WorldServer._close_tick"),
}
README = REPO / "README.md"
RUNNING = REPO / "docs" / "running.md"
ARCHITECTURE = REPO / "docs" / "architecture.md"


@pytest.fixture(scope="module")
def code() -> Code:
    return Code()


def _all_references() -> list[Reference]:
    return [reference for document in documents() for reference in references(document)]


def test_the_docs_name_only_what_is_there(code: Code) -> None:
    found = {
        f"{reference.document}: {reference.kind} {reference.text!r}: {wrong}"
        for reference in _all_references()
        if (reference.document, reference.text) not in HISTORICAL
        and (wrong := problem(reference, code)) is not None
    }
    assert sorted(found) == []


def test_the_historical_exceptions_are_still_needed(code: Code) -> None:
    """An exception whose name is back, or no longer in its page, goes from the list."""
    needed = {
        (reference.document, reference.text)
        for reference in _all_references()
        if problem(reference, code) is not None
    }
    assert HISTORICAL - needed == set()


def test_the_reference_checks_catch_what_is_gone(code: Code) -> None:
    """The checks themselves: each kind of stale name is caught, and live ones pass."""
    text = (
        "`deploy/launcher.py`, `deploy/launcher/launcher.py`, [x](nowhere.md), "
        "[y](protocol.md#keys), [z](protocol.md#no-such-heading), `node.py`, "
        "`robot_node.py`, `python -m world_server.recorder`, `python -m deploy.nothing`, "
        "`deploy.reports.report.read_recording`, `deploy.reports.report.no_such_function`, "
        "`WorldServer._open_tick`, `World.advance`, `protocol.check_name`, "
        "`names.check_name`, `Interrupted`, `RobotEndpoint`, `runs/<run-id>.mcap`, "
        "`tests/vectors/<type>.json`, `viewer/finish`, `summary.json`"
    )
    found = {
        reference.text: problem(reference, code)
        for reference in references_in(text, "docs/a-page.md")
    }
    assert {name for name, wrong in found.items() if wrong is not None} == {
        "deploy/launcher.py",
        "nowhere.md",
        "protocol.md#no-such-heading",
        "node.py",
        "deploy.nothing",
        "deploy.reports.report.no_such_function",
        "WorldServer._open_tick",
        "protocol.check_name",
        "Interrupted",
    }
    assert {"deploy/launcher/launcher.py", "RobotEndpoint", "World.advance"} <= found.keys()


def _commands_in_readme() -> set[str]:
    """The commands of README's command table (its first column)."""
    section = README.read_text().split("## Commands", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `([^`]+)` \|", section, re.MULTILINE))


def test_readmes_command_table_names_every_command() -> None:
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    expected = {f"swarm {name}" for name in SUBCOMMANDS} | (set(scripts) - {"swarm"})
    assert _commands_in_readme() == expected


def test_readme_stays_short() -> None:
    """Issue 21: a newcomer reads it in ten minutes; the rest is in docs/."""
    assert len(README.read_text().splitlines()) <= 150


def test_the_exit_codes_shown_are_the_enums() -> None:
    """docs/running.md shows ``swarm run --help``'s table of endings, made from ``Ending``."""
    text = RUNNING.read_text()
    marker = text.index("<!-- exit codes:")
    shown = re.search(r"```\n(.*?)```", text[marker:], re.DOTALL)
    assert shown is not None
    assert shown.group(1) == exit_codes_help()


def _layer_table() -> dict[str, set[str]]:
    """docs/architecture.md's table of folders: each folder and the folders it may import."""
    rows = re.findall(r"^\| `([\w/]+)/` \| \w+ \| .*? \| (.*?) \|$", ARCHITECTURE.read_text(), re.M)
    table: dict[str, set[str]] = {}
    for folder, imports in rows:
        named = {name.rstrip("/") for name in re.findall(r"`([\w/]+)`", imports)}
        if imports.startswith("everything"):
            named = set(ALLOWED) - {folder} - named
        table[folder] = named
    return table


def test_the_architecture_draws_the_layers_of_test_layering() -> None:
    assert _layer_table() == ALLOWED


GENERATED = re.compile(r"<!-- BEGIN generated by `([^`]+)` \(([^)]*)\); edit ([\w/.]+) -->")


def _writer(command: str) -> Path:
    """The source of the command that writes a block: a study's declaration (``swarm study
    NAME``), a ``swarm`` subcommand's module, or the script the command runs."""
    words = command.split()
    if words[:2] == ["swarm", "study"]:
        return REPO / study_named(words[2]).source
    if words[0] == "swarm":
        return REPO / (SUBCOMMANDS[words[1]][0].replace(".", "/") + ".py")
    return REPO / words[0]


@pytest.mark.parametrize("document", documents(), ids=lambda path: path.name)
def test_every_generated_block_names_a_command_that_writes_it_here(document: Path) -> None:
    """A block between markers is written by a command that exists, into this page: none is
    left behind by a command that now writes elsewhere, or no longer at all."""
    text = document.read_text()
    relative = str(document.relative_to(REPO))
    for command, name, edit in GENERATED.findall(text):
        assert f"<!-- END generated by `{command}` ({name}) -->" in text, (relative, name)
        assert (REPO / edit).is_file(), (relative, edit)
        writer = _writer(command)
        assert relative in command or relative in writer.read_text(), (relative, command)
    if "<!-- swarm_speed:engines -->" in text:
        assert text.count("<!-- swarm_speed:engines -->") == 1
        assert text.count("<!-- /swarm_speed:engines -->") == 1
        # benchmarks/swarm_speed.py --doc writes there (issue 26: README's speed block too)
        assert relative in ("docs/performance.md", "README.md"), relative
