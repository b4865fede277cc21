"""Checkpoint scoring: a checkpoint's score is its own nominal survival, and scoring leaves training untouched."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from conftest import PROJECT, h1_2_dance_env

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.actions import ActionConfig
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.errors import PipelineError
from rd_pipeline.training.evaluate import checkpoint_scorer, nominal, scoring, scoring_starts, survival, zero_action
from rd_pipeline.training.log import best_held, best_scored, checkpoint_path, read_training_log
from rd_pipeline.training.ppo import MultiHeadPPO, build_ppo
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.trainer import train

# With every joint residual, the zero action is the reference itself: a policy that stands a while.
CONFIG = EnvConfig(num_envs=4, threads=2, actions=ActionConfig(mode="all"))


def test_a_score_is_the_survival_from_evenly_spaced_starts_and_sees_a_falling_policy() -> None:
    env = h1_2_dance_env(nominal(CONFIG, 4))
    score = checkpoint_scorer(env, zero_action(env.num_actions))
    first = score()
    # The rollouts moved the curricula and the generator; the next call starts over from the same state.
    assert score() == first
    independent = h1_2_dance_env(nominal(CONFIG, 4))
    starts = scoring_starts(independent.max_episode_length, 4)
    quarter = independent.max_episode_length // 4
    assert starts.tolist() == [0, quarter, 2 * quarter, 3 * quarter]
    seconds = survival(independent, zero_action(independent.num_actions), starts)
    left = (independent.max_episode_length - 1 - starts) / 50.0
    assert first["start_zero_s"] == round(float(seconds[0]), 2)
    assert first["completion"] == pytest.approx(float((seconds / left).mean()), abs=1e-4)
    # The reference fed straight to PD stands 0.72 s from frame 0 of this dance (to a control step).
    assert first["start_zero_s"] == pytest.approx(0.72, abs=0.021)
    # Joints driven to a far, fixed pose topple the robot sooner: the score must fall with it.
    falling = checkpoint_scorer(h1_2_dance_env(nominal(CONFIG, 4)), lambda obs: torch.full((4, env.num_actions), 3.0))()
    assert falling["start_zero_s"] < first["start_zero_s"]
    assert falling["completion"] < first["completion"]


def test_checkpoints_are_scored_on_randomized_physics_that_every_call_repeats() -> None:
    """The score that may choose a checkpoint is not the nominal figure validation reports."""
    env = h1_2_dance_env(scoring(CONFIG, 4))
    assert env.config.randomization.enabled and env.config.rsi_joint_pos == 0.0
    score = checkpoint_scorer(env, zero_action(env.num_actions))
    first = score()
    assert score() == first
    on_nominal = h1_2_dance_env(nominal(CONFIG, 4))
    assert checkpoint_scorer(on_nominal, zero_action(on_nominal.num_actions))() != first


def _mean_action(ppo: MultiHeadPPO):
    return lambda obs: ppo.actor(obs, stochastic_output=False)


def _train(out_dir: Path, scored: bool) -> tuple[MultiHeadPPO, list[dict]]:
    torch.manual_seed(3)
    env = h1_2_dance_env(CONFIG)
    ppo = build_ppo(env.get_observations(), 4, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=6))
    scorer = checkpoint_scorer(h1_2_dance_env(nominal(CONFIG, 4)), _mean_action(ppo)) if scored else None
    train(env, ppo, iterations=3, out_dir=out_dir, checkpoint_every=2, score=scorer)
    return ppo, read_training_log(out_dir)


@pytest.mark.slow
def test_scoring_at_checkpoints_leaves_training_bit_for_bit_and_scores_the_saved_weights(tmp_path: Path) -> None:
    plain, plain_rows = _train(tmp_path / "plain", scored=False)
    scored, rows = _train(tmp_path / "scored", scored=True)
    for name, value in scored.actor.state_dict().items():
        assert torch.equal(value, plain.actor.state_dict()[name]), name
    # Checkpoints at 2 and at the end (3) are scored, iteration 1 is not.
    assert ["start_zero_s" in row for row in rows] == [False, True, True]
    assert best_scored(plain_rows) is None
    # The score logged at iteration 2 is that of the weights saved at 2, rolled out afresh.
    saved = torch.load(checkpoint_path(tmp_path / "scored", 2), weights_only=False)
    env = h1_2_dance_env(CONFIG)
    ppo = build_ppo(env.get_observations(), 4, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=6))
    ppo.load(saved["algorithm"], None, strict=True)
    rescored = checkpoint_scorer(h1_2_dance_env(nominal(CONFIG, 4)), _mean_action(ppo))()
    assert rescored == {key: rows[1][key] for key in ("start_zero_s", "completion")}


def test_best_by_completion_picks_the_checkpoint_that_lasts_from_the_clips_middle(tmp_path: Path) -> None:
    """On the committed log of the 132 M-sample G1 dance-window run, start-zero first picks
    checkpoint 35700 (9.98 s, completion 0.535); completion first picks 42400 (9.78 s, 0.743), the
    one whose fixed-grid validation lasts longer from the window's middle."""
    import gzip
    import shutil

    with gzip.open(PROJECT / "studies" / "results" / "dance_window_state" / "training_log.jsonl.gz") as packed:
        with open(tmp_path / "training_log.jsonl", "wb") as log:
            shutil.copyfileobj(packed, log)
    # The saved state grows with the run; these are the choices over its first 43,000 iterations.
    rows = [row for row in read_training_log(tmp_path) if row["iteration"] <= 43000]
    by_start_zero = best_scored(rows)
    by_completion = best_scored(rows, "completion")
    assert by_start_zero is not None and by_completion is not None
    assert (by_start_zero["iteration"], by_start_zero["start_zero_s"], by_start_zero["completion"]) == (
        35700,
        9.98,
        0.5347,
    )
    assert (by_completion["iteration"], by_completion["start_zero_s"], by_completion["completion"]) == (
        42400,
        9.78,
        0.7428,
    )


def test_export_ranks_only_the_checkpoints_it_has_in_the_order_asked(tmp_path: Path) -> None:
    """A run grown from a saved state logs iterations whose checkpoints it does not hold."""
    from rd_pipeline.stages.export import _best

    scores = {100: (9.9, 0.9), 200: (6.0, 0.7), 300: (8.0, 0.5)}
    rows = [{"iteration": it, "start_zero_s": sz, "completion": c} for it, (sz, c) in scores.items()]
    (tmp_path / "training_log.jsonl").write_text("".join(json.dumps(row) + "\n" for row in rows))
    (tmp_path / "checkpoints").mkdir()
    for it in (200, 300):
        checkpoint_path(tmp_path, it).touch()
    assert (_best(tmp_path, "start_zero"), _best(tmp_path, "completion")) == (300, 200)
    # train's best_checkpoint and its curve's star are the same choice
    assert best_held(tmp_path) == rows[2]


def test_export_of_a_folder_without_a_training_log_is_one_line(tmp_path: Path) -> None:
    from rd_pipeline.stages.export import _best

    with pytest.raises(PipelineError, match=f"^{tmp_path / 'training_log.jsonl'}: no training log here$"):
        _best(tmp_path, "start_zero")
