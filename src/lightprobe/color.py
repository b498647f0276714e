"""Colour: linear RGB with Rec. 709 / sRGB primaries throughout."""

from __future__ import annotations

import numpy as np

__all__ = ["LUMINANCE_WEIGHTS", "linear_to_srgb", "luminance", "srgb_to_linear"]

#: Rec. 709 luminance weights; they sum to 1, so a grey value's luminance is the value itself.
LUMINANCE_WEIGHTS = np.array([0.212671, 0.715160, 0.072169])


def luminance(rgb) -> np.ndarray:
    """Luminance of linear RGB (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1) on values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Its inverse: sRGB-encoded values (clipped to [0, 1]) to linear ones."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))
