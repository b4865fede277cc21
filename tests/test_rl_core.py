"""Residual actions, PD torques, reward terms on hand-built states, and the multi-head GAE."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest
import torch
from conftest import h1_2_dance_env

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp import reward_terms, terminations
from rd_pipeline.env.mdp.actions import RESIDUAL_PRESETS, ActionConfig, ResidualActions, joint_semantics
from rd_pipeline.env.mdp.events import rsi_state
from rd_pipeline.env.mdp.reward_terms import PenaltyTerm, TermContext, TrackingState
from rd_pipeline.env.mdp.rewards import GROUPS, AdaptiveSigma, RewardManager, RewardsConfig
from rd_pipeline.env.mdp.terminations import TerminationContext, TerminationsConfig
from rd_pipeline.env.physics import MujocoCpuBackend
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.robots import load_robot
from rd_pipeline.robots.config import available_robots
from rd_pipeline.training.advantages import combined_advantage, multi_head_gae
from rd_pipeline.training.ppo import MultiHeadPPO, build_ppo
from rd_pipeline.training.ppo_config import PpoConfig

N, B, P = 3, 5, 4


def _state(**changes) -> TrackingState:
    """Robot exactly on the reference, standing still, no torques: every penalty is zero."""
    zeros = lambda *shape: torch.zeros(*shape, dtype=torch.float64)
    quat = zeros(N, B, 4)
    quat[..., 0] = 1.0
    body = torch.arange(N * B * 3, dtype=torch.float64).reshape(N, B, 3) / 10
    joints = torch.linspace(-0.5, 0.5, P, dtype=torch.float64).repeat(N, 1)
    values = dict(
        body_pos=body.clone(),
        body_quat=quat.clone(),
        body_lin_vel=zeros(N, B, 3),
        body_ang_vel=zeros(N, B, 3),
        joint_pos=joints.clone(),
        joint_vel=zeros(N, P),
        ref_body_pos=body.clone(),
        ref_body_quat=quat.clone(),
        ref_body_lin_vel=zeros(N, B, 3),
        ref_body_ang_vel=zeros(N, B, 3),
        ref_joint_pos=joints.clone(),
        ref_joint_vel=zeros(N, P),
        feet_contact=torch.ones(N, 2, dtype=torch.bool),
        ref_feet_contact=torch.ones(N, 2, dtype=torch.bool),
        feet_force=zeros(N, 2, 3),
        feet_speed=zeros(N, 2),
        torque=zeros(N, P),
        joint_acc=zeros(N, P),
        action=zeros(N, P),
        last_action=zeros(N, P),
        second_last_action=zeros(N, P),
        feet_air_time=zeros(N, 2),
        undesired_contacts=zeros(N),
        terminated=torch.zeros(N, dtype=torch.bool),
    )
    values.update(changes)
    return TrackingState(**values)


CONTEXT = TermContext(
    root=0,
    feet=(3, 4),
    keypoints=(1, 2),
    joint_lower=torch.full((P,), -1.0, dtype=torch.float64),
    joint_upper=torch.full((P,), 1.0, dtype=torch.float64),
    velocity_limit=torch.full((P,), 10.0, dtype=torch.float64),
    effort_limit=torch.full((P,), 50.0, dtype=torch.float64),
)
MANAGER = RewardManager(RewardsConfig(), CONTEXT)


def compute_rewards(state, penalty_scale, sigma=None):
    return MANAGER.compute(state, penalty_scale, sigma)


def test_perfect_tracking_earns_every_tracking_weight() -> None:
    groups, terms, _ = compute_rewards(_state(), penalty_scale=0.8)
    assert GROUPS == ("body", "root", "joint", "contact", "regularization")
    expected = {
        "body": 2.0 + 0.5 + 1.8 + 0.5 + 2.0 + 0.5 + 0.5 + 0.5 + 0.5,
        "root": 2.25,
        "joint": 1.5,
        "contact": 0.5,
        "regularization": 0.0,
    }
    for g, name in enumerate(GROUPS):
        assert torch.allclose(groups[:, g], torch.full((N,), expected[name], dtype=torch.float64))
    assert set(terms) >= {"body_pos", "termination", "slippage"}


def test_hand_computed_terms() -> None:
    body = _state().body_pos.clone()
    body[:, :, 0] += 0.02  # every body 2 cm off: e = 0.0004 = sigma^2 for body_pos
    joints = _state().joint_pos.clone()
    joints[:, 1] += 0.3  # one joint 0.3 rad off: e = 0.09 = sigma^2
    torque = torch.full((N, P), 10.0, dtype=torch.float64)
    force = torch.zeros(N, 2, 3, dtype=torch.float64)
    force[:, 0, 2] = 500.0  # 100 N above the 400 N allowance
    terminated = torch.tensor([True, False, False])
    quat = _state().body_quat.clone()
    half = math.radians(10) / 2
    quat[:, 0] = torch.tensor([math.cos(half), 0.0, 0.0, math.sin(half)], dtype=torch.float64)  # pelvis yawed 10 deg
    air = torch.zeros(N, 2, dtype=torch.float64)
    air[:, 0] = 0.45  # left foot touches down after 0.45 s in the air
    air[2, 1] = 0.6  # ... and env 2's right foot after 0.6 s, where the reference has it in the air
    reference_contact = torch.ones(N, 2, dtype=torch.bool)
    reference_contact[2, 1] = False
    state = _state(
        body_pos=body,
        joint_pos=joints,
        torque=torque,
        feet_force=force,
        terminated=terminated,
        body_quat=quat,
        feet_air_time=air,
        ref_feet_contact=reference_contact,
    )
    _, terms, _ = compute_rewards(state, penalty_scale=0.8)
    assert torch.allclose(terms["body_pos"], torch.full((N,), 2.0 * math.exp(-1.0), dtype=torch.float64))
    assert torch.allclose(
        terms["body_pos_rel"], torch.full((N,), 0.5, dtype=torch.float64)
    )  # a shift is not a pose error
    assert torch.allclose(terms["joint_pos"], torch.full((N,), 1.0 * math.exp(-1.0), dtype=torch.float64))
    angle = math.radians(10)
    assert terms["root_orientation"][0].item() == pytest.approx(0.25 * math.exp(-(angle**2) / 0.25**2))
    assert terms["body_orientation"][0].item() == pytest.approx(0.5 * math.exp(-(angle**2 / B) / 0.1**2))
    assert torch.allclose(terms["torque"], torch.full((N,), -1e-6 * 0.8 * 4 * 100, dtype=torch.float64))
    assert torch.allclose(terms["foot_contact_force"], torch.full((N,), -0.01 * 0.8 * 100, dtype=torch.float64))
    assert terms["termination"].tolist() == pytest.approx([-200 * 0.8, 0.0, 0.0])
    assert terms["feet_air_time"].tolist() == pytest.approx([0.2, 0.2, 0.2])  # not scaled by the penalty curriculum


def test_adaptive_sigma_follows_the_error_and_never_widens() -> None:
    body = _state().body_pos.clone()
    body[:, :, 0] += 0.01  # e = 1e-4, a quarter of the table's sigma^2 = 4e-4
    adaptive = AdaptiveSigma(alpha=0.5, table_sigmas=MANAGER.tracking_sigmas(), device=torch.device("cpu"))
    _, _, errors = compute_rewards(_state(body_pos=body), 1.0)
    everyone = torch.ones(N, dtype=torch.bool)
    adaptive.update(errors, everyone)
    assert float(adaptive.sigma()["body_pos"]) == pytest.approx(math.sqrt(0.5 * 4e-4 + 0.5 * 1e-4))
    _, terms, _ = compute_rewards(_state(body_pos=body), 1.0, sigma=adaptive.sigma())
    assert terms["body_pos"][0].item() == pytest.approx(2.0 * math.exp(-1e-4 / 2.5e-4))
    body[:, :, 0] += 1.0  # far worse tracking: the kernel stays at the table width
    for _ in range(20):
        adaptive.update(compute_rewards(_state(body_pos=body), 1.0)[2], everyone)
    assert float(adaptive.sigma()["body_pos"]) == pytest.approx(0.02)
    # Errors of worlds that are not valid (non-finite physics) move nothing.
    before = adaptive.sigma()["body_pos"]
    adaptive.update({name: torch.full((N,), 1e-9) for name in errors}, torch.zeros(N, dtype=torch.bool))
    assert float(adaptive.sigma()["body_pos"]) == float(before)


def _single_head_gae(rewards, values, dones, last, gamma, lam):
    advantage, out = torch.zeros_like(last), torch.zeros_like(rewards)
    for t in reversed(range(rewards.shape[0])):
        nxt = last if t == rewards.shape[0] - 1 else values[t + 1]
        live = 1.0 - dones[t].float()
        delta = rewards[t] + live * gamma * nxt - values[t]
        advantage = delta + live * gamma * lam * advantage
        out[t] = advantage
    return out


def test_multi_head_gae_is_per_head_gae() -> None:
    g = torch.Generator().manual_seed(0)
    T, E, G = 24, 16, 5
    rewards, values = torch.randn(T, E, G, generator=g), torch.randn(T, E, G, generator=g)
    dones, last = torch.rand(T, E, generator=g) < 0.1, torch.randn(E, G, generator=g)
    advantages, returns = multi_head_gae(rewards, values, dones, last, 0.99, 0.95)
    for head in range(G):
        single = _single_head_gae(rewards[..., head], values[..., head], dones, last[:, head], 0.99, 0.95)
        assert torch.allclose(advantages[..., head], single, atol=1e-6)
    assert torch.allclose(returns, advantages + values)
    combined = combined_advantage(advantages)
    summed = advantages.sum(-1)
    assert torch.allclose(combined, (summed - summed.mean()) / (summed.std() + 1e-8))


PRESET_RESIDUAL_JOINTS = {
    # Policy joints with residual semantics per preset: G1 (23 policy joints), G1 29-DoF (29), H1 (19), H1-2 (21).
    "g1": {
        "absolute": 0,
        "selective": 4,
        "hip_knee_ankle": 8,
        "all_legs": 12,
        "legs_torso": 13,
        "all": 23,
        "reference_locked": 4,
    },
    "g1_29dof": {
        "absolute": 0,
        "selective": 4,
        "hip_knee_ankle": 8,
        "all_legs": 12,
        "legs_torso": 15,
        "all": 29,
        "reference_locked": 4,
    },
    "h1": {
        "absolute": 0,
        "selective": 4,
        "hip_knee_ankle": 6,
        "all_legs": 10,
        "legs_torso": 11,
        "all": 19,
        "reference_locked": 4,
    },
    "h1_2": {
        "absolute": 0,
        "selective": 4,
        "hip_knee_ankle": 8,
        "all_legs": 12,
        "legs_torso": 13,
        "all": 21,
        "reference_locked": 4,
    },
}


@pytest.mark.parametrize("robot_name", available_robots())
def test_every_preset_forms_residual_and_absolute_targets_per_joint(robot_name: str) -> None:
    robot = load_robot(robot_name)
    config = robot.config
    policy = config.policy_indices
    lower, upper = (torch.as_tensor(x[policy]) for x in robot.joint_range.T)
    default = torch.tensor(config.default_pos)[policy]
    reference = (lower + upper) / 2 + 0.05  # inside the limits, away from the default pose
    assert RESIDUAL_PRESETS == tuple(PRESET_RESIDUAL_JOINTS[robot_name])
    for preset, residual_count in PRESET_RESIDUAL_JOINTS[robot_name].items():
        semantics = joint_semantics(config, preset)
        residual = torch.tensor([kind == "residual" for kind in semantics])
        absolute = torch.tensor([kind == "absolute" for kind in semantics])
        assert int(residual.sum()) == residual_count, preset
        actions = ResidualActions(ActionConfig(mode=preset), semantics, default, lower, upper)
        # The action has the full policy dimension except in the reference-locked reading.
        assert actions.size == (residual_count if preset == "reference_locked" else len(policy)), preset
        a = torch.linspace(-0.4, 0.4, actions.size, dtype=torch.float64).repeat(2, 1)
        targets = actions.targets(a, reference.repeat(2, 1))
        expected = torch.where(absolute, default, reference).repeat(2, 1)
        expected[:, actions.outputs] += 0.25 * a
        expected = torch.clamp(expected, lower, upper)
        assert torch.allclose(targets, expected), preset
        if preset == "reference_locked":
            assert torch.equal(targets[:, ~residual], reference.repeat(2, 1)[:, ~residual])
    hip_pitch = config.policy_joints.index("left_hip_pitch_joint")
    elbow = config.policy_joints.index("left_elbow_joint")
    selective = joint_semantics(config, "selective")
    assert selective[hip_pitch] == "residual" and selective[elbow] == "absolute"


def test_actions_are_clipped_then_projected_to_the_limits() -> None:
    robot = load_robot("g1")
    config = robot.config
    lower, upper = (torch.as_tensor(x) for x in robot.joint_range.T)
    default = torch.tensor(config.default_pos)
    reference = default.repeat(2, 1)
    actions = torch.full((2, len(default)), 0.4, dtype=torch.float64)
    actions[1] = 1e6  # far beyond the clip
    semantics = joint_semantics(config, "all")
    everything = ResidualActions(ActionConfig(mode="all", clip=1.0), semantics, default, lower, upper)
    targets = everything.targets(actions, reference)
    assert torch.allclose(targets[1], torch.minimum(reference[1] + 0.25, upper))
    assert torch.all(targets <= upper) and torch.all(targets >= lower)


def test_pd_torque_is_clipped_inside_the_physics_loop() -> None:
    robot = load_robot("g1")
    model = simulation_model(robot)
    data = mujoco.MjData(model)
    data.qpos[2], data.qpos[3] = 2.0, 1.0  # in the air, so only the actuators act
    knee = robot.config.joint_names.index("left_knee_joint")
    data.ctrl[:] = robot.config.default_pos
    data.ctrl[knee] += 1.5  # kp 150 x 1.5 rad = 225 N m, above the 139 N m effort limit
    mujoco.mj_step(model, data)
    assert data.actuator_force[knee] == pytest.approx(robot.config.effort_limit[knee])
    elbow = robot.config.joint_names.index("left_elbow_joint")
    assert data.actuator_force[elbow] == pytest.approx(40.0 * 0.3)  # below its limit: plain kp x error (from q = 0)


def test_a_push_changes_only_the_pushed_base_velocity() -> None:
    model = simulation_model(load_robot("g1"))
    backend = MujocoCpuBackend([model, model], threads=1)
    qpos = np.tile(model.qpos0, (2, 1))
    qpos[:, 2] = 1.0
    backend.set_state(torch.arange(2), torch.from_numpy(qpos), torch.zeros(2, model.nv, dtype=torch.float64))
    backend.push(torch.tensor([1]), torch.tensor([[0.3, -0.2]], dtype=torch.float64))
    assert backend.datas[1].qvel[:3].tolist() == pytest.approx([0.3, -0.2, 0.0])
    assert not backend.datas[0].qvel.any()


def test_the_copied_rsl_rl_methods_match_the_installed_library() -> None:
    """`MultiHeadPPO` re-implements rsl-rl methods; a library update must be read before it is used."""
    import hashlib
    import inspect

    from rsl_rl.algorithms import PPO
    from rsl_rl.storage import RolloutStorage

    from rd_pipeline.training.ppo import UPSTREAM_SOURCES

    methods = {"PPO": PPO, "RolloutStorage": RolloutStorage}
    for name, digest in UPSTREAM_SOURCES.items():
        owner, method = name.split(".")
        source = inspect.getsource(getattr(methods[owner], method))
        assert hashlib.sha256(source.encode()).hexdigest() == digest, (
            f"rsl-rl-lib's {name} changed: compare it with rd_pipeline/training/ppo.py, then update UPSTREAM_SOURCES"
        )


def test_a_new_reward_term_is_one_registered_function_plus_its_field(monkeypatch: pytest.MonkeyPatch) -> None:
    # Registered for this test only: monkeypatch removes the entry afterwards.
    monkeypatch.setitem(reward_terms.REWARD_TERMS, "joint_pos_abs", reward_terms.REWARD_TERMS["joint_pos"])

    @reward_terms.reward_term("joint")
    def joint_pos_abs(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
        return (s.joint_pos - s.ref_joint_pos).abs().sum(-1)

    extended = dataclasses.make_dataclass(
        "Extended", [("joint_pos_abs", PenaltyTerm, PenaltyTerm(-1.0))], bases=(RewardsConfig,), frozen=True
    )
    joints = _state().joint_pos.clone()
    joints[:, 0] += 0.2
    groups, terms, _ = RewardManager(extended(), CONTEXT).compute(_state(joint_pos=joints), penalty_scale=0.8)
    assert terms["joint_pos_abs"].tolist() == pytest.approx([-0.2] * N)  # not a regularization term: unscaled
    plain, _, _ = MANAGER.compute(_state(joint_pos=joints), penalty_scale=0.8)
    joint = GROUPS.index("joint")
    assert torch.allclose(groups[:, joint] - plain[:, joint], torch.full((N,), -0.2, dtype=torch.float64))
    unregistered = dataclasses.make_dataclass(
        "Unregistered", [("joint_pos_sq", PenaltyTerm, PenaltyTerm(-1.0))], bases=(RewardsConfig,), frozen=True
    )
    with pytest.raises(KeyError, match="reward terms without a registered function: joint_pos_sq"):
        RewardManager(unregistered(), CONTEXT)


def test_an_episode_fails_when_any_termination_term_fires(monkeypatch: pytest.MonkeyPatch) -> None:
    config = TerminationsConfig()
    context = TerminationContext(config, root=0, bodies=torch.tensor([1, 2]), motion_far_m=0.5)
    on_reference = _state()
    assert terminations.failed(on_reference, context).tolist() == [False] * N
    far = on_reference.body_pos.clone()
    far[1, 2, 2] += 0.6  # env 1: a termination body 0.6 m above its reference
    assert terminations.failed(_state(body_pos=far), context).tolist() == [False, True, False]
    assert not terminations.failed(_state(body_pos=far), dataclasses.replace(context, motion_far_m=0.7)).any()
    aside = on_reference.body_pos.clone()
    aside[0, 1, 0] += 0.6  # env 0: a termination body 0.6 m beside its reference
    height_only = dataclasses.replace(context, config=TerminationsConfig(motion_far_height_only=True))
    assert terminations.failed(_state(body_pos=aside), context).tolist() == [True, False, False]
    assert terminations.failed(_state(body_pos=aside), height_only).tolist() == [False] * N
    assert terminations.failed(_state(body_pos=far), height_only).tolist() == [False, True, False]
    monkeypatch.setattr(terminations, "TERMINATION_TERMS", dict(terminations.TERMINATION_TERMS))

    @terminations.termination_term
    def joint_off(s: TrackingState, c: TerminationContext) -> torch.Tensor:
        return (s.joint_pos - s.ref_joint_pos).abs().amax(-1) > 0.1

    joints = on_reference.joint_pos.clone()
    joints[2, 0] += 0.2
    assert terminations.failed(_state(body_pos=far, joint_pos=joints), context).tolist() == [False, True, True]


def test_quaternion_product_and_rotation_vectors_match_scipy() -> None:
    from scipy.spatial.transform import Rotation

    from rd_pipeline.env import quat

    rotvec = np.random.default_rng(0).normal(size=(50, 3))
    rotvec[0] = 0.0  # the identity, where sin(x/2)/x needs its limit
    base = Rotation.random(50, random_state=1)
    base_wxyz = base.as_quat()[:, [3, 0, 1, 2]]
    mine = quat.multiply(quat.from_rotation_vector(torch.tensor(rotvec)), torch.tensor(base_wxyz)).numpy()
    expected = (Rotation.from_rotvec(rotvec) * base).as_quat()[:, [3, 0, 1, 2]]
    same_sign = np.sign((mine * expected).sum(1))[:, None]
    assert np.allclose(mine, same_sign * expected, atol=1e-12)


def test_a_reset_draws_the_push_timer_anew() -> None:
    """Pushes come 5-10 s into every episode; a timer carried over from a long episode would
    postpone them, and past the clip's length stop them."""
    env = h1_2_dance_env(EnvConfig(num_envs=6, threads=1))
    env.next_push[:] = 10_000
    env.reset(torch.arange(6))
    lo, hi = (round(seconds / env.step_dt) for seconds in env.config.randomization.push_interval_s)
    assert ((env.next_push >= lo) & (env.next_push <= hi)).all()
    assert env.next_push.unique().numel() > 1


