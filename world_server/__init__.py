"""The world server: physics, camera rendering, the radio medium and the clock."""
