"""Colour: linear RGB with Rec. 709 / sRGB primaries throughout."""

from __future__ import annotations

import numpy as np

__all__ = ["LUMINANCE_WEIGHTS", "luminance"]

#: Rec. 709 luminance weights; they sum to 1, so a grey value's luminance is the value itself.
LUMINANCE_WEIGHTS = np.array([0.212671, 0.715160, 0.072169])


def luminance(rgb) -> np.ndarray:
    """Luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS
