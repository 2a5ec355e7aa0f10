"""``python -m nest_beacon``: the nest beacon process (``nest-beacon``)."""

import sys

from nest_beacon.node.cli import main

sys.exit(main())
