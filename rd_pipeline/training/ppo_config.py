"""PPO hyperparameters (the paper's appendix), kept apart from the algorithm so stage params load without torch."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.params import require_at_most, require_positive


@dataclass(frozen=True)
class PpoConfig:
    """Appendix "PPO, Network, and Training Parameters"."""

    steps_per_env: int = 24
    """Rollout length per environment."""
    learning_epochs: int = 5
    """Epochs per update."""
    mini_batches: int = 4
    """Mini-batches per epoch."""
    clip: float = 0.2
    """PPO clip."""
    gamma: float = 0.99
    """Discount."""
    lam: float = 0.95
    """GAE lambda."""
    value_loss_coef: float = 1.0
    """Value-loss coefficient."""
    entropy_coef: float = 0.01
    """Entropy coefficient."""
    learning_rate: float = 1e-3
    """Initial learning rate (adaptive schedule)."""
    max_grad_norm: float = 1.0
    """Gradient-norm limit."""
    desired_kl: float = 0.01
    """Target KL of the adaptive schedule."""
    init_noise_std: float = 0.894
    """Initial action-noise std (variance 0.8)."""
    learn_noise_std: bool = True
    """Whether the action-noise std is learned (the paper) or held at `init_noise_std` (MimicKit's
    G1 tracker holds 0.05)."""
    init_output_gain: float = 1.0
    """Factor on the actor's output layer at initialization, its bias zeroed unless 1: near 0 the
    untrained residual policy starts at zero action, the reference's own controller (MimicKit
    starts its output layer at scale 0.01)."""
    hidden_dims: tuple[int, ...] = (512, 256, 128)
    """Actor and critic MLP widths (ReLU)."""
    mixed_precision: bool = False
    """bf16 autocast in the update's forward passes (rsl-rl's `use_mixed_precision`): about twice
    as fast an update on CPUs with AVX512-BF16 or AMX and on recent GPUs; the paper trains in fp32."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "steps_per_env",
            "learning_epochs",
            "mini_batches",
            "clip",
            "learning_rate",
            "max_grad_norm",
            "desired_kl",
            "init_noise_std",
            "init_output_gain",
        )
        require_at_most(self, 1.0, "gamma", "lam")
