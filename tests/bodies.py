"""The e-puck's navigator parameters, as a robot gets them from the world's WorldInfo."""

from __future__ import annotations

from typing import Any

from robot_agent.core.navigation import NavParams
from world_server.core.body import EPUCK


def epuck_nav_params(**overrides: Any) -> NavParams:
    """``NavParams`` for the e-puck body of world_server/core/body.py (``overrides`` win)."""
    body: dict[str, Any] = {
        "max_speed": EPUCK.max_wheel_speed,
        "wheel_base": EPUCK.wheel_base,
        "robot_radius": EPUCK.radius,
    }
    return NavParams(**(body | overrides))
