"""What a run decided and when a run ends, and the tables made of runs (pure: no I/O)."""
