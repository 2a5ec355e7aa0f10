"""The link without I/O, as both ends use it: frames and bodies (``codec.py``), pacing and
rates (``pacing.py``) and the robot's session (``session.py``). The robot on it is
``robot_agent/core/link_robot.py``; the bridge's end is ``world_server/bridge/core/``."""
