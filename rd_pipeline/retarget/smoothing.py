"""Smooth corrections that never fall short of what a frame needs, and blends of two trajectories."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d


def smooth_cover(need: np.ndarray, fps: float, sigma_s: float) -> np.ndarray:
    """A smooth curve >= `need` everywhere: a max filter three sigmas either side, a Gaussian blur, then a max.

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


def blend_configurations(base: np.ndarray, other: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per frame, `weight` (T,) of `other` and the rest of `base`, both (T, nq) free-base configurations;
    the root quaternions are blended in the same hemisphere and normalized."""
    w = weight[:, None]
    same_side = np.sum(other[:, 3:7] * base[:, 3:7], axis=1, keepdims=True) >= 0.0
    quat_other = np.where(same_side, other[:, 3:7], -other[:, 3:7])
    out = (1.0 - w) * base + w * other
    quat = (1.0 - w) * base[:, 3:7] + w * quat_other
    out[:, 3:7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    return out


def resample_configurations(qpos: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Free-base configurations (T, nq) sampled at `fps`, read at `times` (s, within the clip):
    positions and joints linearly, the root quaternion by the same blend in its hemisphere,
    normalized. Linear reading never raises a frame-to-frame speed above the fastest step of
    `qpos`, so the velocity limits it kept still hold."""
    position = np.clip(times * fps, 0.0, len(qpos) - 1)
    before = np.minimum(np.floor(position).astype(int), len(qpos) - 1)
    after = np.minimum(before + 1, len(qpos) - 1)
    return blend_configurations(qpos[before], qpos[after], position - before)
