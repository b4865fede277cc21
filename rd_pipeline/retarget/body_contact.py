"""Floor contacts of the human's knees, elbows, hands, pelvis and torso, and targets that hold the
matching robot bodies still while they last (the feet have their own planting in `targets`)."""

from __future__ import annotations

import numpy as np

from rd_pipeline.motion.contact import contact_runs, label_contacts
from rd_pipeline.retarget.config import BodyContactConfig
from rd_pipeline.retarget.smoothing import smoothstep


def label_body_contacts(
    human_pos: np.ndarray,
    index: dict[str, int],
    joints: list[str],
    fps: float,
    settings: BodyContactConfig,
) -> np.ndarray:
    """(T, K) which of `joints` rest on the floor (z = 0 in LAFAN1), from each joint's height and speed.

    Joints named in `settings.trunk_joints` sit deeper inside the body than limb joints, so they
    touch the floor at a larger height. Joints in `settings.excluded_joints` never count.
    """
    contact = np.zeros((human_pos.shape[0], len(joints)), dtype=bool)
    for k, joint in enumerate(joints):
        if joint in settings.excluded_joints:
            continue
        thresholds = settings.trunk if joint in settings.trunk_joints else settings.limb
        contact[:, k] = label_contacts(human_pos[:, None, index[joint]], fps, 0.0, thresholds)[:, 0]
    return contact


def hold_in_contact(path: np.ndarray, contact: np.ndarray, fps: float, release_s: float) -> np.ndarray:
    """(T, 3) a target path that stands still (horizontally) through each contact run.

    The body stays where the run began; after the run, the offset to the free path fades out over
    `release_s` with a smooth ease, so leaving the floor adds no jump.
    """
    held = path.copy()
    release = max(1, int(round(release_s * fps)))
    n_frames = path.shape[0]
    for start, end in contact_runs(contact):
        anchor = held[start, :2].copy()  # includes the fade of a run that ended just before
        held[start:end, :2] = anchor
        offset = anchor - path[end - 1, :2]
        after = np.arange(end, min(end + release, n_frames))
        fade = 1.0 - smoothstep((after - end + 1) / release)
        held[after, :2] = path[after, :2] + fade[:, None] * offset
    return held
