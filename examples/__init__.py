"""Examples: a robot and a beacon on a shared Wi-Fi over UDP multicast (``udp_robot.py``,
``udp_beacon.py``, their radio ``udp_radio.py``). Run them as scripts
(``python examples/udp_robot.py ...``) or as modules (``python -m examples.udp_robot ...``)."""
