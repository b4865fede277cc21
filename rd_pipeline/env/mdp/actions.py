"""Residual actions (paper, "Residual Action Learning" and appendix "Action dimension").

The policy outputs one value per policy joint (23 / 19 / 21 for G1 / H1 / H1-2). A residual mask
says which joints read their output as a residual on the reference, `q_ref(t+1) + scale * a`;
every other policy joint reads it as an absolute target around the default pose,
`q_default + scale * a`. The presets are the masks of the paper's Table r5, plus
`reference_locked`: only the selective joints have outputs and the rest follow the reference
exactly (an earlier reading of the paper, kept as an arm so the difference can be measured).
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatch
from typing import TYPE_CHECKING, Literal, get_args

import numpy as np

from rd_pipeline.lazy import lazy_import
from rd_pipeline.robots.config import RobotConfig

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")

ResidualPreset = Literal[
    "absolute",
    "selective",
    "hip_knee_ankle",
    "all_legs",
    "legs_torso",
    "all",
    "reference_locked",
]
RESIDUAL_PRESETS: tuple[str, ...] = get_args(ResidualPreset)

JointSemantics = Literal["residual", "absolute", "reference"]
"""How a policy joint's target is formed: residual on the reference, absolute around the default
pose, or the reference itself (no output)."""

_LEGS = ("*_hip_*", "*_knee_joint", "*_ankle*")
_PRESET_PATTERNS: dict[str, tuple[str, ...]] = {
    "absolute": (),
    "hip_knee_ankle": ("*_hip_pitch_joint", "*_knee_joint", "*_ankle*"),
    "all_legs": _LEGS,
    "legs_torso": (*_LEGS, "torso_joint", "waist_*"),
    "all": ("*",),
}
"""Joint-name patterns of each preset whose mask is not the robot's own (`selective` and
`reference_locked` use the config's `residual_indices`)."""


@dataclass(frozen=True)
class ActionConfig:
    """Paper, Table "Control, Initialization, and Termination Parameters"."""

    mode: ResidualPreset = "selective"
    """Residual mask preset: `selective` (the robot's hip and knee pitch, the paper's method),
    `absolute` (no residual joint, the ablation baseline), `hip_knee_ankle`, `all_legs`,
    `legs_torso`, `all` (Table r5), or `reference_locked`."""
    scale: float = 0.25
    """Action scale."""
    clip: float = 100.0
    """Actions are clipped to +-clip before scaling."""


def residual_mask(config: RobotConfig, preset: str) -> np.ndarray:
    """(P,) bool over the policy joints: which read their output as a residual."""
    if preset in ("selective", "reference_locked"):
        mask = np.zeros(len(config.policy_joints), dtype=bool)
        mask[list(config.residual_indices)] = True
        return mask
    return joints_matching(config.policy_joints, _PRESET_PATTERNS[preset])


def joints_matching(joints: tuple[str, ...], patterns: tuple[str, ...]) -> np.ndarray:
    """(J,) bool: which of `joints` match any of the glob `patterns`."""
    return np.array([any(fnmatch(joint, pattern) for pattern in patterns) for joint in joints], dtype=bool)


def joint_semantics(config: RobotConfig, preset: str) -> tuple[str, ...]:
    """Per policy joint, `residual`, `absolute` or `reference` under `preset`."""
    mask = residual_mask(config, preset)
    other = "reference" if preset == "reference_locked" else "absolute"
    return tuple("residual" if m else other for m in mask)


class ActionTargets:
    """The one formula from policy outputs to joint targets, used by training and by the deploy loop
    (`policy.json`'s `action.formula` says it in words): the base is the reference at the next
    control step on residual and reference joints and the default pose on absolute ones; the outputs
    add `scale * clip(action, -clip, clip)`; the targets stay inside the joint ranges."""

    def __init__(
        self,
        on_reference: torch.Tensor,
        outputs: torch.Tensor,
        default_pos: torch.Tensor,
        lower: torch.Tensor,
        upper: torch.Tensor,
        scale: float,
        clip: float,
    ) -> None:
        self.on_reference = on_reference
        self.outputs = outputs
        self.default_pos = default_pos
        self.lower = lower
        self.upper = upper
        self.scale = scale
        self.clip = clip

    def __call__(self, actions: torch.Tensor, reference_next: torch.Tensor) -> torch.Tensor:
        """(N, A) outputs and (N, P) reference joints of the next step -> (N, P) targets."""
        scaled = self.scale * actions.clamp(-self.clip, self.clip)
        default = self.default_pos.expand_as(reference_next)
        target = torch.where(self.on_reference, reference_next, default)
        target[:, self.outputs] += scaled.to(target.dtype)
        return torch.maximum(torch.minimum(target, self.upper), self.lower)


class ResidualActions:
    """Turns policy outputs (N, A) into joint position targets for the P policy joints."""

    def __init__(
        self,
        config: ActionConfig,
        semantics: tuple[str, ...],
        default_pos: torch.Tensor,
        lower: torch.Tensor,
        upper: torch.Tensor,
    ) -> None:
        self.config = config
        self.semantics = semantics
        self.outputs = torch.tensor([i for i, s in enumerate(semantics) if s != "reference"], dtype=torch.long)
        on_reference = torch.tensor([s != "absolute" for s in semantics]).to(default_pos.device)
        self.targets = ActionTargets(on_reference, self.outputs, default_pos, lower, upper, config.scale, config.clip)

    @property
    def size(self) -> int:
        """A, the policy's action dimension."""
        return len(self.outputs)
