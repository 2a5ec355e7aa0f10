"""The bridge's end of the robots' links, without I/O: sessions (peer.py) and impairment."""
