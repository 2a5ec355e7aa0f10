"""Watching a run, without I/O: what each robot decided and when, the stall watchdog, how
the run ended and its summary. Every engine, report and view feeds the same code."""
