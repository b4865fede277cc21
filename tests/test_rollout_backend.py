"""Batched stepping with mujoco.rollout: the same states as sequential mj_step, results as arrays."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import torch
from conftest import RETARGETED_DIR

from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.rl.physics import MujocoRolloutBackend
from rd_pipeline.rl.physics.state import body_velocities
from rd_pipeline.rl.sim_model import simulation_model
from rd_pipeline.robots import load_robot

TOLERANCE = 1e-9


def test_batched_stepping_equals_sequential_mj_step() -> None:
    robot = load_robot("g1")
    reference = import_retargeted_csv(
        RETARGETED_DIR / "g1" / "dance1_subject2.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    base = simulation_model(robot, collision="primitive", body_sensors=True)
    heavy = copy.copy(base)
    heavy.body_mass[1:] *= 1.1  # per-environment (randomized) models stay supported
    models = [base, heavy, base, heavy]
    frames = np.array([0, 100, 200, 300])
    joints = [base.jnt_qposadr[base.joint(j).id] for j in robot.config.joint_names]
    dofs = [base.jnt_dofadr[base.joint(j).id] for j in robot.config.joint_names]
    qpos = np.tile(base.qpos0, (4, 1))
    qpos[:, :3] = reference.root_pos[frames]
    qpos[:, 3:7] = reference.root_quat[frames]
    qpos[:, joints] = reference.joint_pos[frames]
    qvel = np.zeros((4, base.nv))
    qvel[:, dofs] = reference.joint_vel[frames]
    backend = MujocoRolloutBackend(models, threads=2)
    backend.set_state(torch.arange(4), torch.from_numpy(qpos), torch.from_numpy(qvel))
    sequential = [mujoco.MjData(m) for m in models]
    for data, model, q, v in zip(sequential, models, qpos, qvel):
        data.qpos[:] = q
        data.qvel[:] = v
        mujoco.mj_forward(model, data)
    rng = np.random.default_rng(0)
    for step in range(5):
        ctrl = reference.joint_pos[frames + step + 1]
        force = np.zeros((4, base.nv))
        force[:, dofs] = rng.uniform(-5.0, 5.0, (4, len(dofs)))
        state = backend.step(torch.from_numpy(ctrl), 10, torch.from_numpy(force))
        for i, (model, data) in enumerate(zip(models, sequential)):
            data.qacc_warmstart[:] = 0.0  # the rollout starts each control step's solver cold
            data.ctrl[:] = ctrl[i]
            data.qfrc_applied[:] = force[i]
            for _ in range(9):
                mujoco.mj_step(model, data)
            # Sensors (body poses, forces) are evaluated inside the last step, before it integrates.
            before = copy.copy(data)
            mujoco.mj_forward(model, before)
            mujoco.mj_rnePostConstraint(model, before)
            assert np.abs(state.body_pos[i].numpy() - before.xpos).max() < TOLERANCE
            assert np.abs(state.body_quat[i].numpy() - before.xquat).max() < TOLERANCE
            velocity = body_velocities(before.xpos, before.cvel, before.subtree_com[model.body_rootid])
            assert np.abs(state.body_vel[i].numpy() - velocity).max() < TOLERANCE
            assert np.abs(state.contact_force[i, 1:].numpy() - before.cfrc_ext[1:, 3:]).max() < TOLERANCE
            assert np.abs(state.actuator_force[i].numpy() - before.actuator_force).max() < TOLERANCE
            mujoco.mj_step(model, data)
            assert np.abs(state.qpos[i].numpy() - data.qpos).max() < TOLERANCE
            assert np.abs(state.qvel[i].numpy() - data.qvel).max() < TOLERANCE
    feet = [robot.body_ids[f] for f in robot.config.foot_bodies]
    assert state.contact_force[:, feet, 2].sum() > 0  # the soles carry weight
    backend.close()
