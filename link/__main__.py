"""``python -m link``: one robot outside the emulator (``robot-agent --link``)."""

import sys

from link.io.program import main

sys.exit(main())
