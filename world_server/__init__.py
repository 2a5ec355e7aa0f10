"""The world server: physics, camera rendering, the radio medium and the clock."""

# Stale compiled cores would run old code: their source runs instead (one warning line).
from bestofn_swarm.plumbing import cores_state as _cores_state

_cores_state.use_source_if_stale()
