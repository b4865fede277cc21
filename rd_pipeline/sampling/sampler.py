"""The bounded-mixture segment sampler (paper, Sec. Motion Sampling Strategy), vectorized in torch.

    p = Norm[clip(lu * p_uni + ld(t) * p_bal + lf(t) * p_fail, 0, p_max)]
    r_s <- (1 - alpha) r_s + alpha f_s,   p_fail ~ (r_s + eps)^beta

The cap is enforced after normalization by water-filling: mass above `p_max` is handed to the
uncapped segments in proportion to their weight, until no segment exceeds the cap.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, get_args

from rd_pipeline.lazy import lazy_import
from rd_pipeline.params import ParamRangeError, require_at_most, require_positive

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


SamplerMode = Literal["uniform", "distribution", "failure", "combined"]
MODES: tuple[str, ...] = get_args(SamplerMode)

FailureCredit = Literal["start", "visited"]


@dataclass(frozen=True)
class SamplerConfig:
    """The appendix values by default."""

    mode: SamplerMode = "combined"
    """`uniform`, `distribution` (uniform floor + balanced prior), `failure` (floor + failure prior) or `combined`."""
    uniform_weight: float = 0.3
    """lambda_u, the uniform exploration floor."""
    failure_weight_start: float = 0.4
    """lambda_f before the hand-off."""
    failure_weight_end: float = 0.55
    """lambda_f after the ramp."""
    distribution_weight_start: float = 0.2
    """lambda_d before the hand-off."""
    distribution_weight_end: float = 0.05
    """lambda_d after the ramp."""
    ramp_start_steps: int = 48_000
    """Steps before the (lambda_f, lambda_d) hand-off starts."""
    ramp_steps: int = 48_000
    """Steps the hand-off takes."""
    ema_alpha: float = 0.05
    """Failure EMA rate alpha."""
    epsilon: float = 1e-3
    """epsilon in p_fail ~ (r + epsilon)^beta."""
    beta: float = 2.0
    """Prioritization strength beta."""
    update_interval: int = 100
    """Steps between failure-statistics updates."""
    failure_credit: FailureCredit = "start"
    """Which segments a finished episode counts for. `start`: the segment it started in, failed or
    not. `visited`: one visit for each segment it passed through and the failure for the segment
    it failed in, so r_s is the chance of failing within segment s once there. Episodes run until
    they fail or the clip ends, so on a clip much longer than they last nearly every start fails
    sooner or later: `start` then flattens r_s near 1 and p_fail cannot single out the hard part."""
    cap_factor: float = 4.0
    """p_max as a multiple of the uniform probability 1/S (at least 1: the S caps must hold all the mass)."""

    def __post_init__(self) -> None:
        require_positive(self, "ramp_steps", "update_interval", "ema_alpha")
        require_at_most(self, 1.0, "ema_alpha")
        if not self.cap_factor >= 1.0:
            raise ParamRangeError("cap_factor", f"must be at least 1, got {self.cap_factor}")


def water_fill(weights: torch.Tensor, cap: float) -> torch.Tensor:
    """Normalize `weights` (S,) to sum 1 with no entry above `cap` (needs cap * S >= 1)."""
    p = weights / weights.sum()
    capped = torch.zeros_like(p, dtype=torch.bool)
    for _ in range(p.numel()):
        over = p > cap * (1 + 1e-12)
        if not over.any():
            break
        capped |= over
        free = ~capped
        excess = 1.0 - cap * capped.sum()
        base = p[free].sum()
        p = torch.where(capped, torch.full_like(p, cap), p * (excess / base) if base > 0 else p)
    return p


class SegmentSampler:
    """Chooses start segments for resetting environments and learns which segments fail.

    It lives on the host whatever the training device: a few hundred segments, drawn from and
    updated between physics steps, where the environment keeps its episode bookkeeping."""

    def __init__(self, config: SamplerConfig, balanced: torch.Tensor, seed: int) -> None:
        if config.mode not in MODES:
            raise ValueError(f"sampler mode must be one of {', '.join(MODES)}, got '{config.mode}'")
        self.config = config
        self.n_segments = balanced.numel()
        self.uniform = torch.full((self.n_segments,), 1.0 / self.n_segments, dtype=torch.float64)
        self.balanced = (balanced / balanced.sum()).to(dtype=torch.float64)
        self.failure_rate = torch.zeros(self.n_segments, dtype=torch.float64)
        self.failures = torch.zeros(self.n_segments, dtype=torch.float64)
        self.attempts = torch.zeros(self.n_segments, dtype=torch.float64)
        self.step = 0
        self.generator = torch.Generator().manual_seed(seed)

    def mixture_weights(self, step: int | None = None) -> tuple[float, float, float]:
        """(lambda_u, lambda_d, lambda_f) at `step` for the configured mode."""
        c = self.config
        step = self.step if step is None else step
        ramp = min(max((step - c.ramp_start_steps) / c.ramp_steps, 0.0), 1.0)
        failure = c.failure_weight_start + ramp * (c.failure_weight_end - c.failure_weight_start)
        distribution = c.distribution_weight_start + ramp * (c.distribution_weight_end - c.distribution_weight_start)
        rest = 1.0 - c.uniform_weight
        return {
            "uniform": (1.0, 0.0, 0.0),
            "distribution": (c.uniform_weight, rest, 0.0),
            "failure": (c.uniform_weight, 0.0, rest),
            "combined": (c.uniform_weight, distribution, failure),
        }[c.mode]

    def failure_prior(self) -> torch.Tensor:
        weights = (self.failure_rate + self.config.epsilon) ** self.config.beta
        return weights / weights.sum()

    def probabilities(self) -> torch.Tensor:
        """(S,) the current sampling distribution, capped at `cap_factor / S` after normalization."""
        uniform, distribution, failure = self.mixture_weights()
        mixed = uniform * self.uniform + distribution * self.balanced + failure * self.failure_prior()
        return water_fill(mixed.clamp(min=0.0), self.config.cap_factor / self.n_segments)

    def sample(self, count: int) -> torch.Tensor:
        """(count,) segment indices, drawn with the sampler's own generator (same seed, same draws)."""
        return torch.multinomial(self.probabilities(), count, replacement=True, generator=self.generator)

    def record(self, start: torch.Tensor, end: torch.Tensor, failed: torch.Tensor) -> None:
        """Outcomes of finished episodes: the segments each started and ended in, and whether it failed."""
        ones = torch.ones_like(start, dtype=torch.float64)
        if self.config.failure_credit == "start":
            self.attempts.index_add_(0, start, ones)
            self.failures.index_add_(0, start, failed.to(torch.float64))
            return
        # Each episode visited every segment from its start to its end: a difference array turns
        # those ranges into per-segment counts.
        edges = torch.zeros(self.n_segments + 1, dtype=torch.float64)
        edges.index_add_(0, start, ones)
        edges.index_add_(0, end + 1, -ones)
        self.attempts += edges.cumsum(0)[:-1]
        self.failures.index_add_(0, end, failed.to(torch.float64))

    def advance(self, steps: int = 1) -> None:
        """Count environment steps; every `update_interval` steps, fold the outcomes into the EMA.

        f_s is the failure fraction of the episodes that segment s counted in the interval (see
        `failure_credit`); segments with no episodes keep their rate.
        """
        for _ in range(steps):
            self.step += 1
            if self.step % self.config.update_interval == 0:
                seen = self.attempts > 0
                fraction = torch.where(seen, self.failures / self.attempts.clamp(min=1.0), self.failure_rate)
                alpha = self.config.ema_alpha
                self.failure_rate = torch.where(
                    seen, (1 - alpha) * self.failure_rate + alpha * fraction, self.failure_rate
                )
                self.failures.zero_()
                self.attempts.zero_()

    def state_dict(self) -> dict:
        return {
            "failure_rate": self.failure_rate.clone(),
            "failures": self.failures.clone(),
            "attempts": self.attempts.clone(),
            "step": self.step,
            "generator": self.generator.get_state(),
        }

    def load_state_dict(self, state: dict) -> None:
        self.failure_rate = state["failure_rate"].clone()
        self.failures = state["failures"].clone()
        self.attempts = state["attempts"].clone()
        self.step = int(state["step"])
        self.generator.set_state(state["generator"])
