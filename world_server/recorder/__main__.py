"""``python -m world_server.recorder``: the recorder process."""

import sys

from world_server.recorder.recorder_process import main

sys.exit(main())
