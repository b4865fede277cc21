"""Event terms: reference state initialization at reset and domain randomization (per-environment
models at startup, pushes and random force injection while stepping).

What is drawn once or rarely (the per-environment models, pushes) comes from a numpy generator on
the host; what is drawn at every reset or control step (the reset noise, the injected joint force)
comes from a torch generator on the training device, so nothing crosses between host and device
for it. Both draw in a fixed order: a seed gives the same run on the same device.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from rd_pipeline.env import quat
from rd_pipeline.env.config import EnvConfig, Randomization
from rd_pipeline.env.sim_model import randomized_copy

DR_PARAMS = ("mass", "friction", "kp", "kd", "com_x", "com_y", "com_z", "delay", "rfi_factor")
"""Per-environment randomization draws, in the order the critic observes them."""


def randomized_models(
    base: mujoco.MjModel, count: int, r: Randomization, root_body: int, rng: np.random.Generator
) -> tuple[list[mujoco.MjModel], np.ndarray]:
    """`count` models with link mass, friction, PD gains and pelvis COM drawn per environment, and
    the (count, len(DR_PARAMS)) draws."""
    params = np.zeros((count, len(DR_PARAMS)))
    models = []
    for i in range(count):
        if not r.enabled:
            params[i] = [1, 1, 1, 1, 0, 0, 0, 0, 1]
            models.append(copy.copy(base))
            continue
        mass = rng.uniform(*r.mass_factor)
        friction = rng.uniform(*r.friction_factor)
        kp = rng.uniform(*r.pd_factor)
        kd = rng.uniform(*r.pd_factor)
        com = rng.uniform(-r.com_offset_m, r.com_offset_m, size=3)
        delay = rng.integers(0, r.max_delay_steps + 1)
        rfi = rng.uniform(*r.torque_rfi_factor)
        params[i] = [mass, friction, kp, kd, *com, delay, rfi]
        models.append(randomized_copy(base, mass, friction, kp, kd, root_body, com))
    return models, params


def push_intervals(r: Randomization, count: int, step_dt: float, rng: np.random.Generator) -> np.ndarray:
    """Control steps until each of `count` environments is pushed next."""
    lo, hi = r.push_interval_s
    return np.round(rng.uniform(lo, hi, size=count) / step_dt).astype(np.int64)


def push_velocities(r: Randomization, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 2) horizontal velocity changes."""
    return rng.uniform(-r.push_max_speed, r.push_max_speed, (count, 2))


def random_joint_force_scale(r: Randomization, rfi_factor: np.ndarray, effort_limit: np.ndarray) -> np.ndarray:
    """(N, J) largest random joint force of each environment: `torque_rfi` x its factor x effort limit."""
    return r.torque_rfi * rfi_factor[:, None] * effort_limit


def random_joint_forces(scale: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """(N, J) random force injection, uniform in +-`scale`, redrawn every control step where
    `scale` lives (on a GPU nothing crosses from the host)."""
    unit = torch.rand(scale.shape, generator=generator, dtype=scale.dtype, device=scale.device)
    return scale * (2.0 * unit - 1.0)


@dataclass(frozen=True)
class ReferenceFrames:
    """The reference quantities reset draws from: (T, ...) tensors on the training device."""

    root_pos: torch.Tensor
    root_quat: torch.Tensor
    root_lin_vel: torch.Tensor
    root_ang_vel: torch.Tensor
    joint_pos: torch.Tensor
    joint_vel: torch.Tensor


def rsi_state(
    c: EnvConfig,
    ref: ReferenceFrames,
    frames: torch.Tensor,
    nq: int,
    nv: int,
    qpos_idx: torch.Tensor,
    dof_idx: torch.Tensor,
    joint_range: torch.Tensor,
    generator: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(k, nq), (k, nv) float64 states on the training device at reference `frames` with the
    appendix noise (reference state initialization), joint positions clipped to their range. The
    noise is drawn by `generator` on the device, so a reset reads nothing back and sends nothing."""
    k = len(frames)
    device = ref.root_pos.device
    frames = frames.to(device)
    joints = len(qpos_idx)
    normal = lambda *shape: torch.randn(*shape, generator=generator, dtype=torch.float64, device=device)
    uniform = lambda bound, *shape: bound * (2.0 * _unit(generator, device, *shape) - 1.0)
    qpos = torch.zeros(k, nq, dtype=torch.float64, device=device)
    qvel = torch.zeros(k, nv, dtype=torch.float64, device=device)
    # Draw order is part of the seed's meaning: root position, root rotation, joint positions,
    # root linear and angular velocity, joint velocities.
    root_noise = normal(k, 3) * c.rsi_root_pos_m
    root_noise[:, 2] = 0.0
    qpos[:, :3] = ref.root_pos[frames].double() + root_noise
    turn = normal(k, 3) * math.radians(c.rsi_root_rot_deg) / math.sqrt(3.0)
    qpos[:, 3:7] = quat.multiply(quat.from_rotation_vector(turn), ref.root_quat[frames].double())
    qpos[:, qpos_idx] = ref.joint_pos[frames].double() + uniform(c.rsi_joint_pos, k, joints)
    qvel[:, :3] = ref.root_lin_vel[frames].double() + normal(k, 3) * c.rsi_root_vel
    root_ang_vel = quat.rotate_inverse(qpos[:, 3:7].float(), ref.root_ang_vel[frames]).double()
    qvel[:, 3:6] = root_ang_vel + normal(k, 3) * c.rsi_root_vel
    qvel[:, dof_idx] = ref.joint_vel[frames].double() + uniform(c.rsi_joint_vel, k, joints)
    qpos[:, qpos_idx] = torch.clamp(qpos[:, qpos_idx], joint_range[:, 0], joint_range[:, 1])
    return qpos, qvel


def _unit(generator: torch.Generator, device: torch.device, *shape: int) -> torch.Tensor:
    return torch.rand(*shape, generator=generator, dtype=torch.float64, device=device)
