"""The link's I/O, without Zenoh: UDP and serial transports (``transport.py``), the loop both
ends share (``hub.py``), and ``robot-agent --link`` (``program.py``, ``python -m link``)."""
