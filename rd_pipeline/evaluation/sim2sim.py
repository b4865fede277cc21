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

from rd_pipeline.env.mdp.terminations import bad_orientation, motion_gap
from rd_pipeline.env.physics import MujocoCpuBackend
from rd_pipeline.env.physics.state import PhysicsState
from rd_pipeline.evaluation.deploy import DeployController
from rd_pipeline.evaluation.disturbances import Disturbances
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.policy_runtime import Policy
from rd_pipeline.policy_spec import PolicySpec


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
    ended_by: str
    """What failed at its last step (`tilted`, `far <body>`, `floor <body>`, joined by ` + ` when
    several did); empty when it reached the end of the reference."""
    remaining_steps: int
    """Control steps from the start to the end of the reference (the most it could survive)."""
    errors: dict[str, np.ndarray]
    """`E_g_mpbpe`, `E_mpbpe` (mm), `E_mpjpe` (mrad), `E_mpjve` (mrad/s), `E_mpbve` (mm/s), per step."""
    body_pos: np.ndarray | None
    """(steps + 1, nbody, 3) world positions of every body, for the recording (first rollout only)."""
    body_quat: np.ndarray | None
    """(steps + 1, nbody, 4) wxyz (first rollout only)."""
    qpos: np.ndarray | None = None
    """(steps + 1, nq) generalized positions, for the rendered pictures (first rollout only)."""


@dataclass(frozen=True)
class _Checks:
    """What each control step is measured against: where the checked bodies and joints sit in
    the model (ids) and in the reference (`_ref` columns)."""

    tracked: np.ndarray
    tracked_ref: np.ndarray
    termination: np.ndarray
    termination_ref: np.ndarray
    termination_names: tuple[str, ...]
    root: int
    root_ref: int
    allowed: set[int]
    """Bodies that may touch the floor: the feet and the world."""
    floor: list[int]
    """The world body's geoms."""
    ref_joint: np.ndarray
    """Reference column of each policy joint."""
    qpos_idx: np.ndarray
    """qpos address of each policy joint."""
    dof_idx: np.ndarray
    """qvel address of each policy joint."""


def run_rollouts(
    spec: PolicySpec,
    models: list[mujoco.MjModel],
    reference: ReferenceMotion,
    policy: Policy,
    start_frames: np.ndarray,
    bodies: BodySets,
    protocol: Protocol,
    disturbances: Disturbances | None = None,
) -> list[Rollout]:
    """Roll out `policy` from each start frame (rollout k on `models[k]`), all in one batched loop,
    meeting `disturbances` (delay, pushes, forces, sensor noise) where given; the first rollout
    also keeps its poses for the recording and the pictures."""
    control_hz = spec.get("rates.control_hz")
    substeps = protocol.substeps(control_hz)
    physics = MujocoCpuBackend(models, protocol.threads)
    noise = None if disturbances is None else disturbances.observe
    controller = DeployController(spec, models[0], reference, len(start_frames), noise)
    checks = _checks(models[0], reference, bodies, spec.get("joints.policy"), controller)
    _place_on_reference(physics, controller, reference, start_frames, checks)
    tally = _Tally.begin(physics.state, checks, 1.0 / control_hz)
    last = reference.n_frames - 1
    obs = controller.current()
    while tally.alive.any():
        ctrl = controller.targets(policy(obs.astype(np.float32)))
        force = None
        if disturbances is not None:
            ctrl = disturbances.delayed(ctrl)
            pushed, velocity = disturbances.push_due()
            physics.push(torch.from_numpy(pushed), torch.from_numpy(velocity))
            force = torch.from_numpy(disturbances.joint_force(models[0].nv))
        active = torch.from_numpy(tally.alive)
        physics.step(torch.from_numpy(ctrl), substeps, joint_force=force, active=active)
        qpos = physics.state.qpos.numpy().copy()
        qvel = physics.state.qvel.numpy().copy()
        xpos = physics.state.body_pos.numpy().copy()
        xquat = physics.state.body_quat.numpy().copy()
        frame = controller.frame
        velocity = tally.tracked_velocity(xpos[:, checks.tracked])
        tally.errors.append(_step_errors(checks, reference, frame, qpos, qvel, xpos, velocity))
        tally.poses.append((xpos[0], xquat[0], qpos[0]))
        causes = _failures(checks, models, physics.datas, reference, frame, xpos, xquat, protocol)
        tally.record(causes, at_end=frame >= last)
        obs = controller.observe(qpos, qvel)
    physics.close()
    return tally.rollouts(start_frames, last)


