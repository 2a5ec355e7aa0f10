"""The in-process engine: every process of a lockstep run on an in-memory bus, in one
process (pure: no I/O; ``swarm run --engine inprocess`` is deploy/launcher/inprocess.py)."""
