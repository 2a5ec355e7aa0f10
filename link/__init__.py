"""The link to a robot outside the emulator: its codec, sessions and the robot itself in
``core`` (pure: no I/O, no clock, no Zenoh), and its transports, loop and the program
``robot-agent --link`` in ``io`` (no Zenoh either: it runs on the robot)."""
