"""The link without I/O: frames and bodies (``codec.py``), pacing and rates (``pacing.py``),
the robot's session (``session.py``), the bridge's end of a session (``peer.py``), the
robot outside the emulator (``robot.py``) and a link made worse on purpose
(``impairment.py``)."""