def test_rsi_perturbs_the_root_angular_velocity_by_its_noise() -> None:
    env = h1_2_dance_env(EnvConfig(num_envs=1, threads=1))
    frames = torch.full((4000,), 600)
    model = env.backend.models[0]
    ref = env.command.ref
    args = (ref, frames, model.nq, model.nv, env.qpos_idx, env.dof_idx, env.joint_range)
    quiet = dataclasses.replace(env.config, rsi_root_rot_deg=0.0, rsi_root_vel=0.0)
    noisy = dataclasses.replace(quiet, rsi_root_vel=0.01)
    _, still = rsi_state(quiet, *args, torch.Generator().manual_seed(0))
    _, shaken = rsi_state(noisy, *args, torch.Generator().manual_seed(0))
    assert torch.equal(still[:, 3:6], still[:1, 3:6].expand(4000, 3))
    spread = (shaken[:, 3:6] - still[:, 3:6]).std(dim=0)
    assert torch.allclose(spread, torch.full((3,), 0.01, dtype=spread.dtype), rtol=0.1)


def _tiny_ppo(**changes) -> MultiHeadPPO:
    from tensordict import TensorDict

    torch.manual_seed(0)
    obs = TensorDict({"policy": torch.randn(8, 12), "critic": torch.randn(8, 15)}, batch_size=[8])
    return build_ppo(obs, 8, 5, 2, PpoConfig(steps_per_env=4, hidden_dims=(16, 16), **changes))


def test_a_small_output_gain_starts_near_zero_action_and_a_held_noise_std_stays() -> None:
    from tensordict import TensorDict

    obs = TensorDict({"policy": torch.randn(32, 12), "critic": torch.randn(32, 15)}, batch_size=[32])
    paper = _tiny_ppo()
    small = _tiny_ppo(init_output_gain=0.01, learn_noise_std=False, init_noise_std=0.05)
    paper_mean = paper.actor(obs, stochastic_output=False)
    small_mean = small.actor(obs, stochastic_output=False)
    # Same seed, same hidden layers: the output layer is the paper's times 0.01, without its bias.
    assert small_mean.abs().max() < 0.02 * paper_mean.abs().max()
    # A step of the optimizer on a loss through the std moves the learned std, not the held one.
    for ppo, learned in ((paper, True), (small, False)):
        actions = ppo.actor(obs, stochastic_output=True)
        before = ppo.actor.output_std.detach().clone()
        loss = -ppo.actor.get_output_log_prob(actions).mean() - ppo.actor.output_entropy.mean()
        ppo.optimizer.zero_grad()
        loss.backward()
        ppo.optimizer.step()
        ppo.actor(obs, stochastic_output=True)
        assert torch.equal(ppo.actor.output_std, before) != learned
