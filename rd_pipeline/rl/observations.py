"""The actor's observation layout: which terms, in which order, at which scale.

The training environment builds its actor frames from this layout and the export writes it into
`policy.json`, so a deploy loop can rebuild the same vector from raw simulator state without the
training code.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class ObservationTerm:
    """One block of an actor frame."""

    name: str
    """What the block holds (see `actor_terms`)."""
    size: int
    """Number of values."""
    scale: float
    """Multiplier applied to the raw quantity."""


JOINT_VEL_SCALE = 0.05
ANG_VEL_SCALE = 0.25


def actor_terms(num_joints: int, num_actions: int) -> tuple[ObservationTerm, ...]:
    """One actor frame, oldest history frame first in the stacked vector:

    - `joint_pos`: policy-joint positions minus the default pose (rad);
    - `joint_vel`: policy-joint velocities (rad/s);
    - `projected_gravity`: the unit gravity vector in the pelvis frame;
    - `base_ang_vel`: pelvis angular velocity in the pelvis frame (rad/s);
    - `last_action`: the previous policy output (before clipping and scaling);
    - `ref_joint_pos_next`: the reference's policy-joint positions at the next control step (rad).
    """
    return (
        ObservationTerm("joint_pos", num_joints, 1.0),
        ObservationTerm("joint_vel", num_joints, JOINT_VEL_SCALE),
        ObservationTerm("projected_gravity", 3, 1.0),
        ObservationTerm("base_ang_vel", 3, ANG_VEL_SCALE),
        ObservationTerm("last_action", num_actions, 1.0),
        ObservationTerm("ref_joint_pos_next", num_joints, 1.0),
    )


def layout_json(terms: tuple[ObservationTerm, ...], history: int) -> dict:
    """The `observation` block of `policy.json`."""
    frame = sum(t.size for t in terms)
    return {"history": history, "frame_size": frame, "size": frame * history, "order": "oldest_first",
            "terms": [asdict(t) for t in terms]}
