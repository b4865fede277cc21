"""Floor contacts of the human's knees, elbows, hands, pelvis and torso, and targets that hold the
matching robot bodies still while they rest, not while they slide (the feet have their own
planting in `targets`)."""

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


def hold_in_contact(
    path: np.ndarray, contact: np.ndarray, human: np.ndarray, fps: float, settings: BodyContactConfig
) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) a target path that stands still (horizontally) while each contact run rests, and the
    (T,) frames it is held.

    The body stays where the run began until the `human` joint (scaled like the targets) has slid
    `settings.hold_drift_m` from where it was then (crawling on the belly, sliding on the back):
    from there on the run is not a rest, and the target follows its path. After a hold, the offset
    to the free path fades out over `settings.release_s` with a smooth ease, so letting go adds no
    jump.
    """
    held = path.copy()
    holding = np.zeros(contact.shape, dtype=bool)
    release = max(1, int(round(settings.release_s * fps)))
    n_frames = path.shape[0]
    for start, end in contact_runs(contact):
        slid = np.linalg.norm(human[start:end, :2] - human[start, :2], axis=-1) > settings.hold_drift_m
        if slid.any():
            end = start + int(np.argmax(slid))
        anchor = held[start, :2].copy()  # includes the fade of a run that ended just before
        held[start:end, :2] = anchor
        holding[start:end] = True
        offset = anchor - path[end - 1, :2]
        after = np.arange(end, min(end + release, n_frames))
        fade = 1.0 - smoothstep((after - end + 1) / release)
        held[after, :2] = path[after, :2] + fade[:, None] * offset
    return held, holding
