"""How much a reference moves: the measure that tells dance from standing prelude.

A clip of a take can be mostly standing (the 10 s prelude of dance1_subject2 had a joint-speed
p95 under 1.2 rad/s); a policy that holds it has learned balance, not dance. These figures say
what a training clip contains and choose a take's window by how fast it moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rd_pipeline.motion.reference import ReferenceMotion


@dataclass(frozen=True)
class Window:
    """A window of a take, in whole seconds, and how fast its joints move."""

    start_s: int
    """First second of the window."""
    end_s: int
    """Second the window ends at (exclusive)."""
    joint_speed_p95: float
    """95th percentile of |joint velocity| over the window, rad/s."""

    @property
    def clip(self) -> str:
        """The window as `train.clip` takes it ("start:end" in seconds)."""
        return f"{self.start_s}:{self.end_s}"


def joint_speed_p95_per_second(reference: ReferenceMotion) -> list[float]:
    """The 95th percentile of |joint velocity| (rad/s) in each second of `reference`, the last,
    partial one included."""
    speeds = np.abs(reference.joint_vel)
    return [round(float(np.percentile(speeds[second], 95)), 2) for second in reference.seconds()]


def speed_windows(reference: ReferenceMotion, seconds: int) -> list[Window]:
    """Every `seconds`-long window on whole seconds, in order, with its joint-speed p95.

    The p95 over the window (not a mean of per-second figures) so that one violent second
    does not make a window of standing look busy."""
    frames_per_s = round(reference.fps)
    whole_seconds = reference.n_frames // frames_per_s
    if whole_seconds < seconds:
        raise ValueError(f"a {seconds} s window does not fit a {reference.duration_s:.1f} s reference")
    speeds = np.abs(reference.joint_vel)
    windows = []
    for start in range(whole_seconds - seconds + 1):
        frames = speeds[start * frames_per_s : (start + seconds) * frames_per_s]
        windows.append(Window(start, start + seconds, round(float(np.percentile(frames, 95)), 3)))
    return windows


def window_at_speed_quantile(reference: ReferenceMotion, seconds: int, quantile: float) -> Window:
    """The `seconds`-long window whose joint-speed p95 is nearest that `quantile` of all the take's
    windows (1: the busiest; 0.5: a typical stretch of the take), the earliest of ties."""
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"speed quantile {quantile:g} is outside [0, 1]")
    windows = speed_windows(reference, seconds)
    target = float(np.quantile([window.joint_speed_p95 for window in windows], quantile))
    return min(windows, key=lambda window: (abs(window.joint_speed_p95 - target), window.start_s))
