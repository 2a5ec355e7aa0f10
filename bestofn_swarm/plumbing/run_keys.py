"""Handing run keys to processes: never on a command line, which other users can read.

``swarm run`` gives each child its keys in the environment variable ``BESTOFN_RUN_KEYS``
set for that child only (forked robots get it through the fork call), and the child
takes it out of its environment at once. A process started by hand reads a key file
(``--key-file``, written by ``python -m bestofn_swarm.plumbing.run_keys``). Without either it runs
unauthenticated, as every process did before run keys, and says so.

A key file, or the variable, is one JSON object::

    {"v": 1, "run": "<run id>", "secret": "<64 hex digits>"}               (infrastructure)
    {"v": 1, "run": "<run id>", "keys": {"robot/3": "<64 hex digits>"}}    (a robot)

A process hosting robots 3 to 7 holds their keys and that of its host identity
``host/3-7``, which seals the batches it exchanges with the world (bestofn_swarm/wire/batch.py).
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

from bestofn_swarm.plumbing import cliargs
from bestofn_swarm.plumbing.bounded_read import KEY_FILE_BYTES, read_bounded_text
from bestofn_swarm.plumbing.private_files import make_private_folder, write_private
from bestofn_swarm.wire import auth, names

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
        text = read_key_text(Path(key_file))
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


def read_key_text(path: Path) -> str:
    """The text of a key file, read no further than ``KEY_FILE_BYTES``; ValueError if it
    cannot be read, and a warning if other users may read it."""
    text = read_bounded_text(path, KEY_FILE_BYTES, "key file")
    try:
        mode = path.stat().st_mode
    except OSError as error:
        raise ValueError(f"cannot read key file {path}: {error.strerror}") from None
    if stat.S_ISREG(mode) and mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("key file %s can be read by other users (chmod 600 it)", path)
    return text


def read_key_file(path: Path, identity: str) -> tuple[str, auth.Keyring]:
    """The run a key file is for, and the keyring of ``identity`` alone in it (a robot
    outside the emulator: ``robot-agent --link``); ValueError says what is wrong."""
    text = read_key_text(path)
    try:
        run, keyring = auth.keyring_from_text(text)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    if not keyring.holds(identity):
        raise ValueError(f"{path} holds no key for {identity}")
    return run, keyring.only([identity])


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
    write_private(path, to_text(keyring, run) + "\n")


# --- command line: key files for processes started by hand -------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m bestofn_swarm.plumbing.run_keys",
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
    parser.add_argument(
        "--robots-per-process",
        type=cliargs.int_range(2, names.MAX_ROBOTS),
        default=None,
        metavar="K",
        help="also write host-<first>-<last>.json for processes of K robots each (0 to K-1, "
        "K to 2K-1, ...): the keys of its robots and of its host identity",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Exit code 0; 2 (one line) if ``--out`` is not a folder that can be written, or
    already holds a run's keys."""
    args = build_parser().parse_args(argv)
    out: Path = args.out
    if (out / "secret.json").exists():
        print(f"run_keys: error: {out / 'secret.json'} exists; not replacing it", file=sys.stderr)
        return 2
    keyring = auth.Keyring(secret=new_secret())
    hosts = 0
    try:
        make_private_folder(out)
        out.chmod(0o700)  # a folder of keys: private even if it was there
        write(out / "secret.json", keyring, args.run_id)
        for robot in range(args.robots):
            robot_keys = keyring.only([names.robot_identity(robot)])
            write(out / f"robot-{robot}.json", robot_keys, args.run_id)
        if args.robots_per_process is not None:
            for first in range(0, args.robots, args.robots_per_process):
                last = min(first + args.robots_per_process, args.robots) - 1
                identities = [names.robot_identity(robot) for robot in range(first, last + 1)]
                host_keys = keyring.only([*identities, names.host_identity(first, last)])
                write(out / f"host-{first}-{last}.json", host_keys, args.run_id)
                hosts += 1
    except OSError as error:
        where = error.filename or out
        print(f"run_keys: error: cannot write {where}: {error.strerror or error}", file=sys.stderr)
        return 2
    print(
        f"wrote secret.json, {args.robots} robot key file(s) and {hosts} host key file(s) in {out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
