"""What the docs name in the repository, read from their Markdown, and whether it is there
(for tests/test_docs.py).

A name counts as the repository's when it is unmistakably so:

* ``path``: a path that starts with a top-level folder of the repository
  (``deploy/launcher/launcher.py``), anywhere in the text, code blocks included;
* ``link``: the target of a Markdown link (``[x](protocol.md#keys)``), its heading too;
* ``file``: a ``.py`` or ``.md`` file name in code quotes (``robot_node.py``);
* ``module``: ``python -m`` and a dotted module of the code (``world_server.recorder``);
* ``attribute``: in code quotes, a dotted module of the code and one of its names
  (``deploy.reports.report.read_recording``), a module's short name and one of its names
  (``names.check_name``), or a class of the code and one of its attributes
  (``World.advance``);
* ``name``: a CamelCase name in code quotes (``RobotEndpoint``), defined somewhere in the
  code (or the stem of a file: ``SceneUpdate``).
"""

from __future__ import annotations

import ast
import builtins
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# The top-level folders a path of the repository starts with.
TOP_LEVEL = (
    "bestofn_swarm",
    "robot_agent",
    "world_server",
    "nest_beacon",
    "deploy",
    "tests",
    "benchmarks",
    "docs",
    "examples",
    "portable",
)
# Not the repository's code: .portable/ holds make check-portable's downloads (another
# interpreter's standard library, the lock's packages for aarch64).
SKIPPED = {
    ".venv",
    ".git",
    "__pycache__",
    ".mypy_cache",
    ".ruff_cache",
    ".pytest_cache",
    ".portable",
}

PATH = re.compile(r"(?<![\w./<>-])((?:" + "|".join(TOP_LEVEL) + r")/[\w./<>{}*-]*)")
# A placeholder (``runs/<run-id>.mcap``, ``robot-{id}.json5``, ``*.mcap``) ends what can be
# checked of a path: the folder before it.
PLACEHOLDER = re.compile(r"[<{*]")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.DOTALL | re.MULTILINE)
CODE_SPAN = re.compile(r"`([^`\n]+)`")
FILE_NAME = re.compile(r"^[\w-]+\.(?:py|md)$")
DOTTED = re.compile(r"^(python -m )?([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\(.*\))?$")
CAMEL = re.compile(r"^_?[A-Z][a-z0-9]+(?:[A-Z][A-Za-z0-9]*)*$")
HEADING = re.compile(r"^#+\s+(.*)$", re.MULTILINE)

# Dotted names whose first part is a module's short name but, in the docs, something else:
# fields of the run's summary (JSON), Foxglove's schema names, a ``Layout`` object.
NOT_MODULES = {"summary", "world", "foxglove", "layout"}
# What a dotted name ending so is: a file name (``router.json5``), not a module's name.
FILE_SUFFIXES = {"json", "json5", "jsonl", "csv", "mcap", "png", "txt", "yaml", "pem", "key"}
# Names of the language and of JSON, not of the code.
OUTSIDE_NAMES = {*dir(builtins), "NaN", "Infinity"}


@dataclass(frozen=True)
class Reference:
    """One name a document gives, and what kind of name it is."""

    document: str  # the document's path in the repository
    kind: str  # path, link, file, module, attribute, name
    text: str


def documents() -> list[Path]:
    """README.md, deploy/README.md, deploy/zenoh/README.md and every page of docs/."""
    named = [REPO / "README.md", REPO / "deploy" / "README.md", REPO / "deploy/zenoh/README.md"]
    return named + sorted((REPO / "docs").glob("*.md"))


def references(document: Path) -> Iterator[Reference]:
    """Every name of the repository ``document`` gives."""
    return references_in(document.read_text(), str(document.relative_to(REPO)))


def references_in(text: str, document: str) -> Iterator[Reference]:
    """Every name of the repository ``text`` gives, read as the document at ``document``
    (its links are relative to it)."""
    for match in PATH.finditer(text):
        yield Reference(document, "path", match.group(1).rstrip(".,;:"))
    for match in LINK.finditer(text):
        yield Reference(document, "link", match.group(1))
    for match in CODE_SPAN.finditer(FENCE.sub("", text)):
        span = match.group(1).strip()
        if FILE_NAME.match(span):
            yield Reference(document, "file", span)
        elif (dotted := DOTTED.match(span)) is not None:
            name = dotted.group(2)
            if name.split(".")[0] not in NOT_MODULES and name.rsplit(".")[-1] not in FILE_SUFFIXES:
                yield Reference(document, "module" if dotted.group(1) else "attribute", name)
        elif CAMEL.match(span) and span not in OUTSIDE_NAMES:
            yield Reference(document, "name", span)


def anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[`*_\[\]()]", "", heading.strip().lower())
    return re.sub(r"[^\w\s-]", "", text).replace(" ", "-")


class Code:
    """The repository's files, and what its Python code defines, each read once."""

    def __init__(self) -> None:
        self.files = [path for path in _walk(REPO) if path.is_file()]
        self.paths = {str(path.relative_to(REPO)) for path in self.files}
        self.folders = {str(parent) for path in self.paths for parent in Path(path).parents}
        # Every file's name, and its stem (``SceneUpdate`` of ``SceneUpdate.json``).
        self.file_names = {path.name for path in self.files} | {path.stem for path in self.files}

    @cached_property
    def modules(self) -> dict[str, ast.Module]:
        """Every Python module by its path without ``.py`` (``deploy/launcher/launcher``)."""
        return {
            str(path.relative_to(REPO).with_suffix("")): ast.parse(path.read_text())
            for path in self.files
            if path.suffix == ".py"
        }

    @cached_property
    def classes(self) -> dict[str, list[ast.ClassDef]]:
        """Every class of the code, by its name (several modules may define one)."""
        found: dict[str, list[ast.ClassDef]] = {}
        for tree in self.modules.values():
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef):
                    found.setdefault(node.name, []).append(node)
        return found

    @cached_property
    def defined(self) -> set[str]:
        """Every name the code defines anywhere: classes, functions, assignments."""
        return {
            name
            for tree in self.modules.values()
            for node in ast.walk(tree)
            for name in _names_defined_by(node)
        }

    def exists(self, path: str) -> bool:
        """Whether ``path`` is a file or folder of the repository (up to a placeholder)."""
        if (cut := PLACEHOLDER.search(path)) is not None:
            return path[: cut.start()].rpartition("/")[0] in self.folders
        path = path.rstrip("/")
        return path in self.paths or path in self.folders

    def module_names(self, module: str) -> set[str] | None:
        """The names module ``module`` (``deploy/report``) defines at its top level, and for
        a package its modules; None if there is no such module."""
        tree = self.modules.get(module) or self.modules.get(f"{module}/__init__")
        if tree is None:
            return None
        names = {name for node in tree.body for name in _names_defined_by(node)}
        inside = {Path(other).name for other in self.modules if str(Path(other).parent) == module}
        return names | inside

    def class_attributes(self, name: str) -> set[str] | None:
        """What the classes called ``name`` define, their bases' included (None: no class
        of that name)."""
        if name not in self.classes:
            return None
        attributes: set[str] = set()
        for node in self.classes[name]:
            attributes |= {found for item in node.body for found in _names_defined_by(item)}
            attributes |= {
                item.attr
                for item in ast.walk(node)
                if isinstance(item, ast.Attribute)
                and isinstance(item.value, ast.Name)
                and item.value.id == "self"
                and isinstance(item.ctx, ast.Store)
            }
            for base in node.bases:
                if isinstance(base, ast.Name) and base.id != name:
                    attributes |= self.class_attributes(base.id) or set()
        return attributes

    def defines(self, module: str, names: Sequence[str]) -> bool:
        """Whether ``module`` defines ``names[0]``, and, if that is a class, whether the
        class has ``names[1]``."""
        if names[0] not in (self.module_names(module) or set()):
            return False
        attributes = self.class_attributes(names[0]) if len(names) > 1 else None
        return attributes is None or names[1] in attributes


def _walk(folder: Path) -> Iterator[Path]:
    for path in folder.iterdir():
        if path.name in SKIPPED or path.name.endswith(".egg-info"):
            continue
        yield path
        if path.is_dir():
            yield from _walk(path)


def _names_defined_by(node: ast.AST) -> set[str]:
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return {node.name}
    if isinstance(node, ast.Assign):
        return {target.id for target in node.targets if isinstance(target, ast.Name)}
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return {node.target.id}
    if isinstance(node, ast.Import | ast.ImportFrom):
        return {(alias.asname or alias.name).split(".")[0] for alias in node.names}
    return set()


def problem(reference: Reference, code: Code) -> str | None:
    """What is wrong with ``reference``; None if it names what is there."""
    text = reference.text
    if reference.kind == "path":
        return None if code.exists(text) else "no such file or folder"
    if reference.kind == "link":
        return _link_problem(text, REPO / reference.document)
    if reference.kind == "file":
        return None if text in code.file_names else "no file of that name"
    if reference.kind == "name":
        found = text in code.defined or text in code.file_names
        return None if found else "nothing of that name in the code"
    return _dotted_problem(text.split("."), code, module_only=reference.kind == "module")


def _link_problem(target: str, document: Path) -> str | None:
    if re.match(r"^[a-z]+:", target):
        return None  # a URL
    path, _, fragment = target.partition("#")
    file = (document.parent / path).resolve() if path else document
    if not file.exists():
        return "the link's file does not exist"
    if fragment and file.suffix == ".md" and fragment not in _anchors(file):
        return f"no heading {fragment!r} in {file.relative_to(REPO)}"
    return None


def _anchors(page: Path) -> set[str]:
    return {anchor(heading) for heading in HEADING.findall(page.read_text())}


def _dotted_problem(parts: list[str], code: Code, module_only: bool) -> str | None:
    if parts[0] in TOP_LEVEL:
        # A module's path, maybe followed by one of its names (and that one's attribute).
        for cut in range(len(parts), 0, -1):
            module, rest = "/".join(parts[:cut]), parts[cut:]
            if code.module_names(module) is None:
                continue
            if not rest:
                return None
            if module_only:
                return "no such module"
            return None if code.defines(module, rest) else f"{module} has no {'.'.join(rest)!r}"
        return "no such module"
    if parts[0][0].isupper():
        attributes = code.class_attributes(parts[0])
        if attributes is None or parts[1] in attributes:
            return None  # not a class of the code (a schema's name), or one that has it
        return f"class {parts[0]} has no {parts[1]!r}"
    modules = [module for module in code.modules if Path(module).name == parts[0]]
    if not modules or any(code.defines(module, parts[1:]) for module in modules):
        return None  # not a module of the code (a variable, a JSON field), or one that has it
    return f"no module {parts[0]} defines {'.'.join(parts[1:])!r}"
