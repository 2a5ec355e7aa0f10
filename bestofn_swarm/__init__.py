"""The shared layers of bestofn-swarm: the wire vocabulary every process speaks (``wire``),
what every Zenoh process shares (``plumbing``) and what both ends of a hardware link share
(``link``)."""

# Stale compiled cores would run old code: their source runs instead (one warning line).
from bestofn_swarm.plumbing import cores_state as _cores_state

_cores_state.use_source_if_stale()
