"""Shared process plumbing of the swarm's programs (world server, beacon, robots,
recorder, launcher): argument types and logging, Zenoh sessions, process lifetime,
finding the world. A port to a robot needs none of it: that lives in ``robot_agent``."""
