"""Every kind of message is spelled once, in the key table (bestofn_swarm/wire/keyspace.py):
the product's code holds no key built by hand and no enumeration of kinds beside it. A new
kind is then one row there, and what hears or sends it asks the table."""

from __future__ import annotations

import ast
import enum
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from bestofn_swarm.wire import keyspace

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("bestofn_swarm", "robot_agent", "world_server", "nest_beacon", "deploy")
TABLE = REPO / "bestofn_swarm" / "wire" / "keyspace.py"
ANY_CHUNK = "[^/\\s\"'`]+"


def kind_patterns() -> dict[str, re.Pattern[str]]:
    """Each kind's key as text: its chunks, a placeholder matching any one chunk (or a
    wildcard), and a key expression of a whole folder (``alive/**``) too."""
    found: dict[str, re.Pattern[str]] = {}
    for kind in keyspace.KINDS:
        chunks = [
            ANY_CHUNK if chunk.startswith("{") else re.escape(chunk) for chunk in kind.pattern
        ]
        found[kind.name] = re.compile(r"(?<![\w-])" + "/".join(chunks) + r"(?![\w-])")
        found[f"{kind.name} folder"] = re.compile(
            r"(?<![\w-])" + re.escape(kind.pattern[0]) + r"/\*\*"
        )
    return found


PATTERNS = kind_patterns()


def strings(tree: ast.AST) -> Iterator[tuple[int, str]]:
    """Every string the code builds (an f-string with its values as ``X``), but
    docstrings."""
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    inside_fstrings = {
        id(part)
        for node in ast.walk(tree)
        if isinstance(node, ast.JoinedStr)
        for part in node.values
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            text = "".join(
                str(part.value) if isinstance(part, ast.Constant) else "X" for part in node.values
            )
            yield node.lineno, text
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings
            and id(node) not in inside_fstrings
        ):
            yield node.lineno, node.value


def _shown(path: Path) -> str:
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else path.name


def hand_built_keys(path: Path) -> list[str]:
    """Strings that hold a key of a kind: no whitespace (a key has none; a sentence that
    names a key, in a log line or a help text, is prose)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    return [
        f"{_shown(path)}:{line}: {text!r} spells {name}"
        for line, text in strings(tree)
        if not any(character.isspace() for character in text)
        for name, pattern in PATTERNS.items()
        if pattern.search(text)
    ]


def kind_enums(path: Path) -> list[str]:
    """Enumerations whose members are kinds of the table, by name or by value (the last
    word of a key: ``sense``, ``rx``; a liveliness token's words are roles, names.Role)."""
    spelled = {kind.name for kind in keyspace.KINDS} | {
        [chunk for chunk in kind.pattern if not chunk.startswith("{")][-1]
        for kind in keyspace.KINDS
        if kind.how is not keyspace.How.TOKEN
    }
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if not isinstance(node, ast.ClassDef):
            continue
        if not any(
            isinstance(base, ast.Attribute | ast.Name)
            and (base.attr if isinstance(base, ast.Attribute) else base.id).endswith("Enum")
            for base in node.bases
        ):
            continue
        members = [
            (target.id, statement.value)
            for statement in node.body
            if isinstance(statement, ast.Assign)
            for target in statement.targets
            if isinstance(target, ast.Name)
        ]
        kinds = [
            name
            for name, value in members
            if name.lower() in spelled
            or (isinstance(value, ast.Constant) and str(value.value).lower() in spelled)
        ]
        if len(kinds) >= 2:
            found.append(f"{_shown(path)}:{node.lineno}: {node.name} lists {kinds}")
    return found


def kind_lists(path: Path) -> list[str]:
    """Lists, sets, tuples and dicts that name two kinds or more, by their names or by the
    schema names a recording gives them (``bestofn.Sense``), and such names alone."""
    names = {kind.name for kind in keyspace.KINDS}
    # Our schemas (Foxglove's own names belong to world_server/recording/foxglove.py).
    schemas = {
        kind.schema
        for kind in keyspace.KINDS
        if kind.schema is not None and kind.schema.startswith("bestofn.")
    }
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        items: list[ast.expr | None] = []
        if isinstance(node, ast.List | ast.Set | ast.Tuple):
            items = list(node.elts)
        elif isinstance(node, ast.Dict):
            items = list(node.keys)
        elif isinstance(node, ast.Compare) and all(
            isinstance(op, ast.Eq | ast.NotEq | ast.Is | ast.IsNot) for op in node.ops
        ):
            items = [node.left, *node.comparators]
        elif isinstance(node, ast.Constant) and node.value in schemas:
            found.append(f"{_shown(path)}:{node.lineno}: the schema {node.value!r}")
            continue
        named = [
            item.value
            for item in items
            if isinstance(item, ast.Constant)
            and isinstance(item.value, str)
            and item.value in names
        ]
        if len(named) >= (1 if isinstance(node, ast.Compare) else 2):
            found.append(f"{_shown(path)}:{getattr(node, 'lineno', 0)}: kinds {named}")
    return found


def product_files() -> list[Path]:
    return sorted(
        path
        for package in PACKAGES
        for path in (REPO / package).rglob("*.py")
        if path != TABLE and ".venv" not in path.parts
    )


def test_no_key_is_built_by_hand() -> None:
    found = [problem for path in product_files() for problem in hand_built_keys(path)]
    assert found == []


def test_no_enumeration_of_kinds_stands_beside_the_table() -> None:
    found = [
        problem for path in product_files() for problem in [*kind_enums(path), *kind_lists(path)]
    ]
    assert found == []


@pytest.mark.parametrize(
    "source",
    [
        'key = f"{prefix}/robot/{robot}/sense"',
        'key = prefix + "/world/clock"',
        'subscribe(f"{keys.prefix}/alive/**")',
        'class Kinds(StrEnum):\n    SENSE = "sense"\n    ACT = "act"\n',
        "class Kinds(enum.Enum):\n    STATUS = 1\n    CLOCK = 2\n",
        'VIEWED = frozenset({"state", "clock", "status"})',
        'TYPES = {"clock": Clock, "sense": Sense}',
        'if schema == "bestofn.Sense": pass',
        'if kind.name == "status": pass',
    ],
)
def test_the_checks_find_what_they_look_for(tmp_path: Path, source: str) -> None:
    path = tmp_path / "probe.py"
    path.write_text(source)
    assert hand_built_keys(path) or kind_enums(path) or kind_lists(path)


def test_the_table_is_what_the_checks_read() -> None:
    assert set(PATTERNS) >= {kind.name for kind in keyspace.KINDS}
    assert issubclass(keyspace.Party, enum.Enum)  # parties are not kinds
