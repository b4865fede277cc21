"""The tracking environment: N robots following one reference motion, stepped by a physics backend.

Everything here is batched torch over environments; MuJoCo is only reached through the backend
seam (`rd_pipeline.rl.backend`). Observations come in rsl-rl groups (`policy`, `critic`); rewards
come per group, one column per critic value head.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from tensordict import TensorDict

from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.rl.actions import ResidualActions
from rd_pipeline.rl.backend import make_backend
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.rl.observations import actor_terms
from rd_pipeline.rl.quat import projected_gravity, rotate_inverse
from rd_pipeline.rl.rewards import AdaptiveSigma, RewardIndices, RewardLimits, TrackingState, compute_rewards
from rd_pipeline.rl.sim_model import randomized_copy, simulation_model
from rd_pipeline.robots import Robot
from rd_pipeline.sampling.sampler import SegmentSampler

DTYPE = torch.float32


class TrackingEnv:
    """rsl-rl style vectorized env: `get_observations()`, `step(actions)`."""

    def __init__(self, robot: Robot, reference: ReferenceMotion, sampler: SegmentSampler,
                 segment_starts: np.ndarray, segment_lengths: np.ndarray, config: EnvConfig, seed: int) -> None:
        self.robot, self.config, self.sampler = robot, config, sampler
        self.num_envs, self.device = config.num_envs, "cpu"
        self.rng = np.random.default_rng(seed)
        self.segment_starts, self.segment_lengths = segment_starts, segment_lengths
        rc = robot.config
        self.policy_idx = torch.as_tensor(rc.policy_indices)
        self.max_episode_length = reference.n_frames
        self.step_dt = config.physics_dt * config.decimation

        base = simulation_model(robot, config.physics_dt)
        self.dr_params = np.zeros((self.num_envs, 9))  # mass, friction, kp, kd, com xyz, delay, rfi factor
        models = [self._randomized(base, i) for i in range(self.num_envs)]
        self.backend = make_backend(config.backend, models, config.threads)
        self.qpos_idx = np.array([base.jnt_qposadr[base.joint(j).id] for j in rc.joint_names])
        self.dof_idx = np.array([base.jnt_dofadr[base.joint(j).id] for j in rc.joint_names])

        tracked = list(rc.tracking_bodies)
        self.sim_bodies = np.array([base.body(b).id for b in tracked])
        ref_bodies = [reference.body_names.index(b) for b in tracked]
        self.feet_sim = np.array([base.body(b).id for b in rc.foot_bodies])
        self.term_idx = torch.as_tensor([tracked.index(b) for b in rc.termination_bodies])
        foot_ids = set(self.feet_sim.tolist())
        self.undesired = np.array([b for b in range(1, base.nbody) if b not in foot_ids])
        self.indices = RewardIndices(
            root=tracked.index(rc.root_body), feet=(tracked.index(rc.foot_bodies[0]), tracked.index(rc.foot_bodies[1])),
            keypoints=tuple(i for i, b in enumerate(tracked) if b not in rc.foot_bodies)[-3:],
        )
        # Reference tensors.
        t = lambda x: torch.as_tensor(np.asarray(x), dtype=DTYPE)
        self.ref_joint_pos, self.ref_joint_vel = t(reference.joint_pos), t(reference.joint_vel)
        self.ref_root_pos, self.ref_root_quat = t(reference.root_pos), t(reference.root_quat)
        self.ref_body_pos, self.ref_body_quat = t(reference.body_pos_w[:, ref_bodies]), t(reference.body_quat_w[:, ref_bodies])
        self.ref_body_lin_vel = t(reference.body_lin_vel_w[:, ref_bodies])
        self.ref_body_ang_vel = t(reference.body_ang_vel_w[:, ref_bodies])
        self.ref_contact = torch.as_tensor(reference.foot_contact)
        root = reference.body_names.index(rc.root_body)
        self.ref_root_lin_vel, self.ref_root_ang_vel = t(reference.body_lin_vel_w[:, root]), t(reference.body_ang_vel_w[:, root])

        lower, upper = (torch.tensor(x, dtype=DTYPE) for x in robot.joint_range.T)
        self.default_pos = torch.tensor(rc.default_pos, dtype=DTYPE)
        mask = torch.zeros(len(rc.policy_joints), dtype=torch.bool)
        mask[list(rc.residual_indices)] = True
        p = self.policy_idx
        self.actions = ResidualActions(config.actions, mask, self.default_pos[p], lower[p], upper[p])
        self.num_actions = self.actions.size
        self.actor_terms = actor_terms(len(rc.policy_joints), self.num_actions)
        self.sigma = AdaptiveSigma(config.adaptive_sigma_alpha)
        middle, half = (upper + lower) / 2, (upper - lower) / 2
        self.limits = RewardLimits(
            joint_lower=(middle - 0.9 * half)[p], joint_upper=(middle + 0.9 * half)[p],
            joint_velocity=0.9 * torch.tensor(rc.velocity_limit, dtype=DTYPE)[p],
            torque=0.85 * torch.tensor(rc.effort_limit, dtype=DTYPE),
        )

        n, a = self.num_envs, self.num_actions
        self.frame = torch.zeros(n, dtype=torch.long)
        self.start_segment = torch.zeros(n, dtype=torch.long)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long)
        self.action_history = torch.zeros(n, 3, a, dtype=DTYPE)
        self.delay = torch.as_tensor(self.dr_params[:, 7], dtype=torch.long)
        self.target_queue = torch.zeros(n, config.randomization.max_delay_steps + 1, len(rc.joint_names), dtype=DTYPE)
        self.feet_air_time = torch.zeros(n, 2, dtype=DTYPE)
        self.next_push = torch.as_tensor(self._push_times(n))
        self.motion_far = config.motion_far_init_m
        self.penalty_scale = config.penalty_scale[0]
        self.obs_frames: torch.Tensor | None = None
        self.reset(torch.arange(n))
        self.get_observations()  # fills the observation history

    # -- setup -------------------------------------------------------------------------------
    def _randomized(self, base, i: int):
        r = self.config.randomization
        if not r.enabled:
            self.dr_params[i] = [1, 1, 1, 1, 0, 0, 0, 0, 1]
            return copy.copy(base)
        u = self.rng.uniform
        mass, friction, kp, kd = u(*r.mass_factor), u(*r.friction_factor), u(*r.pd_factor), u(*r.pd_factor)
        com = u(-r.com_offset_m, r.com_offset_m, size=3)
        delay, rfi = self.rng.integers(0, r.max_delay_steps + 1), u(*r.torque_rfi_factor)
        self.dr_params[i] = [mass, friction, kp, kd, *com, delay, rfi]
        return randomized_copy(base, mass, friction, kp, kd, base.body(self.robot.config.root_body).id, com)

    def _push_times(self, count: int) -> np.ndarray:
        lo, hi = self.config.randomization.push_interval_s
        return np.round(self.rng.uniform(lo, hi, size=count) / self.step_dt).astype(np.int64)

    # -- reset -------------------------------------------------------------------------------
    def reset(self, env_ids: torch.Tensor, frames: torch.Tensor | None = None) -> None:
        """Reference state initialization, with the appendix noise, at `frames` or at a frame drawn
        from a segment the sampler picks."""
        if len(env_ids) == 0:
            return
        c, k = self.config, len(env_ids)
        if frames is None:
            segments = self.sampler.sample(k)
            offsets = torch.as_tensor(self.rng.random(k)) * torch.as_tensor(self.segment_lengths)[segments]
            frames = (torch.as_tensor(self.segment_starts)[segments] + offsets.long()).clamp(max=self.max_episode_length - 2)
        else:
            starts = torch.as_tensor(self.segment_starts)
            segments = (torch.searchsorted(starts, frames, right=True) - 1).clamp(min=0)
        model = self.backend.models[0]
        qpos, qvel = np.zeros((k, model.nq)), np.zeros((k, model.nv))
        f = frames.numpy()
        qpos[:, :3] = self.ref_root_pos[f].numpy() + self.rng.normal(0, c.rsi_root_pos_m, (k, 3)) * [1, 1, 0]
        qpos[:, 3:7] = _perturb_quat(self.ref_root_quat[f].numpy(), np.radians(c.rsi_root_rot_deg), self.rng)
        qpos[:, self.qpos_idx] = self.ref_joint_pos[f].numpy() + self.rng.uniform(-c.rsi_joint_pos, c.rsi_joint_pos, (k, len(self.qpos_idx)))
        qvel[:, :3] = self.ref_root_lin_vel[f].numpy() + self.rng.normal(0, c.rsi_root_vel, (k, 3))
        qvel[:, 3:6] = rotate_inverse(torch.as_tensor(qpos[:, 3:7], dtype=DTYPE), self.ref_root_ang_vel[f]).numpy()
        qvel[:, self.dof_idx] = self.ref_joint_vel[f].numpy() + self.rng.uniform(-c.rsi_joint_vel, c.rsi_joint_vel, (k, len(self.dof_idx)))
        lower, upper = self.robot.joint_range.T
        qpos[:, self.qpos_idx] = np.clip(qpos[:, self.qpos_idx], lower, upper)
        self.backend.set_state(env_ids.numpy(), qpos, qvel)
        self.frame[env_ids] = frames
        self.start_segment[env_ids] = segments
        self.episode_length_buf[env_ids] = 0
        self.action_history[env_ids] = 0.0
        self.feet_air_time[env_ids] = 0.0
        self.target_queue[env_ids] = torch.as_tensor(qpos[:, self.qpos_idx], dtype=DTYPE)[:, None]
        if self.obs_frames is not None:
            self.obs_frames[env_ids] = self._actor_frame()[env_ids, None]

    # -- observations ------------------------------------------------------------------------
    def _state(self) -> dict[str, torch.Tensor]:
        s = self.backend.state
        t = lambda x: torch.as_tensor(x, dtype=DTYPE)
        quat = t(s.qpos[:, 3:7])
        return {
            "joint_pos": t(s.qpos[:, self.qpos_idx])[:, self.policy_idx],
            "joint_vel": t(s.qvel[:, self.dof_idx])[:, self.policy_idx],
            "root_quat": quat,
            "base_ang_vel": t(s.qvel[:, 3:6]),  # free-joint angular velocity is in the body frame
            "base_lin_vel": rotate_inverse(quat, t(s.qvel[:, :3])),
        }

    def _actor_frame(self, st: dict[str, torch.Tensor] | None = None) -> torch.Tensor:
        """One actor frame from `st` (the current `_state()`, computed here when not given)."""
        st = self._state() if st is None else st
        next_frame = (self.frame + 1).clamp(max=self.max_episode_length - 1)
        values = {
            "joint_pos": st["joint_pos"] - self.default_pos[self.policy_idx], "joint_vel": st["joint_vel"],
            "projected_gravity": projected_gravity(st["root_quat"]), "base_ang_vel": st["base_ang_vel"],
            "last_action": self.action_history[:, 0], "ref_joint_pos_next": self.ref_joint_pos[next_frame][:, self.policy_idx],
        }
        return torch.cat([term.scale * values[term.name] for term in self.actor_terms], dim=-1)

    def get_observations(self) -> TensorDict:
        if self.obs_frames is None:
            frame = self._actor_frame()
            self.obs_frames = frame[:, None].repeat(1, self.config.history, 1)
        st = self._state()
        root = self.indices.root
        ref = self.ref_body_pos[self.frame]
        ref_rel = rotate_inverse(self.ref_root_quat[self.frame][:, None], ref - ref[:, root : root + 1])
        critic = torch.cat([self.obs_frames[:, -1], st["base_lin_vel"], ref_rel.flatten(1),
                            torch.as_tensor(self.dr_params, dtype=DTYPE)], dim=-1)
        return TensorDict({"policy": self.obs_frames.flatten(1), "critic": critic}, batch_size=[self.num_envs])

    # -- step --------------------------------------------------------------------------------
    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        n, r = self.num_envs, self.config.randomization
        actions = actions.to(DTYPE)
        next_frame = (self.frame + 1).clamp(max=self.max_episode_length - 1)
        ref_next = self.ref_joint_pos[next_frame]
        targets = self.default_pos.repeat(n, 1)  # joints outside the policy hold their default
        targets[:, self.policy_idx] = self.actions.targets(actions, ref_next[:, self.policy_idx])
        self.target_queue = torch.roll(self.target_queue, 1, dims=1)
        self.target_queue[:, 0] = targets
        ctrl = self.target_queue[torch.arange(n), self.delay]
        joint_force = None
        if r.enabled:
            self._push()
            # Random force injection: 0.1 x factor x effort limit, redrawn every control step.
            scale = r.torque_rfi * self.dr_params[:, 8:9] * self.robot.config.effort_limit
            joint_force = np.zeros((n, self.backend.models[0].nv))
            joint_force[:, self.dof_idx] = scale * self.rng.uniform(-1.0, 1.0, scale.shape)
        before_vel = self._state()["joint_vel"]
        self.backend.step(ctrl.numpy().astype(np.float64), self.config.decimation, joint_force)
        self.frame = next_frame
        self.episode_length_buf += 1
        self.action_history = torch.roll(self.action_history, 1, dims=1)
        self.action_history[:, 0] = actions

        current = self._state()
        state = self._tracking_state(current, actions, before_vel)
        terminated = self._failed(state)
        state.terminated = terminated
        rewards, terms, errors = compute_rewards(state, self.indices, self.limits, self.penalty_scale, self.sigma.sigma())
        self.sigma.update(errors)
        # Weights are per second, as in legged_gym: a step earns weight x dt. This keeps returns within
        # reach of PPO's clipped value loss (0.2 per update); at full scale the -200 termination
        # alone puts the values in the hundreds and the critic cannot follow.
        rewards = rewards * self.step_dt
        time_out = self.frame >= self.max_episode_length - 1
        dones = terminated | time_out
        done_ids = torch.nonzero(dones).flatten()
        self.sampler.record(self.start_segment[done_ids], terminated[done_ids])
        self.sampler.advance(1)
        extras = {"time_outs": time_out & ~terminated, "log": {f"reward/{k}": v.mean().item() for k, v in terms.items()},
                  "episode_length": self.episode_length_buf[done_ids].float()}
        self._update_curricula(self.episode_length_buf[done_ids])
        frame = self._actor_frame(current)
        self.obs_frames = torch.cat([self.obs_frames[:, 1:], frame[:, None]], dim=1)
        self.reset(done_ids)
        return self.get_observations(), rewards, dones, extras

    def _push(self) -> None:
        due = torch.nonzero(self.episode_length_buf >= torch.as_tensor(self.next_push)).flatten().numpy()
        if len(due) == 0:
            return
        speed = self.config.randomization.push_max_speed
        self.backend.push(due, self.rng.uniform(-speed, speed, (len(due), 2)))
        self.next_push = self.next_push.clone()
        self.next_push[due] = torch.as_tensor(self.episode_length_buf[due].numpy() + self._push_times(len(due)))

    def _tracking_state(self, st: dict[str, torch.Tensor], actions: torch.Tensor,
                        before_vel: torch.Tensor) -> TrackingState:
        s = self.backend.state
        t = lambda x: torch.as_tensor(x, dtype=DTYPE)
        f = self.frame
        force = t(s.contact_force[:, self.feet_sim])
        contact = force[..., 2] > 1.0
        touchdown_air_time = self.feet_air_time * (contact & (self.feet_air_time > 0))
        self.feet_air_time = torch.where(contact, 0.0, self.feet_air_time + self.step_dt)
        body_vel = t(s.body_vel[:, self.sim_bodies])
        feet_vel = t(s.body_vel[:, self.feet_sim])
        return TrackingState(
            body_pos=t(s.body_pos[:, self.sim_bodies]), body_quat=t(s.body_quat[:, self.sim_bodies]),
            body_lin_vel=body_vel[..., 3:], body_ang_vel=body_vel[..., :3],
            joint_pos=st["joint_pos"], joint_vel=st["joint_vel"],
            ref_body_pos=self.ref_body_pos[f], ref_body_quat=self.ref_body_quat[f],
            ref_body_lin_vel=self.ref_body_lin_vel[f], ref_body_ang_vel=self.ref_body_ang_vel[f],
            ref_joint_pos=self.ref_joint_pos[f][:, self.policy_idx], ref_joint_vel=self.ref_joint_vel[f][:, self.policy_idx],
            feet_contact=contact, ref_feet_contact=self.ref_contact[f], feet_air_time=touchdown_air_time,
            feet_force=force, feet_speed=feet_vel[..., 3:5].norm(dim=-1), torque=t(s.actuator_force),
            joint_acc=(st["joint_vel"] - before_vel) / self.step_dt, action=actions,
            last_action=self.action_history[:, 1], second_last_action=self.action_history[:, 2],
            undesired_contacts=(t(s.contact_force[:, self.undesired]).norm(dim=-1) > 1.0).sum(-1).to(DTYPE),
            terminated=torch.zeros(self.num_envs, dtype=torch.bool),
        )

    def _failed(self, state: TrackingState) -> torch.Tensor:
        """Motion far (a termination body too far from its reference) or root tilt error."""
        gap = (state.body_pos - state.ref_body_pos)[:, self.term_idx].norm(dim=-1).max(dim=-1).values
        root = self.indices.root
        tilt = torch.acos((projected_gravity(state.body_quat[:, root]) * projected_gravity(state.ref_body_quat[:, root]))
                          .sum(-1).clamp(-1.0, 1.0))
        return (gap > self.motion_far) | (tilt > self.config.orientation_limit_rad)

    def _update_curricula(self, lengths: torch.Tensor) -> None:
        if len(lengths) == 0:
            return
        c, mean = self.config, float(lengths.float().mean())
        down, up = c.curriculum_down_up
        step = c.curriculum_degree * len(lengths)
        if mean < down:
            self.motion_far = min(c.motion_far_max_m, self.motion_far + step)
            self.penalty_scale = max(c.penalty_scale[1], self.penalty_scale - step)
        elif mean > up:
            self.motion_far = max(c.motion_far_min_m, self.motion_far - step)
            self.penalty_scale = min(c.penalty_scale[2], self.penalty_scale + step)

    def state_dict(self) -> dict:
        """Everything a resumed run needs to continue exactly: physics states, buffers, curricula, RNG."""
        return {
            "physics": self.backend.get_states(), "frame": self.frame.clone(), "start_segment": self.start_segment.clone(),
            "episode_length": self.episode_length_buf.clone(), "action_history": self.action_history.clone(),
            "target_queue": self.target_queue.clone(),
            "next_push": self.next_push.clone(), "obs_frames": self.obs_frames.clone(), "motion_far": self.motion_far,
            "penalty_scale": self.penalty_scale, "rng": self.rng.bit_generator.state,
            "feet_air_time": self.feet_air_time.clone(), "sigma_variance": dict(self.sigma.variance),
        }

    def load_state_dict(self, state: dict) -> None:
        self.backend.set_states(state["physics"])
        self.frame, self.start_segment = state["frame"].clone(), state["start_segment"].clone()
        self.episode_length_buf, self.action_history = state["episode_length"].clone(), state["action_history"].clone()
        self.target_queue = state["target_queue"].clone()
        self.next_push, self.obs_frames = state["next_push"].clone(), state["obs_frames"].clone()
        self.motion_far, self.penalty_scale = state["motion_far"], state["penalty_scale"]
        self.feet_air_time, self.sigma.variance = state["feet_air_time"].clone(), dict(state["sigma_variance"])
        self.rng.bit_generator.state = state["rng"]

    def close(self) -> None:
        self.backend.close()


def _perturb_quat(quat_wxyz: np.ndarray, max_angle: float, rng: np.random.Generator) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    noise = Rotation.from_rotvec(rng.normal(size=(len(quat_wxyz), 3)) * max_angle / np.sqrt(3))
    base = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]])
    return (noise * base).as_quat()[:, [3, 0, 1, 2]]
