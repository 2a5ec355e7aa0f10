"""Preloaded by the robots' fork server (deploy/launcher/forking.py), and meant only for it: moves
the fork server, and so every robot it forks, out of the launcher's process group.

A Ctrl-C in the terminal, a closing terminal (SIGHUP) and ``timeout(1)`` signal the whole
foreground process group. Only the launcher should see that: it stops the robots itself,
in order, and finishes the recording. Had the robots got the signal too, they would be
gone before the launcher could read the world's last counters. Importing this module
anywhere else does nothing: it acts only in a process whose parent is the launcher that
asked for the fork server (``FORK_SERVER_OF``).
"""

from __future__ import annotations

import contextlib
import os

from deploy.launcher.forking import FORK_SERVER_OF


def leave_launchers_group() -> None:
    if os.environ.get(FORK_SERVER_OF) == str(os.getppid()) and os.getpgrp() != os.getpid():
        # On failure it stays in the launcher's group: signals reach the robots as before.
        with contextlib.suppress(OSError):
            os.setpgid(0, 0)


leave_launchers_group()
