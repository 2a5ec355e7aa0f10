"""``robot-agent``: a robot on Zenoh (``robot_agent/node``), or with ``--link`` a robot
outside the emulator over a link to the run's bridge (``robot_agent/link/``).

The link program is chosen before anything else is imported: it runs where there is no
Zenoh (a Raspberry Pi robot, a test bench), and must not need it. The choice is made here,
above both: the link imports the robot's core, so the robot's package may not import the
link.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    if any(argument == "--link" or argument.startswith("--link=") for argument in arguments):
        from robot_agent.link.program import main as link_main

        return link_main(arguments)
    from robot_agent.node.cli import main as node_main

    return node_main(arguments)


if __name__ == "__main__":
    sys.exit(main())
