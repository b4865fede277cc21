"""What a randomized rollout meets besides its randomized model: control delay, pushes, random
joint forces and sensor noise, drawn per rollout from one seed with the training terms' own draws
(`rl/events.py`), so validation randomizes as the paper's training does."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rd_pipeline.env.mdp import events
from rd_pipeline.evaluation.protocol import RandomizedProtocol


@dataclass(frozen=True)
class RandomizedPhysics:
    """What one seed draws for R rollouts: their models and the delays and force scales they keep."""

    models: list[mujoco.MjModel]
    """(R) models, cycling through a pool of `RandomizedProtocol.models_per_seed` randomized copies
    (a copy of a mesh model costs a tenth of a second)."""
    delay: np.ndarray
    """(R,) control steps each rollout's PD targets arrive late."""
    force_scale: np.ndarray
    """(R, actuated) largest random force on each actuated joint."""

    @classmethod
    def draw(
        cls,
        model: mujoco.MjModel,
        count: int,
        root_body: int,
        effort_limit: np.ndarray,
        protocol: RandomizedProtocol,
        seed: int,
    ) -> RandomizedPhysics:
        rng = np.random.default_rng((seed, 0))
        ranges = protocol.ranges
        pool, _ = events.randomized_models(model, protocol.models_per_seed, ranges, root_body, rng)
        rfi = rng.uniform(*ranges.torque_rfi_factor, size=count)
        return cls(
            models=[pool[k % len(pool)] for k in range(count)],
            delay=rng.integers(0, ranges.max_delay_steps + 1, size=count),
            force_scale=events.random_joint_force_scale(ranges, rfi, effort_limit),
        )


@dataclass
class Disturbances:
    """What R rollouts side by side meet while they run; call `delayed`, `push_due` and
    `joint_force` once per control step, in that order, so a seed gives the same draws."""

    protocol: RandomizedProtocol
    physics: RandomizedPhysics
    rng: np.random.Generator
    dof_idx: np.ndarray
    """qvel address of each actuated joint."""
    control_dt: float
    next_push: np.ndarray
    """(R,) control step of each rollout's next push."""
    step: int = 0
    queue: np.ndarray | None = None
    """(R, max delay + 1, actuated) the latest PD targets, newest first."""

    @classmethod
    def start(
        cls,
        physics: RandomizedPhysics,
        actuated: list[str],
        control_dt: float,
        protocol: RandomizedProtocol,
        seed: int,
    ) -> Disturbances:
        """The disturbances of a run on `physics`: the same for every controller run with `seed`."""
        rng = np.random.default_rng((seed, 1))
        model = physics.models[0]
        count = len(physics.models)
        return cls(
            protocol=protocol,
            physics=physics,
            rng=rng,
            dof_idx=np.array([model.jnt_dofadr[model.joint(j).id] for j in actuated]),
            control_dt=control_dt,
            next_push=events.push_intervals(protocol.ranges, count, control_dt, rng),
        )

    def delayed(self, ctrl: np.ndarray) -> np.ndarray:
        """(R, actuated) the targets each rollout's delay lets through this step."""
        if self.queue is None:
            # Before the first step the motors hold the first targets.
            depth = self.protocol.ranges.max_delay_steps + 1
            self.queue = np.repeat(ctrl[:, None], depth, axis=1)
        self.queue = np.roll(self.queue, 1, axis=1)
        self.queue[:, 0] = ctrl
        return self.queue[np.arange(len(ctrl)), self.physics.delay]

    def push_due(self) -> tuple[np.ndarray, np.ndarray]:
        """(k,) rollouts pushed this step and (k, 2) their horizontal velocity changes."""
        due = np.flatnonzero(self.step >= self.next_push)
        ranges = self.protocol.ranges
        velocity = events.push_velocities(ranges, len(due), self.rng)
        self.next_push[due] = self.step + events.push_intervals(ranges, len(due), self.control_dt, self.rng)
        return due, velocity

    def joint_force(self, nv: int) -> np.ndarray:
        """(R, nv) this step's random force injection on the actuated joints; advances the step."""
        scale = self.physics.force_scale
        forces = np.zeros((len(scale), nv))
        forces[:, self.dof_idx] = scale * self.rng.uniform(-1.0, 1.0, scale.shape)
        self.step += 1
        return forces

    def observe(self, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The sensor terms of one observation frame with uniform noise added."""
        noise = self.protocol.observation_noise
        out = dict(values)
        for name in ("joint_pos", "joint_vel", "projected_gravity", "base_ang_vel"):
            bound = getattr(noise, name)
            out[name] = values[name] + self.rng.uniform(-bound, bound, values[name].shape)
        return out
