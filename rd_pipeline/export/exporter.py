"""Turn a training checkpoint into the two files that go to the robot.

`policy.pt` is rsl-rl's own TorchScript export of the actor (observation normalizer, MLP, mean
action): observation in, action out. `policy.json` (see `policy_spec`) carries what the numbers mean.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.actions import ActionConfig, joint_semantics
from rd_pipeline.env.mdp.observations import actor_terms, layout_json
from rd_pipeline.policy_spec import FORMAT_VERSION, PolicySpec
from rd_pipeline.robots import Robot


def load_actor(checkpoint: Path, observation_size: int, num_actions: int, hidden_dims: list[int]) -> MLPModel:
    """The training actor (rsl-rl `MLPModel`) with the checkpoint's weights, in eval mode."""
    obs = TensorDict({"policy": torch.zeros(1, observation_size)}, batch_size=[1])
    actor = MLPModel(
        obs,
        {"actor": ["policy"]},
        "actor",
        num_actions,
        hidden_dims,
        "relu",
        obs_normalization=True,
        distribution_cfg={"class_name": "GaussianDistribution", "init_std": 1.0},
    )
    state = torch.load(checkpoint, weights_only=False, map_location="cpu")["algorithm"]["actor_state_dict"]
    actor.load_state_dict(state, strict=True)
    return actor.eval()


def _joints_block(robot: Robot, policy: list[str]) -> dict[str, Any]:
    """The actuated and policy joints with their gains, limits and default pose."""
    config = robot.config
    lower, upper = robot.joint_range[config.policy_indices].T
    floats = lambda values: [float(v) for v in values]
    return {
        "actuated": list(config.joint_names),
        "policy": policy,
        "kp": floats(config.kp),
        "kd": floats(config.kd),
        "effort_limit": floats(config.effort_limit),
        "default_pos": floats(config.default_pos),
        "policy_lower": floats(lower),
        "policy_upper": floats(upper),
    }


def _action_block(actions: ActionConfig, semantics: tuple[str, ...], outputs: list[str]) -> dict[str, Any]:
    """How the policy's outputs become joint targets."""
    return {
        "mode": actions.mode,
        "scale": float(actions.scale),
        "clip": float(actions.clip),
        "residual_mask": [i for i, kind in enumerate(semantics) if kind == "residual"],
        "outputs": outputs,
        "semantics": list(semantics),
        "formula": "per policy joint: base = the reference at the next control step where semantics is "
        "'residual' or 'reference', default_pos where it is 'absolute'; targets[outputs] += "
        "scale * clip(action, -clip, clip); targets projected to [policy_lower, policy_upper]; "
        "actuated joints outside the policy hold default_pos",
    }


def script_actor(actor: MLPModel) -> torch.jit.ScriptModule:
    """TorchScript of the deterministic actor: (B, observation_size) -> (B, num_actions)."""
    return torch.jit.script(actor.as_jit().cpu().eval())


def build_policy_spec(
    robot: Robot,
    env: EnvConfig,
    num_actions: int,
    reference_stage: str,
    reference_key: str,
    clip_frames: tuple[int, int],
) -> PolicySpec:
    """`policy.json` from the robot config and the training run's environment config."""
    config = robot.config
    policy = [config.joint_names[i] for i in config.policy_indices]
    semantics = joint_semantics(config, env.actions.mode)
    outputs = [joint for joint, kind in zip(policy, semantics) if kind != "reference"]
    if len(outputs) != num_actions:
        raise ValueError(f"the checkpoint's actor has {num_actions} outputs, the action mode implies {len(outputs)}")
    terms = actor_terms(len(policy), num_actions, env.observations)
    return PolicySpec(
        {
            "format_version": FORMAT_VERSION,
            "robot": config.name,
            "mjcf": config.mjcf,
            "joints": _joints_block(robot, policy),
            "action": _action_block(env.actions, semantics, outputs),
            "observation": layout_json(terms, int(env.history), env.observations.ref_future_steps),
            "rates": {
                "control_hz": 1.0 / (env.physics_dt * env.decimation),
                "physics_hz": 1.0 / env.physics_dt,
            },
            "reference": {
                "stage": reference_stage,
                "key": reference_key,
                "start_frame": int(clip_frames[0]),
                "end_frame": int(clip_frames[1]),
            },
        }
    )
