"""Process lifetime: a child of ``swarm run`` dies with it, even on SIGKILL.

The launcher sets ``BESTOFN_PARENT_PID``; each process asks Linux for a SIGTERM when its
parent dies (prctl PR_SET_PDEATHSIG), then checks the parent is still the launcher, in
case it died before the request. Doing this in the child avoids ``preexec_fn``, which is
unsafe in a launcher that runs threads.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

PARENT_ENV = "BESTOFN_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def die_with_launcher() -> None:
    parent = os.environ.get(PARENT_ENV)
    if not parent or not parent.isdigit():
        return
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != int(parent):
        os.kill(os.getpid(), signal.SIGTERM)
