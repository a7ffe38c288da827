"""Axis limits for the panel's live plots (no imgui here, so the tests can check them).

implot's auto-fit stretches any spread to the full height: an energy that only carries float32
round-off (0.4533371 to 0.4533374 J) then swings from the bottom of the plot to the top, and 997
to 1000 awake bodies looks like a collapse.  ``axis_limits`` keeps the span at least a fraction of
the values' magnitude, so a change shows in proportion to the quantity it changes.
"""

from __future__ import annotations

import numpy as np

MIN_RELATIVE_SPAN = 0.05  # of max |value|: smaller ranges are drawn this tall, centred
MIN_ABSOLUTE_SPAN = 1e-6  # for series that sit at (or near) zero
PAD = 0.05  # margin above and below, of the span


def axis_limits(values, relative: float = MIN_RELATIVE_SPAN, absolute: float = MIN_ABSOLUTE_SPAN):
    """(lo, hi) for a y axis showing ``values`` (non-finite entries ignored; none: (0, 1))."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    magnitude = max(abs(lo), abs(hi))
    if magnitude == 0.0:  # all zeros: a plain 0..1 axis rather than one of +-1e-6
        return -PAD, 1.0 + PAD
    span = max(hi - lo, relative * magnitude, absolute)
    centre = 0.5 * (lo + hi)
    # keep non-negative series (times, counts, energy) from dipping below zero on the axis
    bottom = centre - 0.5 * span
    if lo >= 0.0 and bottom < 0.0:
        bottom = 0.0
    top = bottom + span
    return bottom - PAD * span, top + PAD * span
