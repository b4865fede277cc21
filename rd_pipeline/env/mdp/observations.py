"""The actor's observation layout: which terms, in which order, at which scale.

The training environment builds its actor frames from this layout and the export writes it into
`policy.json`, so a deploy loop can rebuild the same vector from raw simulator state without the
training code.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from rd_pipeline.env.quat import projected_gravity, rotate_inverse
from rd_pipeline.lazy import lazy_import
from rd_pipeline.params import ParamRangeError

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


@dataclass(frozen=True)
class ObservationTerm:
    """One block of an actor frame."""

    name: str
    """What the block holds (see `actor_terms`)."""
    size: int
    """Number of values."""
    scale: float
    """Multiplier applied to the raw quantity."""


@dataclass(frozen=True)
class ObservationsConfig:
    """Scales of the actor's observation terms (the raw quantity is multiplied by its scale)."""

    joint_pos: float = 1.0
    """Policy-joint positions minus the default pose (rad)."""
    joint_vel: float = 0.05
    """Policy-joint velocities (rad/s)."""
    projected_gravity: float = 1.0
    """The unit gravity vector in the pelvis frame."""
    base_ang_vel: float = 0.25
    """Pelvis angular velocity in the pelvis frame (rad/s)."""
    last_action: float = 1.0
    """The previous policy output (before clipping and scaling)."""
    ref_joint_pos_next: float = 1.0
    """The reference's policy-joint positions at the next control step (rad)."""
    ref_joint_pos_future: float = 1.0
    """The reference's policy-joint positions `ref_future_steps` control steps ahead (rad)."""
    ref_future_steps: tuple[int, ...] = ()
    """Control steps ahead whose reference joint positions the actor sees besides the next one
    (empty: the paper's actor, the next step only; at 50 Hz, 5 and 25 are 0.1 and 0.5 s), so it can
    prepare for a fast move. Past the reference's end, its last frame."""

    def __post_init__(self) -> None:
        if any(step < 1 for step in self.ref_future_steps):
            raise ParamRangeError(
                "ref_future_steps", f"must be control steps of 1 or more, got {self.ref_future_steps}"
            )


@dataclass(frozen=True)
class ActorInputs:
    """Raw quantities the actor terms read (batched, policy-joint order)."""

    joint_pos: torch.Tensor
    """(N, P) joint positions."""
    joint_vel: torch.Tensor
    """(N, P) joint velocities."""
    root_quat: torch.Tensor
    """(N, 4) pelvis orientation, wxyz."""
    base_ang_vel: torch.Tensor
    """(N, 3) pelvis angular velocity, pelvis frame."""
    last_action: torch.Tensor
    """(N, A) previous action."""
    ref_joint_pos_next: torch.Tensor
    """(N, P) reference joint positions at the next control step."""
    ref_joint_pos_future: torch.Tensor
    """(N, K * P) reference joint positions at each of the K `ref_future_steps`, nearest first."""
    default_pos: torch.Tensor
    """(P,) default pose."""


def joint_pos(x: ActorInputs) -> torch.Tensor:
    return x.joint_pos - x.default_pos


def joint_vel(x: ActorInputs) -> torch.Tensor:
    return x.joint_vel


def gravity(x: ActorInputs) -> torch.Tensor:
    return projected_gravity(x.root_quat)


def base_ang_vel(x: ActorInputs) -> torch.Tensor:
    return x.base_ang_vel


def last_action(x: ActorInputs) -> torch.Tensor:
    return x.last_action


def ref_joint_pos_next(x: ActorInputs) -> torch.Tensor:
    return x.ref_joint_pos_next


def ref_joint_pos_future(x: ActorInputs) -> torch.Tensor:
    return x.ref_joint_pos_future


ACTOR_TERMS: dict[str, Callable[[ActorInputs], torch.Tensor]] = {
    "joint_pos": joint_pos,
    "joint_vel": joint_vel,
    "projected_gravity": gravity,
    "base_ang_vel": base_ang_vel,
    "last_action": last_action,
    "ref_joint_pos_next": ref_joint_pos_next,
    "ref_joint_pos_future": ref_joint_pos_future,
}
"""Term name -> function, in the order of an actor frame."""


def actor_terms(num_joints: int, num_actions: int, cfg: ObservationsConfig) -> tuple[ObservationTerm, ...]:
    """One actor frame's layout (oldest history frame first in the stacked vector)."""
    sizes = {
        "projected_gravity": 3,
        "base_ang_vel": 3,
        "last_action": num_actions,
        "ref_joint_pos_future": len(cfg.ref_future_steps) * num_joints,
    }
    terms = (ObservationTerm(name, sizes.get(name, num_joints), getattr(cfg, name)) for name in ACTOR_TERMS)
    # A term of no values is left out, so the paper's layout (and its policy.json) stays as it was.
    return tuple(term for term in terms if term.size)


def actor_frame(terms: tuple[ObservationTerm, ...], inputs: ActorInputs) -> torch.Tensor:
    """(N, frame_size): every term's scaled value, concatenated in layout order."""
    return torch.cat([term.scale * ACTOR_TERMS[term.name](inputs) for term in terms], dim=-1)


@dataclass(frozen=True)
class CriticInputs:
    """Raw quantities the critic terms read: the actor's newest frame plus privileged state."""

    actor_frame: torch.Tensor
    """(N, frame_size) the newest actor frame."""
    base_lin_vel: torch.Tensor
    """(N, 3) pelvis linear velocity, pelvis frame."""
    ref_root_quat: torch.Tensor
    """(N, 4) the reference root orientation at the current frame, wxyz."""
    ref_body_pos: torch.Tensor
    """(N, B, 3) the reference's tracked body positions at the current frame (world)."""
    root: int
    """Index of the root among the tracked bodies."""
    dr_params: torch.Tensor
    """(N, 9) each environment's domain-randomization draw."""


def ref_body_pos_rel(x: CriticInputs) -> torch.Tensor:
    """The reference's tracked bodies relative to its root, in the root's frame, flattened."""
    relative = x.ref_body_pos - x.ref_body_pos[:, x.root : x.root + 1]
    return rotate_inverse(x.ref_root_quat[:, None], relative).flatten(1)


CRITIC_TERMS: dict[str, Callable[[CriticInputs], torch.Tensor]] = {
    "actor_frame": lambda x: x.actor_frame,
    "base_lin_vel": lambda x: x.base_lin_vel,
    "ref_body_pos_rel": ref_body_pos_rel,
    "dr_params": lambda x: x.dr_params,
}
"""Term name -> function, in the order of the critic's observation."""


def critic_observation(inputs: CriticInputs) -> torch.Tensor:
    """(N, critic_size): every critic term, concatenated in order."""
    return torch.cat([term(inputs) for term in CRITIC_TERMS.values()], dim=-1)


def layout_json(terms: tuple[ObservationTerm, ...], history: int, future_steps: tuple[int, ...]) -> dict:
    """The `observation` block of `policy.json` (`ref_future_steps` only where the actor sees any)."""
    frame = sum(t.size for t in terms)
    layout = {
        "history": history,
        "frame_size": frame,
        "size": frame * history,
        "order": "oldest_first",
        "terms": [asdict(t) for t in terms],
    }
    if future_steps:
        layout["ref_future_steps"] = list(future_steps)
    return layout
