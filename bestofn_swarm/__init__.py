"""The shared layers of bestofn-swarm: the wire vocabulary every process speaks (``wire``),
what every Zenoh process shares (``plumbing``) and what both ends of a hardware link share
(``link``)."""
