"""The env's default reward: DeepRacer's "follow the centre line" sample.

The bundled, documented sample reward functions live in ``agents``; this one is only
the default when a car is given none.
"""

from __future__ import annotations

from typing import Any


def follow_center_line(params: dict[str, Any]) -> float:
    """1.0 near the centre line, less further out, almost nothing off the track."""
    if not params["all_wheels_on_track"] or params["is_offtrack"]:
        return 1e-3
    width = params["track_width"]
    distance = params["distance_from_center"]
    if distance <= 0.1 * width:
        return 1.0
    if distance <= 0.25 * width:
        return 0.5
    if distance <= 0.5 * width:
        return 0.1
    return 1e-3