def _place_on_reference(
    physics: MujocoCpuBackend,
    controller: DeployController,
    reference: ReferenceMotion,
    start_frames: np.ndarray,
    checks: _Checks,
) -> None:
    """Put every rollout on the reference at its start frame, and the controller with it."""
    qpos0, qvel0 = reference_states(physics.models[0], reference, start_frames, checks.root_ref)
    rows = torch.arange(len(start_frames))
    physics.set_state(rows, torch.from_numpy(qpos0), torch.from_numpy(qvel0))
    controller.reset(physics.state.qpos.numpy(), physics.state.qvel.numpy(), start_frames)


@dataclass
class _Tally:
    """What the batched loop gathers as it goes: which rollouts still run, what ended the others,
    and every step's errors and the first rollout's body poses."""

    alive: np.ndarray
    ended_by: np.ndarray
    steps: np.ndarray
    errors: list[dict[str, np.ndarray]]
    poses: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    previous_pos: np.ndarray
    """(R, tracked, 3) the tracked bodies' positions one control step ago."""
    dt: float
    """Seconds per control step."""

    @classmethod
    def begin(cls, state: PhysicsState, checks: _Checks, dt: float) -> _Tally:
        count = state.qpos.shape[0]
        return cls(
            alive=np.ones(count, dtype=bool),
            ended_by=np.full(count, "", dtype=object),
            steps=np.zeros(count, dtype=np.int64),
            errors=[],
            poses=[
                (
                    state.body_pos[0].numpy().copy(),
                    state.body_quat[0].numpy().copy(),
                    state.qpos[0].numpy().copy(),
                )
            ],
            previous_pos=state.body_pos[:, checks.tracked].numpy().copy(),
            dt=dt,
        )

    def tracked_velocity(self, pos: np.ndarray) -> np.ndarray:
        """(R, tracked, 3) finite-difference velocity of the tracked bodies over the last step."""
        velocity = (pos - self.previous_pos) / self.dt
        self.previous_pos = pos
        return velocity

    def record(self, causes: np.ndarray, at_end: np.ndarray) -> None:
        """Count the step for every running rollout; stop those that failed or reached the end."""
        failed = causes != ""
        self.steps += self.alive
        self.ended_by = np.where(self.alive & failed, causes, self.ended_by)
        self.alive &= ~failed & ~at_end

    def rollouts(self, start_frames: np.ndarray, last: int) -> list[Rollout]:
        """Per rollout, the steps it survived; the body poses for the first only."""
        out = []
        for k in range(len(start_frames)):
            n = int(self.steps[k])
            out.append(
                Rollout(
                    start_frame=int(start_frames[k]),
                    steps=n,
                    completed=not self.ended_by[k],
                    ended_by=str(self.ended_by[k]),
                    remaining_steps=int(last - start_frames[k]),
                    errors={name: np.array([e[name][k] for e in self.errors[:n]]) for name in self.errors[0]},
                    body_pos=np.stack([p[0] for p in self.poses[: n + 1]]) if k == 0 else None,
                    body_quat=np.stack([p[1] for p in self.poses[: n + 1]]) if k == 0 else None,
                    qpos=np.stack([p[2] for p in self.poses[: n + 1]]) if k == 0 else None,
                )
            )
        return out


def _checks(
    model: mujoco.MjModel,
    reference: ReferenceMotion,
    bodies: BodySets,
    policy_joints: list[str],
    controller: DeployController,
) -> _Checks:
    """Look up the checked bodies and joints in the model and in the reference."""

    def body_id(names: tuple[str, ...]) -> np.ndarray:
        return np.array([model.body(n).id for n in names])

    def ref_body(names: tuple[str, ...]) -> np.ndarray:
        return np.array([reference.body_names.index(n) for n in names])

    return _Checks(
        tracked=body_id(bodies.tracked),
        tracked_ref=ref_body(bodies.tracked),
        termination=body_id(bodies.termination),
        termination_ref=ref_body(bodies.termination),
        termination_names=bodies.termination,
        root=model.body(bodies.root).id,
        root_ref=reference.body_names.index(bodies.root),
        allowed=set(body_id(bodies.feet).tolist()) | {0},
        floor=[g for g in range(model.ngeom) if model.geom_bodyid[g] == 0],
        ref_joint=np.array([reference.joint_names.index(j) for j in policy_joints]),
        qpos_idx=controller.qpos_idx,
        dof_idx=controller.dof_idx,
    )


