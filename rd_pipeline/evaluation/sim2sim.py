"""Sim2sim rollouts of an exported policy (or the zero-action baseline) and their per-step errors.

Every rollout starts on the reference (no noise) at one start frame and runs the deploy loop until
it fails or reaches the end of the reference. Failure per SPEC: the pelvis gravity direction more
than `orientation_limit_rad` from the reference's, a termination body farther than `motion_far_m`
from its reference, or a body other than the feet touching the floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from rd_pipeline.evaluation.deploy import DeployController, Policy
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.policy_spec import PolicySpec
from rd_pipeline.rl.env_config import Randomization
from rd_pipeline.rl.physics import MujocoCpuBackend
from rd_pipeline.rl.sim_model import randomized_copy
from rd_pipeline.rl.terminations import bad_orientation, motion_far


@dataclass(frozen=True)
class BodySets:
    """Which bodies the metrics and failure checks look at (names in the MJCF and the reference)."""

    root: str
    tracked: tuple[str, ...]
    termination: tuple[str, ...]
    feet: tuple[str, ...]


@dataclass
class Rollout:
    """One rollout: how long it lasted and its per-step errors (one value per control step survived)."""

    start_frame: int
    steps: int
    completed: bool
    remaining_steps: int
    """Control steps from the start to the end of the reference (the most it could survive)."""
    errors: dict[str, np.ndarray]
    """`E_g_mpbpe`, `E_mpbpe` (mm), `E_mpjpe` (mrad), `E_mpjve` (mrad/s), `E_mpbve` (mm/s), per step."""
    body_pos: np.ndarray | None
    """(steps + 1, nbody, 3) world positions of every body, for the recording (first rollout only)."""
    body_quat: np.ndarray | None
    """(steps + 1, nbody, 4) wxyz (first rollout only)."""


def run_rollouts(
    spec: PolicySpec,
    models: list[mujoco.MjModel],
    reference: ReferenceMotion,
    policy: Policy,
    start_frames: np.ndarray,
    bodies: BodySets,
    protocol: Protocol,
) -> list[Rollout]:
    """Roll out `policy` from each start frame (rollout k on `models[k]`), all in one batched loop;
    the first rollout also keeps its body poses for the recording."""
    count, dt = len(start_frames), 1.0 / spec.get("rates.control_hz")
    model = models[0]
    physics = MujocoCpuBackend(models, protocol.threads)
    state = physics.state
    controller = DeployController(spec, model, reference, count)
    body_id = lambda names: np.array([model.body(n).id for n in names])
    ref_body = lambda names: np.array([reference.body_names.index(n) for n in names])
    tracked, tracked_ref = body_id(bodies.tracked), ref_body(bodies.tracked)
    term, term_ref = body_id(bodies.termination), ref_body(bodies.termination)
    root, root_ref = model.body(bodies.root).id, reference.body_names.index(bodies.root)
    allowed = set(body_id(bodies.feet).tolist()) | {0}
    floor = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0]
    policy_joints = spec.get("joints.policy")
    ref_joint = np.array([reference.joint_names.index(j) for j in policy_joints])
    qpos0 = np.zeros((count, model.nq))
    qvel0 = np.zeros((count, model.nv))
    f = start_frames
    qpos0[:, :3], qpos0[:, 3:7] = reference.root_pos[f], reference.root_quat[f]
    qvel0[:, :3] = reference.body_lin_vel_w[f, root_ref]
    for k in range(count):
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, reference.root_quat[f[k]])
        qvel0[k, 3:6] = rot.reshape(3, 3).T @ reference.body_ang_vel_w[f[k], root_ref]
    for j, name in enumerate(reference.joint_names):
        joint = model.joint(name)
        qpos0[:, model.jnt_qposadr[joint.id]] = reference.joint_pos[f, j]
        qvel0[:, model.jnt_dofadr[joint.id]] = reference.joint_vel[f, j]
    physics.set_state(torch.arange(count), torch.from_numpy(qpos0), torch.from_numpy(qvel0))
    controller.reset(state.qpos.numpy(), state.qvel.numpy(), start_frames)

    last = reference.n_frames - 1
    alive = np.ones(count, dtype=bool)
    terminated = np.zeros(count, dtype=bool)
    steps = np.zeros(count, dtype=np.int64)
    errors: list[dict[str, np.ndarray]] = []
    poses = [(state.body_pos[0].numpy().copy(), state.body_quat[0].numpy().copy())]
    previous_pos = state.body_pos[:, tracked].numpy().copy()
    obs = controller.current()
    while alive.any():
        action = policy(obs.astype(np.float32))
        ctrl = controller.targets(action)
        physics.step(torch.from_numpy(ctrl), spec.decimation, active=torch.from_numpy(alive))
        qpos = state.qpos.numpy().copy()
        qvel = state.qvel.numpy().copy()
        xpos = state.body_pos.numpy().copy()
        xquat = state.body_quat.numpy().copy()
        frame = controller.frame
        ref_pos = reference.body_pos_w[frame][:, tracked_ref]
        pos = xpos[:, tracked]
        rel = pos - xpos[:, root : root + 1]
        ref_rel = ref_pos - reference.body_pos_w[frame][:, root_ref : root_ref + 1]
        velocity = (pos - previous_pos) / dt
        previous_pos = pos
        errors.append(
            {
                "E_g_mpbpe": 1000 * np.linalg.norm(pos - ref_pos, axis=-1).mean(-1),
                "E_mpbpe": 1000 * np.linalg.norm(rel - ref_rel, axis=-1).mean(-1),
                "E_mpjpe": 1000
                * np.abs(qpos[:, controller.qpos_idx] - reference.joint_pos[frame][:, ref_joint]).mean(-1),
                "E_mpjve": 1000
                * np.abs(qvel[:, controller.dof_idx] - reference.joint_vel[frame][:, ref_joint]).mean(-1),
                "E_mpbve": 1000
                * np.linalg.norm(velocity - reference.body_lin_vel_w[frame][:, tracked_ref], axis=-1).mean(-1),
            }
        )
        poses.append((xpos[0], xquat[0]))
        tilted = bad_orientation(
            torch.from_numpy(xquat[:, root]),
            torch.from_numpy(reference.body_quat_w[frame, root_ref]),
            protocol.orientation_limit_rad,
        )
        far = motion_far(
            torch.from_numpy(xpos[:, term]),
            torch.from_numpy(reference.body_pos_w[frame][:, term_ref]),
            protocol.motion_far_m,
        )
        touching = np.array([_bad_contact(m, d, floor, allowed) for m, d in zip(models, physics.datas)])
        failed = tilted.numpy() | far.numpy() | touching
        steps += alive
        terminated |= alive & failed
        alive &= ~failed & (frame < last)
        obs = controller.observe(qpos, qvel)
    out = []
    for k in range(count):
        n = int(steps[k])
        out.append(
            Rollout(
                start_frame=int(start_frames[k]),
                steps=n,
                completed=not terminated[k],
                remaining_steps=int(last - start_frames[k]),
                errors={name: np.array([e[name][k] for e in errors[:n]]) for name in errors[0]},
                body_pos=np.stack([p[0] for p in poses[: n + 1]]) if k == 0 else None,
                body_quat=np.stack([p[1] for p in poses[: n + 1]]) if k == 0 else None,
            )
        )
    physics.close()
    return out


def _bad_contact(model: mujoco.MjModel, data: mujoco.MjData, floor: list[int], allowed: set[int]) -> bool:
    for i in range(data.ncon):
        g1, g2 = data.contact.geom1[i], data.contact.geom2[i]
        if g1 in floor or g2 in floor:
            other = g2 if g1 in floor else g1
            if model.geom_bodyid[other] not in allowed:
                return True
    return False


def randomized_models(
    model: mujoco.MjModel, count: int, rng: np.random.Generator, ranges: Randomization = Randomization()
) -> list[mujoco.MjModel]:
    """`count` copies of `model` with the training ranges of link mass, ground friction and PD gains
    drawn per copy: the optional randomized evaluation."""
    out = []
    for _ in range(count):
        mass, friction = rng.uniform(*ranges.mass_factor), rng.uniform(*ranges.friction_factor)
        kp, kd = rng.uniform(*ranges.pd_factor, size=2)
        out.append(randomized_copy(model, mass, friction, kp, kd))
    return out
