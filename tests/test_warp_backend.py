"""The MuJoCo Warp backend (on Warp's CPU device) steps like the C MuJoCo backend behind the same seam."""

from __future__ import annotations

import copy
import warnings

import mujoco
import numpy as np
import pytest
import torch
from conftest import RETARGETED_DIR

from rd_pipeline.env.physics import MujocoCpuBackend
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import Robot, load_robot

pytest.importorskip("mujoco_warp", reason="the gpu extra (mujoco-warp) is not installed")

CONTROL_STEPS = 10
QPOS_TOLERANCE = 1e-4
"""rad or m after 10 control steps (0.2 s, 100 physics steps, feet in contact): float32 Warp against
float64 C. Measured: 5e-7."""


def test_warp_backend_matches_c_mujoco_on_a_short_rollout() -> None:
    from rd_pipeline.env.physics.warp import MujocoWarpBackend

    robot = load_robot("g1")
    reference = import_retargeted_csv(
        RETARGETED_DIR / "g1" / "dance1_subject2.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    base = simulation_model(robot)
    heavy = copy.copy(base)
    heavy.body_mass[1:] *= 1.1  # a randomized world: per-world fields must reach Warp
    heavy.body_inertia[1:] *= 1.1
    models = [base, heavy, base]
    frames = np.array([0, 0, 200])
    qpos = np.zeros((3, base.nq))
    qvel = np.zeros((3, base.nv))
    qpos[:, :3], qpos[:, 3:7] = reference.root_pos[frames], reference.root_quat[frames]
    qadr = [base.jnt_qposadr[base.joint(j).id] for j in robot.config.joint_names]
    qpos[:, qadr] = reference.joint_pos[frames]
    c = MujocoCpuBackend(models, threads=1)
    warp = MujocoWarpBackend(models, device="cpu")
    for backend in (c, warp):
        backend.set_state(torch.arange(3), torch.from_numpy(qpos), torch.from_numpy(qvel))
    for step in range(CONTROL_STEPS):
        ctrl = torch.from_numpy(reference.joint_pos[frames + step + 1])
        c.step(ctrl, 10)
        warp.step(ctrl, 10)
    a = {name: getattr(c.state, name).numpy() for name in ("qpos", "body_pos", "actuator_force", "contact_force")}
    b = {name: getattr(warp.state, name).numpy() for name in ("qpos", "body_pos", "actuator_force", "contact_force")}
    gap = np.abs(a["qpos"] - b["qpos"]).max()
    assert gap < QPOS_TOLERANCE, gap
    assert np.abs(a["body_pos"] - b["body_pos"]).max() < QPOS_TOLERANCE
    assert np.allclose(a["actuator_force"], b["actuator_force"], atol=0.01)  # N m, PD torques of the last substep
    assert a["contact_force"][:, robot.model.body("left_ankle_roll_link").id, 2].min() > 10  # feet carry weight
    assert np.allclose(a["contact_force"].sum(axis=1)[:, 2], b["contact_force"].sum(axis=1)[:, 2], rtol=1e-3)
    # The randomized world is heavier in Warp too: the ground carries about 10 % more.
    vertical = b["contact_force"].sum(axis=1)[:, 2]
    assert 1.03 < vertical[1] / vertical[0] < 1.2
    # Both count about the same contacts (float32 against float64 at the margins).
    peaks = [backend.diagnostics()["contacts_peak_world"] for backend in (c, warp)]
    assert peaks[0] > 0 and abs(peaks[0] - peaks[1]) <= 2, peaks


def test_graphs_replay_what_kernel_launches_compute() -> None:
    """The graph path, on Warp's CPU device (which records graphs since Warp 1.19): the step graph
    with its refresh and the reset graph give exactly what launching kernel by kernel gives,
    through partial resets, pushes and joint forces; another substep count gets its own graph."""
    from rd_pipeline.env.physics.warp import MujocoWarpBackend

    robot = load_robot("g1")
    base = simulation_model(robot, collision="primitive")
    heavy = copy.copy(base)
    heavy.body_mass[1:] *= 1.1
    models = [base, heavy, base]
    launched = MujocoWarpBackend(models, device="cpu")
    replayed = MujocoWarpBackend(models, device="cpu", cpu_graphs=True)
    assert "'cpu' is not a CUDA device" in launched.capture_fallback_reason
    assert replayed.capture_fallback_reason is None
    qpos, qvel, targets = _reference_states(robot, base, np.array([0, 0, 200]), CONTROL_STEPS)
    forces = torch.randn(CONTROL_STEPS, 3, base.nv, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    for backend in (launched, replayed):
        backend.set_state(torch.arange(3), qpos, qvel)
        for step in range(CONTROL_STEPS):
            backend.step(targets[step], 10, 5.0 * forces[step] if step % 2 else None)
            if step == 3:
                backend.set_state(torch.tensor([1]), qpos[1:2], qvel[1:2])
            if step == 5:
                backend.push(torch.tensor([0, 2]), torch.tensor([[0.3, -0.2], [-0.1, 0.4]]))
        backend.step(targets[-1], 5)
    for name in ("qpos", "qvel", "body_pos", "body_quat", "body_vel", "actuator_force", "contact_force"):
        assert torch.equal(getattr(launched.state, name), getattr(replayed.state, name)), name
    assert launched.diagnostics() == replayed.diagnostics()
    assert set(replayed.graphs) == {("forward", 0), ("step", 10), ("step", 5)} and not launched.graphs


def test_a_failed_capture_falls_back_to_kernel_launches(monkeypatch: pytest.MonkeyPatch) -> None:
    """A graph that cannot be captured (here: every capture raises) leaves the backend launching
    kernel by kernel, with the reason kept and said once; nothing of the failed capture ran."""
    import warp as wp

    from rd_pipeline.env.physics.warp import MujocoWarpBackend

    class FailingCapture:
        def __enter__(self):
            raise RuntimeError("no graphs today")

        def __exit__(self, *exc: object) -> None: ...

    robot = load_robot("g1")
    base = simulation_model(robot, collision="primitive")
    launched = MujocoWarpBackend([base, base], device="cpu")
    failing = MujocoWarpBackend([base, base], device="cpu", cpu_graphs=True)
    monkeypatch.setattr(wp, "ScopedCapture", FailingCapture)
    qpos, qvel, targets = _reference_states(robot, base, np.array([0, 100]), 2)
    with pytest.warns(UserWarning, match="graph capture failed: no graphs today"):
        failing.set_state(torch.arange(2), qpos, qvel)
    assert failing.capture_fallback_reason == "graph capture failed: no graphs today" and not failing.graphs
    launched.set_state(torch.arange(2), qpos, qvel)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once: no capture is tried again
        for backend in (launched, failing):
            backend.step(targets[0], 10)
            backend.step(targets[1], 10)
    assert torch.equal(launched.state.qpos, failing.state.qpos)


def _reference_states(
    robot: Robot, model: mujoco.MjModel, frames: np.ndarray, steps: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """States at reference `frames` (root pose and joints, at rest) and the (steps, N, J) joint
    targets of the frames after them."""
    reference = import_retargeted_csv(
        RETARGETED_DIR / "g1" / "dance1_subject2.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    qpos = np.zeros((len(frames), model.nq))
    qpos[:, :3] = reference.root_pos[frames]
    qpos[:, 3:7] = reference.root_quat[frames]
    qadr = [model.jnt_qposadr[model.joint(j).id] for j in robot.config.joint_names]
    qpos[:, qadr] = reference.joint_pos[frames]
    targets = np.stack([reference.joint_pos[frames + step + 1] for step in range(steps)])
    return torch.from_numpy(qpos), torch.zeros(len(frames), model.nv, dtype=torch.float64), torch.from_numpy(targets)


@pytest.mark.slow
def test_ppo_trains_through_the_warp_backend(tmp_path) -> None:
    """A few PPO iterations end to end with physics in MuJoCo Warp (on Warp's CPU device here, on
    a GPU in the `paper` profile): the same environment, state as torch tensors from Warp."""
    from rd_pipeline.env.config import EnvConfig
    from rd_pipeline.env.mdp.rewards import GROUPS
    from rd_pipeline.env.tracking_env import TrackingEnv
    from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
    from rd_pipeline.sampling.segments import segment_bounds
    from rd_pipeline.training.evaluate import checkpoint_scorer, nominal
    from rd_pipeline.training.log import read_training_log
    from rd_pipeline.training.ppo import build_ppo
    from rd_pipeline.training.ppo_config import PpoConfig
    from rd_pipeline.training.trainer import train

    torch.manual_seed(0)
    robot = load_robot("g1")
    reference = import_retargeted_csv(
        RETARGETED_DIR / "g1" / "dance1_subject2.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference.frames(0, 250)
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=0)
    config = EnvConfig(num_envs=4, backend="warp", device="cpu")
    env = TrackingEnv(robot, reference, sampler, starts, lengths, config, seed=0)
    assert env.backend.state.qpos.device.type == "cpu" and env.num_actions == 23
    ppo = build_ppo(env.get_observations(), env.num_envs, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=8))
    before = {k: v.clone() for k, v in ppo.actor.state_dict().items()}
    # The checkpoint is scored in a nominal environment on the same backend.
    scoring_env = TrackingEnv(robot, reference, sampler, starts, lengths, nominal(config, 2), seed=0)
    score = checkpoint_scorer(scoring_env, lambda obs: ppo.actor(obs, stochastic_output=False))
    train(env, ppo, iterations=3, out_dir=tmp_path, checkpoint_every=3, score=score)
    rows = read_training_log(tmp_path)
    assert [row["iteration"] for row in rows] == [1, 2, 3]
    assert 0.0 < rows[-1]["start_zero_s"] < 4.98 and 0.0 < rows[-1]["completion"] < 1.0
    assert all(np.isfinite(row["reward"]) and np.isfinite(row["loss_value"]) for row in rows)
    assert any(not torch.equal(v, before[k]) for k, v in ppo.actor.state_dict().items())  # it learned something
    assert (tmp_path / "checkpoints" / "model_3.pt").is_file()
    env.close()
    scoring_env.close()
