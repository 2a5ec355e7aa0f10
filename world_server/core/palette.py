"""The colours every picture of a run shares: the recording's Foxglove scene, the live
and replay pages, the report's figures. (What a robot's camera sees is another thing: a
site's panel in the camera's colour, red share = quality, ``camera.site_colour_bgr``.)

Each site has a categorical colour a person can tell apart from its neighbours', also
with a colour-vision deficiency: Okabe and Ito's eight for up to eight sites, Matplotlib's
tab10 for nine or ten, tab20 for up to twenty, hues around the circle beyond (not safe
then; a site's id is in every label). A site's quality is shown beside its colour (its ρ
in the label), never by it.
"""

from __future__ import annotations

import colorsys

Rgba = tuple[float, float, float, float]


def _hex(text: str) -> Rgba:
    return (int(text[1:3], 16) / 255, int(text[3:5], 16) / 255, int(text[5:7], 16) / 255, 1.0)


# Okabe & Ito (2008), "Color Universal Design": orange, sky blue, bluish green, yellow,
# blue, vermillion, reddish purple, and grey in place of their black (robots are outlined
# in black).
OKABE_ITO = tuple(
    _hex(text)
    for text in (
        "#E69F00",
        "#56B4E9",
        "#009E73",
        "#F0E442",
        "#0072B2",
        "#D55E00",
        "#CC79A7",
        "#999999",
    )
)
TAB10 = tuple(
    _hex(text)
    for text in (
        "#1f77b4",
        "#ff7f0e",
        "#2ca02c",
        "#d62728",
        "#9467bd",
        "#8c564b",
        "#e377c2",
        "#7f7f7f",
        "#bcbd22",
        "#17becf",
    )
)
TAB20 = tuple(
    _hex(text)
    for text in (
        "#1f77b4",
        "#aec7e8",
        "#ff7f0e",
        "#ffbb78",
        "#2ca02c",
        "#98df8a",
        "#d62728",
        "#ff9896",
        "#9467bd",
        "#c5b0d5",
        "#8c564b",
        "#c49c94",
        "#e377c2",
        "#f7b6d2",
        "#7f7f7f",
        "#c7c7c7",
        "#bcbd22",
        "#dbdb8d",
        "#17becf",
        "#9edae5",
    )
)


def site_palette(sites: int) -> tuple[Rgba, ...]:
    """The colours of sites 0 to ``sites`` - 1, in order of their ids."""
    if sites <= len(OKABE_ITO):
        return OKABE_ITO[:sites]
    if sites <= len(TAB10):
        return TAB10[:sites]
    if sites <= len(TAB20):
        return TAB20[:sites]
    return tuple(
        (*colorsys.hsv_to_rgb(index / sites, 0.75 if index % 2 else 0.55, 0.85), 1.0)
        for index in range(sites)
    )


def site_colour(site: int, sites: int, alpha: float = 1.0) -> Rgba:
    """Site ``site``'s colour in a run of ``sites`` sites."""
    red, green, blue, _ = site_palette(sites)[site]
    return (red, green, blue, alpha)


def hex_colour(rgba: Rgba) -> str:
    red, green, blue, _ = rgba
    return f"#{round(255 * red):02x}{round(255 * green):02x}{round(255 * blue):02x}"


# Robots not yet decided are coloured by phase; decided robots take their site's colour.
# Each phase has a swatch of its own: the decided ones are dark greys apart from the
# waiting one's light grey.
PHASE_COLOURS: dict[str, Rgba] = {
    "waiting": (0.72, 0.72, 0.72, 1.0),
    "to_site": (0.09, 0.75, 0.81, 1.0),
    "sensing": (0.58, 0.40, 0.74, 1.0),
    "to_nest": (1.0, 0.50, 0.05, 1.0),
    "at_nest": (0.17, 0.63, 0.17, 1.0),
    "lingering": (0.95, 0.85, 0.1, 1.0),
    "to_decision": (0.42, 0.42, 0.42, 1.0),
    "stopped": (0.12, 0.12, 0.12, 1.0),
}
UNKNOWN_PHASE_COLOUR: Rgba = (0.86, 0.86, 0.86, 1.0)
