"""TD3 hyperparameters (FastTD3's recipe scaled to a CPU), kept apart from the algorithm so stage
params load without torch."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.params import ParamRangeError, require_at_most, require_positive


@dataclass(frozen=True)
class Td3Config:
    """Off-policy actor-critic with clipped double Q, n-step returns and many updates per sample."""

    steps_per_env: int = 4
    """Environment steps per environment between two rounds of updates (an iteration)."""
    updates_per_step: int = 2
    """Gradient updates per environment step of all environments."""
    batch_size: int = 256
    """Transitions per gradient update (FastTD3 takes 32,768 on a GPU beside thousands of
    environments; on a CPU core an update of 256 costs about what collecting its step does)."""
    buffer_size: int = 1_000_000
    """Replay capacity in transitions (the oldest are overwritten)."""
    learning_starts: int = 16
    """Environment steps collected before the first update."""
    gamma: float = 0.99
    """Discount."""
    n_step: int = 3
    """Rewards summed before bootstrapping (cut short where an episode ends)."""
    tau: float = 0.1
    """Soft-update rate of the target networks."""
    learning_rate: float = 3e-4
    """Adam's learning rate, actor and critics."""
    policy_delay: int = 2
    """Critic updates per actor and target update."""
    noise_std_min: float = 0.01
    """Smallest exploration-noise std; each environment draws its own std between this and
    `noise_std_max` at every reset (FastTD3's mixed noise)."""
    noise_std_max: float = 0.2
    """Largest exploration-noise std."""
    target_noise: float = 0.2
    """Std of the noise on the target policy's action (target policy smoothing)."""
    target_noise_clip: float = 0.5
    """That noise is clipped to +-this."""
    max_grad_norm: float = 1.0
    """Gradient-norm limit of every update."""
    hidden_dims: tuple[int, ...] = (512, 256, 128)
    """Actor MLP widths (ReLU); the exported policy has this shape."""
    critic_hidden_dims: tuple[int, ...] = (512, 256, 128)
    """Widths of each of the two Q networks (ReLU)."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "steps_per_env",
            "updates_per_step",
            "batch_size",
            "buffer_size",
            "learning_starts",
            "n_step",
            "tau",
            "learning_rate",
            "policy_delay",
            "noise_std_min",
            "noise_std_max",
            "target_noise",
            "target_noise_clip",
            "max_grad_norm",
        )
        require_at_most(self, 1.0, "gamma", "tau")
        if self.noise_std_min > self.noise_std_max:
            raise ParamRangeError(
                "noise_std_min", f"must be at most noise_std_max ({self.noise_std_max:g}), got {self.noise_std_min:g}"
            )
