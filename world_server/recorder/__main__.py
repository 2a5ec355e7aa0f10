"""``python -m world_server.recorder``: the recorder process."""

import sys

from world_server.recording.writer import main

sys.exit(main())
