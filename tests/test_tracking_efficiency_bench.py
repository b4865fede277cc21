"""The tracking bench's report: samples to threshold counts a budget only when every seed holds
the window from its start that long, and successive halving keeps the best arms by train's score."""

from __future__ import annotations

from typing import Any

from bench import tracking_efficiency


def _row(arm: str, seed: int, rung: float, start_zero: float, score: float) -> dict[str, Any]:
    return {
        "arm": arm,
        "seed": seed,
        "rung_m": rung,
        "nominal_start_zero_s": start_zero,
        "train_score_s": score,
        "wall_h": 0.5 * rung,
    }


ROWS = [
    _row("td3", 0, 1, 0.9, 0.8),
    _row("td3", 1, 1, 2.7, 0.9),
    _row("td3", 0, 2, 2.6, 1.5),
    _row("td3", 1, 2, 3.0, 1.2),
    _row("ppo", 0, 1, 2.6, 0.6),
    _row("ppo", 1, 1, 0.6, 0.7),
]


def test_samples_to_threshold_needs_every_seed() -> None:
    lines = tracking_efficiency._samples_to_threshold(ROWS, threshold=2.5)
    assert lines == ["- td3: 2 M samples, 1.00 h a seed", "- ppo: not within 1 M samples"]


def test_successive_halving_keeps_the_best_half_by_train_score() -> None:
    at_first_rung = [row for row in ROWS if row["rung_m"] == 1]
    assert tracking_efficiency._survivors(at_first_rung, eta=2) == {"td3"}
    assert tracking_efficiency._survivors(at_first_rung, eta=1) == {"td3", "ppo"}
