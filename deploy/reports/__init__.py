"""What is made of runs: ``swarm report`` (recordings to figures and tables), ``swarm
section5`` and ``swarm wellstirred``."""
