"""The tracking environment: N robots following one reference motion, stepped by a physics backend.

Built like mjlab's manager-based tasks: actions, observations, rewards, terminations, curricula and
events are configured terms (`EnvConfig`), and `step` only wires them together. Simulation and
terms are batched torch on the configured device; episode bookkeeping (lengths, start segments,
pushes) stays on the host beside the random generator and the sampler, so a step reads only its done
flags back from the device. MuJoCo is only reached through the backend seam
(`rd_pipeline.env.physics`). Observations come in rsl-rl groups (`policy`, `critic`); rewards come
per group, one column per critic value head.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import torch
from tensordict import TensorDict

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp import curricula, events
from rd_pipeline.env.mdp.actions import ResidualActions, joint_semantics
from rd_pipeline.env.mdp.motion_command import MotionCommand
from rd_pipeline.env.mdp.observations import ActorInputs, CriticInputs, actor_frame, actor_terms, critic_observation
from rd_pipeline.env.mdp.reward_terms import TermContext, TrackingState
from rd_pipeline.env.mdp.rewards import AdaptiveSigma, RewardManager
from rd_pipeline.env.mdp.terminations import TerminationContext, failed
from rd_pipeline.env.physics import make_backend
from rd_pipeline.env.quat import rotate_inverse
from rd_pipeline.env.sim_model import SolverBudget, simulation_model
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.robots import Robot
from rd_pipeline.sampling.sampler import SegmentSampler

DTYPE = torch.float32


class TrackingEnv:
    """rsl-rl style vectorized env: `get_observations()`, `step(actions)`."""

    def __init__(
        self,
        robot: Robot,
        reference: ReferenceMotion,
        sampler: SegmentSampler,
        segment_starts: np.ndarray,
        segment_lengths: np.ndarray,
        config: EnvConfig,
        seed: int,
    ) -> None:
        self.robot = robot
        self.config = config
        self.num_envs = config.num_envs
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.step_dt = config.physics_dt * config.decimation
        self.control_hz = 1.0 / self.step_dt
        # One reference frame per control step: a reference at another rate would play too fast or slow.
        if not math.isclose(self.control_hz, reference.fps, rel_tol=1e-6):
            raise PipelineError(
                f"train.env: the control rate 1 / (physics_dt * decimation) = {self.control_hz:g} Hz "
                f"differs from the reference's {reference.fps:g} fps"
            )
        base = self._build_physics()
        self._index_model(base)
        tracked = list(robot.config.tracking_bodies)
        self.command = MotionCommand(
            reference,
            tracked,
            robot.config.root_body,
            sampler,
            segment_starts,
            segment_lengths,
            self.num_envs,
            self.tensor,
        )
        self._build_terms(tracked)
        self._build_buffers()
        self.reset(torch.arange(self.num_envs))  # every history starts full of its first frame

    @property
    def max_episode_length(self) -> int:
        """Frames of the reference: an episode ends at its last one."""
        return self.command.n_frames

    def tensor(self, values: object, dtype: torch.dtype = DTYPE) -> torch.Tensor:
        """`values` as a tensor on the simulation's device."""
        return torch.tensor(np.asarray(values), dtype=dtype, device=self.device)

    def _build_physics(self) -> mujoco.MjModel:
        """The backend over one randomized model per environment; returns the nominal model."""
        config = self.config
        sensors = config.backend == "rollout"
        solver = SolverBudget(config.solver_iterations, config.ls_iterations)
        base = simulation_model(self.robot, config.physics_dt, config.collision, sensors, solver)
        root = base.body(self.robot.config.root_body).id
        models, dr_params = events.randomized_models(base, self.num_envs, config.randomization, root, self.rng)
        self.backend = make_backend(config.backend, models, config.threads, config.device)
        self.device = self.backend.device
        self.dr_params = self.tensor(dr_params)
        effort = np.asarray(self.robot.config.effort_limit)
        rfi_factor = dr_params[:, events.DR_PARAMS.index("rfi_factor")]
        scale = events.random_joint_force_scale(config.randomization, rfi_factor, effort)
        self.joint_force_scale = self.tensor(scale, torch.float64)
        self.joint_force = torch.zeros(self.num_envs, base.nv, dtype=torch.float64, device=self.device)
        self.generator = torch.Generator(device=self.device).manual_seed(self.seed)
        """Draws the reset noise and the injected joint forces on the device."""
        self.delay = self.tensor(dr_params[:, events.DR_PARAMS.index("delay")], torch.long)
        return base

    def _index_model(self, base: mujoco.MjModel) -> None:
        """Where the configured joints and bodies sit in the model's state."""
        rc = self.robot.config
        index = lambda values: self.tensor(values, torch.long)
        self.policy_idx = index(rc.policy_indices)
        self.qpos_idx = index([base.jnt_qposadr[base.joint(j).id] for j in rc.joint_names])
        self.dof_idx = index([base.jnt_dofadr[base.joint(j).id] for j in rc.joint_names])
        self.joint_range = self.tensor(self.robot.joint_range, torch.float64)
        tracked = list(rc.tracking_bodies)
        self.sim_bodies = index([base.body(b).id for b in tracked])
        self.feet_sim = index([base.body(b).id for b in rc.foot_bodies])
        feet = set(self.feet_sim.tolist())
        self.undesired = index([b for b in range(1, base.nbody) if b not in feet])
        self.term_idx = index([tracked.index(b) for b in rc.termination_bodies])

    def _build_terms(self, tracked: list[str]) -> None:
        """Actions, actor observation layout, reward terms and the adaptive sigmas."""
        rc = self.robot.config
        config = self.config
        lower = self.tensor(self.robot.joint_range[:, 0])
        upper = self.tensor(self.robot.joint_range[:, 1])
        self.default_pos = self.tensor(rc.default_pos)
        p = self.policy_idx
        semantics = joint_semantics(rc, config.actions.mode)
        self.actions = ResidualActions(config.actions, semantics, self.default_pos[p], lower[p], upper[p])
        self.num_actions = self.actions.size
        self.actor_terms = actor_terms(len(rc.policy_joints), self.num_actions, config.observations)
        self.future_steps = config.observations.ref_future_steps
        self.term_context = TermContext(
            root=tracked.index(rc.root_body),
            feet=(tracked.index(rc.foot_bodies[0]), tracked.index(rc.foot_bodies[1])),
            keypoints=tuple(tracked.index(body) for body in rc.keypoint_bodies),
            joint_lower=lower[p],
            joint_upper=upper[p],
            velocity_limit=self.tensor(rc.velocity_limit)[p],
            effort_limit=self.tensor(rc.effort_limit),
        )
        self.rewards = RewardManager(config.rewards, self.term_context)
        sigmas = self.rewards.tracking_sigmas()
        self.sigma = AdaptiveSigma(config.curricula.adaptive_sigma_alpha, sigmas, self.device)

    def _build_buffers(self) -> None:
        """Per-environment state between steps. Episode bookkeeping lives on the host beside the
        random generator and the sampler: resets, pushes and curricula then read one transfer per
        step, the done flags."""
        n = self.num_envs
        config = self.config
        device = self.device
        self.episode_length_buf = torch.zeros(n, dtype=torch.long)
        self.action_history = torch.zeros(n, 3, self.num_actions, dtype=DTYPE, device=device)
        queue = config.randomization.max_delay_steps + 1
        joints = len(self.robot.config.joint_names)
        self.target_queue = torch.zeros(n, queue, joints, dtype=DTYPE, device=device)
        self.feet_air_time = torch.zeros(n, 2, dtype=DTYPE, device=device)
        self.next_push = torch.zeros(n, dtype=torch.long)  # drawn at each reset
        self.curriculum = curricula.initial_state(config.curricula, config.terminations)
        frame_size = sum(term.size for term in self.actor_terms)
        self.obs_frames = torch.zeros(n, config.history, frame_size, dtype=DTYPE, device=device)

    # -- reset -------------------------------------------------------------------------------
    def reset(self, env_ids: torch.Tensor, frames: torch.Tensor | None = None) -> None:
        """Reference state initialization, with the appendix noise, at `frames` or at a frame drawn
        from a segment the sampler picks."""
        if len(env_ids) == 0:
            return
        host_ids = env_ids.cpu()
        if frames is None:
            frames = self.command.sample_start_frames(len(host_ids), self.rng)
        else:
            frames = frames.cpu()
        model = self.backend.models[0]
        ref = self.command.ref
        qpos, qvel = events.rsi_state(
            self.config, ref, frames, model.nq, model.nv, self.qpos_idx, self.dof_idx, self.joint_range, self.generator
        )
        self.command.start(host_ids, frames)
        self.episode_length_buf[host_ids] = 0
        # Push timers count from each episode's start, or a long episode would postpone every later push.
        intervals = events.push_intervals(self.config.randomization, len(host_ids), self.step_dt, self.rng)
        self.next_push[host_ids] = torch.as_tensor(intervals)
        device_ids = host_ids.to(self.device)
        self.backend.set_state(device_ids, qpos, qvel)
        self.action_history[device_ids] = 0.0
        self.feet_air_time[device_ids] = 0.0
        self.target_queue[device_ids] = qpos[:, self.qpos_idx].to(DTYPE)[:, None]
        self.obs_frames[device_ids] = self._actor_frame()[device_ids, None]

    @property
    def sampler(self) -> SegmentSampler:
        return self.command.sampler

    # -- observations ------------------------------------------------------------------------
    def _state(self) -> dict[str, torch.Tensor]:
        s = self.backend.state
        quat = s.qpos[:, 3:7].to(DTYPE)
        return {
            "joint_pos": s.qpos[:, self.qpos_idx].to(DTYPE)[:, self.policy_idx],
            "joint_vel": s.qvel[:, self.dof_idx].to(DTYPE)[:, self.policy_idx],
            "root_quat": quat,
            "base_ang_vel": s.qvel[:, 3:6].to(DTYPE),  # free-joint angular velocity is in the body frame
            "base_lin_vel": rotate_inverse(quat, s.qvel[:, :3].to(DTYPE)),
        }

    def _actor_frame(self, st: dict[str, torch.Tensor] | None = None) -> torch.Tensor:
        """One actor frame from `st` (the current `_state()`, computed here when not given)."""
        st = self._state() if st is None else st
        next_frame = self.command.next_frame()
        future = self.command.frames_ahead(self.future_steps)
        inputs = ActorInputs(
            joint_pos=st["joint_pos"],
            joint_vel=st["joint_vel"],
            root_quat=st["root_quat"],
            base_ang_vel=st["base_ang_vel"],
            last_action=self.action_history[:, 0],
            ref_joint_pos_next=self.command.ref.joint_pos[next_frame][:, self.policy_idx],
            ref_joint_pos_future=self.command.ref.joint_pos[future][..., self.policy_idx].flatten(1),
            default_pos=self.default_pos[self.policy_idx],
        )
        return actor_frame(self.actor_terms, inputs)

    def get_observations(self) -> TensorDict:
        frame = self.command.frame
        inputs = CriticInputs(
            actor_frame=self.obs_frames[:, -1],
            base_lin_vel=self._state()["base_lin_vel"],
            ref_root_quat=self.command.ref.root_quat[frame],
            ref_body_pos=self.command.body_pos[frame],
            root=self.term_context.root,
            dr_params=self.dr_params,
        )
        critic = critic_observation(inputs)
        return TensorDict({"policy": self.obs_frames.flatten(1), "critic": critic}, batch_size=[self.num_envs])

    # -- step --------------------------------------------------------------------------------
    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        actions = actions.to(DTYPE)
        before_vel = self._state()["joint_vel"]
        self.backend.step(self._delayed_targets(actions), self.config.decimation, self._disturbances())
        self.command.advance()
        self.episode_length_buf += 1
        self.action_history = torch.roll(self.action_history, 1, dims=1)
        self.action_history[:, 0] = actions

        broken = self._scrub_nonfinite()
        current = self._state()
        state = self._tracking_state(current, actions, before_vel)
        terminated = failed(state, self._termination_context()) | broken
        state.terminated = terminated
        rewards, _, errors = self.rewards.compute(state, self.curriculum.penalty_scale, self.sigma.sigma())
        self.sigma.update(errors, valid=~broken)
        # Weights are per second, as in legged_gym: a step earns weight x dt. This keeps returns within
        # reach of PPO's clipped value loss (0.2 per update); at full scale the -200 termination
        # alone puts the values in the hundreds and the critic cannot follow.
        rewards = torch.where(broken[:, None], 0.0, rewards * self.step_dt)
        time_out = self.command.time_out()
        dones = terminated | time_out
        # The one read from the device per step (mjlab and Isaac Lab read their reset ids too).
        flags = torch.stack([terminated, time_out, broken]).cpu()
        done_ids = torch.nonzero(flags[:2].any(0)).flatten()
        lengths = self.episode_length_buf[done_ids]
        self.command.record_ends(done_ids, lengths, flags[0][done_ids])
        extras = {
            "time_outs": time_out & ~terminated,
            "episode_length": lengths.float(),
            "nonfinite": int(flags[2].sum()),
        }
        mean_length = float(lengths.float().mean()) if len(lengths) else 0.0
        curricula.update(self.curriculum, mean_length, len(lengths), self.config.curricula, self.config.terminations)
        self.obs_frames = torch.cat([self.obs_frames[:, 1:], self._actor_frame(current)[:, None]], dim=1)
        self.reset(done_ids)
        return self.get_observations(), rewards, dones, extras

    def _scrub_nonfinite(self) -> torch.Tensor:
        """(N,) True where the physics returned a non-finite value (a world that blew up). Such a
        world fails and resets this step; its values are zeroed first, so no NaN reaches the
        rewards, the observation normalizer or the adaptive sigmas. Finite worlds are untouched."""
        s = self.backend.state
        broken = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        for tensor in vars(s).values():
            broken |= ~torch.isfinite(tensor).flatten(1).all(1)
            torch.nan_to_num_(tensor, nan=0.0, posinf=0.0, neginf=0.0)
        return broken

    def _delayed_targets(self, actions: torch.Tensor) -> torch.Tensor:
        """(N, J) PD targets of this step's actions, through each environment's control delay."""
        reference_next = self.command.ref.joint_pos[self.command.next_frame()][:, self.policy_idx]
        targets = self.default_pos.repeat(self.num_envs, 1)  # joints outside the policy hold their default
        targets[:, self.policy_idx] = self.actions.targets(actions, reference_next)
        self.target_queue = torch.roll(self.target_queue, 1, dims=1)
        self.target_queue[:, 0] = targets
        return self.target_queue[torch.arange(self.num_envs, device=self.device), self.delay]

    def _disturbances(self) -> torch.Tensor | None:
        """Pushes that are due (applied to the backend) and this step's random joint forces."""
        r = self.config.randomization
        if not r.enabled:
            return None
        due = torch.nonzero(self.episode_length_buf >= self.next_push).flatten()
        if len(due):
            velocity = events.push_velocities(r, len(due), self.rng)
            self.backend.push(due.to(self.device), torch.as_tensor(velocity, device=self.device))
            intervals = events.push_intervals(r, len(due), self.step_dt, self.rng)
            self.next_push[due] = self.episode_length_buf[due] + torch.as_tensor(intervals)
        forces = events.random_joint_forces(self.joint_force_scale, self.generator)
        self.joint_force[:, self.dof_idx] = forces
        return self.joint_force

    def _tracking_state(
        self, st: dict[str, torch.Tensor], actions: torch.Tensor, before_vel: torch.Tensor
    ) -> TrackingState:
        s = self.backend.state
        command = self.command
        f = command.frame
        threshold = self.config.contact_threshold_n
        force = s.contact_force[:, self.feet_sim].to(DTYPE)
        contact = force[..., 2] > threshold
        touchdown_air_time = self.feet_air_time * (contact & (self.feet_air_time > 0))
        self.feet_air_time = torch.where(contact, 0.0, self.feet_air_time + self.step_dt)
        body_vel = s.body_vel[:, self.sim_bodies].to(DTYPE)
        feet_vel = s.body_vel[:, self.feet_sim].to(DTYPE)
        touching = s.contact_force[:, self.undesired].to(DTYPE).norm(dim=-1) > threshold
        return TrackingState(
            body_pos=s.body_pos[:, self.sim_bodies].to(DTYPE),
            body_quat=s.body_quat[:, self.sim_bodies].to(DTYPE),
            body_lin_vel=body_vel[..., 3:],
            body_ang_vel=body_vel[..., :3],
            joint_pos=st["joint_pos"],
            joint_vel=st["joint_vel"],
            ref_body_pos=command.body_pos[f],
            ref_body_quat=command.body_quat[f],
            ref_body_lin_vel=command.body_lin_vel[f],
            ref_body_ang_vel=command.body_ang_vel[f],
            ref_joint_pos=command.ref.joint_pos[f][:, self.policy_idx],
            ref_joint_vel=command.ref.joint_vel[f][:, self.policy_idx],
            feet_contact=contact,
            ref_feet_contact=command.contact[f],
            feet_air_time=touchdown_air_time,
            feet_force=force,
            feet_speed=feet_vel[..., 3:5].norm(dim=-1),
            torque=s.actuator_force.to(DTYPE),
            joint_acc=(st["joint_vel"] - before_vel) / self.step_dt,
            action=actions,
            last_action=self.action_history[:, 1],
            second_last_action=self.action_history[:, 2],
            undesired_contacts=touching.sum(-1).to(DTYPE),
            terminated=torch.zeros(self.num_envs, dtype=torch.bool, device=self.device),
        )

    def _termination_context(self) -> TerminationContext:
        return TerminationContext(
            self.config.terminations, self.term_context.root, self.term_idx, self.curriculum.motion_far_m
        )

    # -- checkpoints -------------------------------------------------------------------------
    def state_dict(self) -> dict:
        """Everything a resumed run needs to continue exactly: physics states, buffers, curricula, RNG."""
        return {
            "physics": self.backend.get_states(),
            "frame": self.command.frame.clone(),
            "start_frame": self.command.start_frame.clone(),
            "episode_length": self.episode_length_buf.clone(),
            "action_history": self.action_history.clone(),
            "target_queue": self.target_queue.clone(),
            "next_push": self.next_push.clone(),
            "obs_frames": self.obs_frames.clone(),
            "motion_far": self.curriculum.motion_far_m,
            "penalty_scale": self.curriculum.penalty_scale,
            "rng": self.rng.bit_generator.state,
            "device_rng": self.generator.get_state(),
            "feet_air_time": self.feet_air_time.clone(),
            "sigma_variance": self.sigma.state_dict(),
        }

    def load_state_dict(self, state: dict) -> None:
        device = lambda name: state[name].to(self.device).clone()
        host = lambda name: state[name].cpu().clone()
        self.backend.set_states(state["physics"])
        self.command.frame = device("frame")
        self.command.start_frame = host("start_frame")
        self.episode_length_buf = host("episode_length")
        self.action_history = device("action_history")
        self.target_queue = device("target_queue")
        self.next_push = host("next_push")
        self.obs_frames = device("obs_frames")
        self.feet_air_time = device("feet_air_time")
        self.curriculum = curricula.CurriculumState(state["motion_far"], state["penalty_scale"])
        self.sigma.load_state_dict(state["sigma_variance"])
        self.rng.bit_generator.state = state["rng"]
        self.generator.set_state(state["device_rng"])

    def close(self) -> None:
        self.backend.close()
