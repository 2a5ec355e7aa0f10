"""``python -m robot_agent.node``: the robot process (``robot-agent``)."""

import sys

from robot_agent.node.cli import main

sys.exit(main())
