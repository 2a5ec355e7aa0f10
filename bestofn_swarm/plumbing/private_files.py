"""Files and folders only their owner can read: recordings, logs, traces, run keys,
certificates' private keys. Every file the code writes at a user's path goes through here.

A file is created mode 0600 (never readable by others, not even for a moment) and set to
0600 if it was there already: truncating a file keeps its old mode, and a recording or key
written over a world-readable file must not stay world-readable. A folder the code creates
is 0700; a folder that was already there is left as its owner made it (what is written
into it is private anyway).
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import IO, Literal, overload

FILE_MODE = 0o600
FOLDER_MODE = 0o700

_FLAGS = {
    "w": os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
    "a": os.O_WRONLY | os.O_CREAT | os.O_APPEND,
    "x": os.O_WRONLY | os.O_CREAT | os.O_EXCL,
}


@overload
def open_private(
    path: str | Path, mode: Literal["wb", "ab", "xb"], buffering: int = -1
) -> IO[bytes]: ...


@overload
def open_private(
    path: str | Path,
    mode: Literal["w", "a", "x"],
    buffering: int = -1,
    newline: str | None = None,
) -> IO[str]: ...


def open_private(
    path: str | Path, mode: str, buffering: int = -1, newline: str | None = None
) -> IO[bytes] | IO[str]:
    """``open(path, mode)`` for writing (``w``, ``a`` or ``x``; text, in UTF-8, or ``b``),
    the file readable by its owner only. OSError as ``open`` raises it."""
    flags = _FLAGS[mode[0]] | getattr(os, "O_CLOEXEC", 0)
    descriptor = os.open(path, flags, FILE_MODE)
    try:
        os.fchmod(descriptor, FILE_MODE)  # a file that was there keeps its mode otherwise
        if "b" in mode:
            return os.fdopen(descriptor, mode, buffering)
        return os.fdopen(descriptor, mode, buffering, encoding="utf-8", newline=newline)
    except BaseException:
        os.close(descriptor)
        raise


def write_private(path: str | Path, data: bytes | str) -> None:
    """Write ``data`` to ``path`` (replacing what was there), readable by its owner only."""
    if isinstance(data, bytes):
        with open_private(path, "wb") as binary:
            binary.write(data)
    else:
        with open_private(path, "w") as text:
            text.write(data)


def make_private_folder(path: str | Path) -> Path:
    """``path`` and its missing parents, each created mode 0700 (``mkdir -p``); folders
    that were there are left as they are. OSError if it cannot be made (or is a file)."""
    folder = Path(path)
    missing = []
    for candidate in (folder, *folder.parents):
        if candidate.exists():
            break
        missing.append(candidate)
    for created in reversed(missing):
        try:
            created.mkdir(FOLDER_MODE)
        except FileExistsError:  # made meanwhile by someone else: theirs
            continue
        created.chmod(FOLDER_MODE)  # mkdir's mode passes through the umask
    if not folder.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "not a folder", str(folder))
    return folder
