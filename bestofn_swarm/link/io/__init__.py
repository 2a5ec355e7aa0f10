"""The link's I/O, without Zenoh: UDP and serial transports (``transport.py``) and the loop
both ends share (``hub.py``)."""
