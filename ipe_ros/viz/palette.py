"""Colours shared by the RViz markers and the rerun logs (no ROS, no rerun here).

Groups travel as names ("red", "yellow"); a marker's colour becomes its group only through
:func:`nearest_group_name`, so the Exp. 5 red/yellow convention works with plain coloured cubes.
"""

from __future__ import annotations

import math

#: Named group colours, RGB in [0, 1]. The first two are the paper's Exp. 5 block colours.
GROUP_RGB: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.15, 0.15),
    "yellow": (0.95, 0.85, 0.15),
    "green": (0.2, 0.7, 0.25),
    "blue": (0.2, 0.35, 0.85),
    "orange": (0.95, 0.55, 0.1),
    "purple": (0.55, 0.25, 0.7),
    "white": (0.95, 0.95, 0.95),
    "gray": (0.5, 0.5, 0.5),
    "black": (0.1, 0.1, 0.1),
    "heavy": (0.35, 0.3, 0.3),   # paper Exps. 3-4: dark blocks are heavy ...
    "light": (0.85, 0.8, 0.7),   # ... light ones pale
}
#: Colours that can be read back from a marker as a group (heavy/light are labels, not hues).
_HUES = ("red", "yellow", "green", "blue", "orange", "purple", "white", "gray", "black")
UNGROUPED_RGB = (0.75, 0.6, 0.4)  # wood
SUPPORT_RGB = (0.55, 0.55, 0.58)


def group_rgb(group: str) -> tuple[float, float, float]:
    """Display colour of a group (an unknown or empty group is drawn as wood)."""
    return GROUP_RGB.get(group.strip().lower(), UNGROUPED_RGB)


def nearest_group_name(r: float, g: float, b: float) -> str:
    """The named hue closest to an RGB colour in [0, 1] (Euclidean in RGB)."""
    return min(_HUES, key=lambda name: math.dist(GROUP_RGB[name], (r, g, b)))


def risk_rgb(probability: float) -> tuple[float, float, float]:
    """Green (0, stays) through yellow (0.5) to red (1, falls) for a fall probability."""
    p = min(1.0, max(0.0, float(probability)))
    if p <= 0.5:
        return (0.1 + 1.7 * p, 0.75, 0.15)
    return (0.95, 0.75 - 1.3 * (p - 0.5), 0.15)


def to_rgb8(rgb: tuple[float, float, float]) -> tuple[int, int, int]:
    return tuple(int(round(255 * min(1.0, max(0.0, c)))) for c in rgb)  # type: ignore[return-value]
