"""The link to a robot outside the emulator, what both of its ends share: the protocol in
``core`` (pure: no I/O, no clock, no Zenoh) and the transports and loop in ``io`` (no Zenoh
either: the robot's end runs on the robot)."""
