"""Handing run keys to processes: never on a command line, which other users can read.

``swarm run`` gives each child its keys in the environment variable ``BESTOFN_RUN_KEYS``
set for that child only (forked robots get it through the fork call), and the child
takes it out of its environment at once. A process started by hand reads a key file
(``--key-file``, written by ``python -m plumbing.run_keys``). Without either it runs
unauthenticated, as every process did before run keys, and says so.

A key file, or the variable, is one JSON object::

    {"v": 1, "run": "<run id>", "secret": "<64 hex digits>"}               (infrastructure)
    {"v": 1, "run": "<run id>", "keys": {"robot/3": "<64 hex digits>"}}    (a robot)
"""

from __future__ import annotations

import argparse
import logging
import os
import secrets
import stat
import sys
from collections.abc import Sequence
from pathlib import Path

from plumbing import cliargs
from wire import auth, names

KEYS_ENV = "BESTOFN_RUN_KEYS"
log = logging.getLogger("run_keys")


def new_secret() -> bytes:
    return secrets.token_bytes(auth.SECRET_BYTES)


def to_text(keyring: auth.Keyring, run: str) -> str:
    return auth.keyring_to_text(keyring, run)


def from_text(text: str, run: str) -> auth.Keyring:
    """The keyring in ``text``; ValueError says what is wrong (never echoes a key)."""
    found, keyring = auth.keyring_from_text(text)
    if found != run:
        raise ValueError(f"the keys are for run {found!r}, not {run!r}")
    return keyring


def load(run: str, key_file: str | None, program: str) -> auth.Keyring | None:
    """This process's keys: from the launcher's variable (removed from the environment at
    once, so that nothing this process starts inherits it), else from ``key_file``.

    None, with a warning, when there are none. ValueError on a bad key file."""
    text = os.environ.pop(KEYS_ENV, None)
    source = f"${KEYS_ENV}"
    if text is None and key_file is not None:
        path = Path(key_file)
        try:
            text = path.read_text()
            mode = path.stat().st_mode
        except OSError as error:
            raise ValueError(f"cannot read key file {key_file}: {error.strerror}") from None
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            log.warning("key file %s can be read by other users (chmod 600 it)", key_file)
        source = key_file
    if text is None:
        log.warning(
            "%s: no run keys: messages are neither tagged nor checked (unauthenticated run)",
            program,
        )
        return None
    try:
        return from_text(text, run)
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None


def from_args(
    parser: argparse.ArgumentParser, args: argparse.Namespace, program: str
) -> auth.Keyring | None:
    """``load`` for a process's command line: a bad key file is a usage error (exit 2)."""
    try:
        return load(args.run_id, args.key_file, program)
    except ValueError as error:
        parser.exit(2, f"{program}: error: {error}\n")


def write(path: Path, keyring: auth.Keyring, run: str) -> None:
    """A key file only its owner can read."""
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "w") as file:
        file.write(to_text(keyring, run) + "\n")
    path.chmod(0o600)


# --- command line: key files for processes started by hand -------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m plumbing.run_keys",
        description="Write the key files of one run: secret.json for the world server, "
        "beacon, recorder and launcher, and robot-<id>.json for each robot (its key only).",
    )
    parser.add_argument("--run-id", type=cliargs.name, required=True, help="the run id")
    parser.add_argument(
        "--robots",
        type=cliargs.robots,
        required=True,
        help="number of robots (ids 0 to N-1)",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    out: Path = args.out
    if (out / "secret.json").exists():
        print(f"run_keys: error: {out / 'secret.json'} exists; not replacing it", file=sys.stderr)
        return 1
    out.mkdir(parents=True, exist_ok=True)
    out.chmod(0o700)
    keyring = auth.Keyring(secret=new_secret())
    write(out / "secret.json", keyring, args.run_id)
    for robot in range(args.robots):
        robot_keys = keyring.only([names.robot_identity(robot)])
        write(out / f"robot-{robot}.json", robot_keys, args.run_id)
    print(f"wrote secret.json and {args.robots} robot key file(s) in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
