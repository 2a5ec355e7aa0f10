"""``python -m world_server.server``: the world server process (``world-server``)."""

import sys

from world_server.server.cli import main

sys.exit(main())
