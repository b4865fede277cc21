"""Batched stepping with mujoco.rollout: the same states as sequential mj_step, results as arrays."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import torch
from conftest import RETARGETED_DIR

from rd_pipeline.env.physics import MujocoCpuBackend, MujocoRolloutBackend
from rd_pipeline.env.physics.state import body_velocities
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
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


def test_the_cpu_backend_resumes_from_its_states_bit_for_bit() -> None:
    """A checkpoint keeps the solver's warm start: stepping on from restored states is the same, to
    the last bit, as stepping on without the interruption."""
    robot = load_robot("g1")
    reference = import_retargeted_csv(
        RETARGETED_DIR / "g1" / "dance1_subject2.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    model = simulation_model(robot)
    joints = [model.jnt_qposadr[model.joint(j).id] for j in robot.config.joint_names]
    qpos = np.tile(model.qpos0, (2, 1))
    qpos[:, :3] = reference.root_pos[[0, 300]]
    qpos[:, 3:7] = reference.root_quat[[0, 300]]
    qpos[:, joints] = reference.joint_pos[[0, 300]]
    straight = MujocoCpuBackend([model, model], threads=1)
    straight.set_state(torch.arange(2), torch.from_numpy(qpos), torch.zeros(2, model.nv, dtype=torch.float64))
    ctrl = lambda step: torch.from_numpy(reference.joint_pos[[step, 300 + step]])
    for step in range(3):
        straight.step(ctrl(step), 10)
    resumed = MujocoCpuBackend([model, model], threads=1)
    resumed.set_states(straight.get_states())
    for step in range(3, 8):
        straight.step(ctrl(step), 10)
        resumed.step(ctrl(step), 10)
    assert torch.equal(straight.state.qpos, resumed.state.qpos)
    assert torch.equal(straight.state.qvel, resumed.state.qvel)
