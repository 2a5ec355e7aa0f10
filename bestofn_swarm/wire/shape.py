"""The shape of a run, said once: how many robots and sites, its seed, and how much sim
time it may take. Every command and process that takes them uses these bounds and defaults
(their options are made from here: ``bestofn_swarm/plumbing/cliargs.py``)."""

from __future__ import annotations

from typing import Annotated

from msgspec import Meta

from bestofn_swarm.wire import protocol

# Robots one run may have: the largest swarm measured here (docs/scale.md), and what one
# batch of senses or acts may carry (bestofn_swarm/wire/batch.py).
MAX_SWARM = 1000
MAX_SEED = protocol.MAX_SEED

Robots = Annotated[int, Meta(ge=1, le=MAX_SWARM)]
Sites = Annotated[int, Meta(ge=2, le=protocol.MAX_OPTIONS)]
Seed = protocol.Seed

DEFAULT_ROBOTS = 10
DEFAULT_SITES = 10  # the paper's largest n in Section 5
DEFAULT_SEED = 0
DEFAULT_TIMEOUT = 1800.0  # sim seconds before a run ends as timeout
