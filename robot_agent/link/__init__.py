"""The robot's end of the link to the run's bridge: ``robot-agent --link`` (``program.py``,
``python -m robot_agent.link``), a robot outside the emulator over UDP or a serial line. No
Zenoh: it runs on the robot. Its pure part is ``robot_agent/core/link_robot.py``."""
