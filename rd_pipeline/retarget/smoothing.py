"""Smooth corrections that never fall short of what a frame needs."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d


def smooth_cover(need: np.ndarray, fps: float, sigma_s: float) -> np.ndarray:
    """A smooth curve >= `need` everywhere: a max filter three sigmas wide, a Gaussian blur, then a max.

    Used for vertical corrections (lowering the body so legs reach, lifting it so feet stay above
    ground) that must hold at every frame without adding jerk.
    """
    if not need.any():
        return need
    sigma = sigma_s * fps
    widened = maximum_filter1d(need, size=int(6 * sigma) + 1)
    return np.maximum(gaussian_filter1d(widened, sigma), need)


def smoothstep(s: np.ndarray) -> np.ndarray:
    """Quintic ease on [0, 1] (zero velocity and acceleration at both ends), so blends add little jerk."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (s * (6.0 * s - 15.0) + 10.0)
