"""``swarm run``: the plan of a run, its processes, following it to its end, and the
other ways a run starts (in process, ``swarm router``)."""
