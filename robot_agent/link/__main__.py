"""``python -m robot_agent.link``: one robot outside the emulator (``robot-agent --link``)."""

import sys

from robot_agent.link.program import main

sys.exit(main())
