"""``python -m nest_beacon``: the nest beacon process (``nest-beacon``)."""

import sys

from nest_beacon.node.beacon_node import main

sys.exit(main())
