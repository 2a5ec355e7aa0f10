"""Reading a file a user names (a key file, a Zenoh configuration, a certificate) with a
size limit: ``--key-file /dev/zero`` must fail at once with one line, not read until memory
runs out. Every such read goes through here; what fails is a ValueError whose message is
that one line (the caller makes it a usage error, exit code 2).
"""

from __future__ import annotations

from pathlib import Path

KEY_FILE_BYTES = 2**20  # a robot process's keys: about 100 bytes per robot it hosts
CONFIG_FILE_BYTES = 16 * 2**20  # a Zenoh configuration: a router's rules grow with the swarm
CERTIFICATE_BYTES = 2**20  # a PEM certificate or key: a few kilobytes


def read_bounded(path: str | Path, limit: int, what: str = "file") -> bytes:
    """The whole of the file at ``path``, ``what`` it is said to be; ValueError if it
    cannot be read or holds more than ``limit`` bytes (read no further than that: a device
    or a pipe may never end)."""
    try:
        with open(path, "rb") as stream:
            data = stream.read(limit + 1)
    except OSError as error:
        raise ValueError(f"cannot read {what} {path}: {error.strerror or error}") from None
    if len(data) > limit:
        raise ValueError(f"{what} {path} is too big (more than {limit} bytes)")
    return data


def read_bounded_text(path: str | Path, limit: int, what: str = "file") -> str:
    """``read_bounded`` as UTF-8 text; ValueError if it is not."""
    data = read_bounded(path, limit, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{what} {path} is not UTF-8 text") from None
