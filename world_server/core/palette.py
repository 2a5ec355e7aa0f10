"""The colours every picture of a run shares: the recording's Foxglove scene, the live
and replay pages, the report's figures (a site's own colour is the camera's,
``camera.site_colour_bgr``)."""

from __future__ import annotations

Rgba = tuple[float, float, float, float]

# Robots not yet decided are coloured by phase; decided robots take their site's colour.
PHASE_COLOURS: dict[str, Rgba] = {
    "waiting": (0.6, 0.6, 0.6, 1.0),
    "to_site": (0.09, 0.75, 0.81, 1.0),
    "sensing": (0.58, 0.40, 0.74, 1.0),
    "to_nest": (1.0, 0.50, 0.05, 1.0),
    "at_nest": (0.17, 0.63, 0.17, 1.0),
    "lingering": (0.95, 0.85, 0.1, 1.0),
    "to_decision": (0.3, 0.3, 0.3, 1.0),
    "stopped": (0.3, 0.3, 0.3, 1.0),
}
UNKNOWN_PHASE_COLOUR: Rgba = (0.8, 0.8, 0.8, 1.0)