def reference_states(
    model: mujoco.MjModel,
    reference: ReferenceMotion,
    start_frames: np.ndarray,
    root_ref: int,
) -> tuple[np.ndarray, np.ndarray]:
    """(R, nq) qpos and (R, nv) qvel of the reference at each of `start_frames` (the base's angular
    velocity turned into its own frame, as MuJoCo's free joint holds it)."""
    count = len(start_frames)
    qpos0 = np.zeros((count, model.nq))
    qvel0 = np.zeros((count, model.nv))
    f = start_frames
    qpos0[:, :3] = reference.root_pos[f]
    qpos0[:, 3:7] = reference.root_quat[f]
    qvel0[:, :3] = reference.body_lin_vel_w[f, root_ref]
    for k in range(count):
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, reference.root_quat[f[k]])
        qvel0[k, 3:6] = rot.reshape(3, 3).T @ reference.body_ang_vel_w[f[k], root_ref]
    for j, name in enumerate(reference.joint_names):
        joint = model.joint(name)
        qpos0[:, model.jnt_qposadr[joint.id]] = reference.joint_pos[f, j]
        qvel0[:, model.jnt_dofadr[joint.id]] = reference.joint_vel[f, j]
    return qpos0, qvel0


def _step_errors(
    checks: _Checks,
    reference: ReferenceMotion,
    frame: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    xpos: np.ndarray,
    velocity: np.ndarray,
) -> dict[str, np.ndarray]:
    """(R,) each error of this step, see `Rollout.errors`; `velocity` is the tracked bodies'."""
    ref_pos = reference.body_pos_w[frame][:, checks.tracked_ref]
    pos = xpos[:, checks.tracked]
    rel = pos - xpos[:, checks.root : checks.root + 1]
    ref_rel = ref_pos - reference.body_pos_w[frame][:, checks.root_ref : checks.root_ref + 1]
    joint_pos_error = qpos[:, checks.qpos_idx] - reference.joint_pos[frame][:, checks.ref_joint]
    joint_vel_error = qvel[:, checks.dof_idx] - reference.joint_vel[frame][:, checks.ref_joint]
    body_vel_error = velocity - reference.body_lin_vel_w[frame][:, checks.tracked_ref]
    return {
        "E_g_mpbpe": 1000 * np.linalg.norm(pos - ref_pos, axis=-1).mean(-1),
        "E_mpbpe": 1000 * np.linalg.norm(rel - ref_rel, axis=-1).mean(-1),
        "E_mpjpe": 1000 * np.abs(joint_pos_error).mean(-1),
        "E_mpjve": 1000 * np.abs(joint_vel_error).mean(-1),
        "E_mpbve": 1000 * np.linalg.norm(body_vel_error, axis=-1).mean(-1),
    }


def _failures(
    checks: _Checks,
    models: list[mujoco.MjModel],
    datas: list[mujoco.MjData],
    reference: ReferenceMotion,
    frame: np.ndarray,
    xpos: np.ndarray,
    xquat: np.ndarray,
    protocol: Protocol,
) -> np.ndarray:
    """(R,) what fails this step, "" where nothing does (`Rollout.ended_by`): the pelvis tilted or
    a termination body too far from the reference (the training terms), or a body other than the
    feet touching the floor."""
    tilted = bad_orientation(
        torch.from_numpy(xquat[:, checks.root]),
        torch.from_numpy(reference.body_quat_w[frame, checks.root_ref]),
        protocol.orientation_limit_rad,
    ).numpy()
    body_pos = torch.from_numpy(xpos[:, checks.termination])
    ref_body_pos = torch.from_numpy(reference.body_pos_w[frame][:, checks.termination_ref])
    gap = motion_gap(body_pos, ref_body_pos).max(dim=-1)
    far = (gap.values > protocol.motion_far_m).numpy()
    farthest = gap.indices.numpy()
    causes = []
    for k, (model, data) in enumerate(zip(models, datas)):
        found = ["tilted"] if tilted[k] else []
        if far[k]:
            found.append(f"far {checks.termination_names[farthest[k]]}")
        touching = _floor_contact(model, data, checks.floor, checks.allowed)
        if touching is not None:
            found.append(f"floor {touching}")
        causes.append(" + ".join(found))
    return np.array(causes, dtype=object)


def _floor_contact(model: mujoco.MjModel, data: mujoco.MjData, floor: list[int], allowed: set[int]) -> str | None:
    """The name of the first body touching the floor that may not, or None."""
    for i in range(data.ncon):
        first = data.contact.geom1[i]
        second = data.contact.geom2[i]
        if first in floor or second in floor:
            other = second if first in floor else first
            body = int(model.geom_bodyid[other])
            if body not in allowed:
                return model.body(body).name or f"body {body}"
    return None
