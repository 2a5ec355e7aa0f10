"""``python -m world_server.bridge``: the bridge to robots outside the emulator."""

import sys

from world_server.bridge.cli import main

sys.exit(main())
