"""TD3's replay buffer: n-step sums cut where an episode ends, bootstraps by how it ended."""

from __future__ import annotations

import pytest
import torch

from rd_pipeline.training.replay import ReplayBuffer

GAMMA = 0.9
N_STEP = 3

pytestmark = pytest.mark.offline


def _filled(steps: int, ends: dict[int, str], rows: int = 100) -> ReplayBuffer:
    """Two environments stepped `steps` times into `rows` rows: observation = step number (env 1:
    + 100), reward = step number + 1, and `ends[step]` ('terminated' or 'timed_out') where env 0's
    episode ends."""
    buffer = ReplayBuffer(2, 2 * rows, 1, 1, 1)
    for step in range(steps):
        obs = torch.tensor([[step], [step + 100]], dtype=torch.float32)
        rewards = torch.tensor([step + 1.0, step + 101.0])
        terminated = torch.tensor([ends.get(step) == "terminated", False])
        timed_out = torch.tensor([ends.get(step) == "timed_out", False])
        buffer.add(obs, obs, obs, rewards, terminated, timed_out)
    return buffer


def _expected(step: int, ends: dict[int, str]) -> tuple[float, float, float, bool]:
    """(returns, discount, bootstrap observation, cut by a time-out) of env 0's `step`, by hand."""
    returns = 0.0
    for k in range(N_STEP):
        end = ends.get(step + k)
        if end == "terminated":
            return returns + GAMMA**k * (step + k + 1), 0.0, step + k + 1, False
        if end == "timed_out":  # Q(s, a) of the time-out step holds its reward
            return returns, GAMMA**k, step + k, True
        returns += GAMMA**k * (step + k + 1)
    return returns, GAMMA**N_STEP, step + N_STEP, False


def test_n_step_targets_stop_at_terminations_and_bootstrap_time_outs_from_their_own_step() -> None:
    ends = {4: "terminated", 9: "timed_out", 10: "timed_out"}
    buffer = _filled(16, ends)
    batch = buffer.sample(4000, N_STEP, GAMMA, torch.Generator().manual_seed(0))
    env0 = batch.policy_obs[:, 0] < 100
    steps = batch.policy_obs[env0, 0].long().tolist()
    assert sorted(set(steps)) == list(range(16 - N_STEP))  # every step with n after it, none without
    for i, step in zip(torch.nonzero(env0).flatten().tolist(), steps):
        returns, discount, bootstrap, cut = _expected(step, ends)
        assert float(batch.returns[i]) == pytest.approx(returns, rel=1e-6), step
        assert float(batch.discount[i]) == pytest.approx(discount, rel=1e-6), step
        assert bool(batch.cut_by_timeout[i]) == cut, step
        source = batch.timeout_critic_obs if cut else batch.next_critic_obs
        if discount > 0:
            assert float(source[i, 0]) == bootstrap, step
        assert float(batch.weight[i]) == (0.0 if step in (9, 10) else 1.0), step
    # The other environment never ended: every target is n rewards and a bootstrap n steps on.
    other = batch.policy_obs[~env0, 0] - 100
    sums = sum(GAMMA**k * (other + k + 101) for k in range(N_STEP))
    assert torch.allclose(batch.returns[~env0], sums)
    assert torch.equal(batch.next_policy_obs[~env0, 0], batch.policy_obs[~env0, 0] + N_STEP)


def test_a_full_buffer_overwrites_its_oldest_rows_and_samples_only_in_time_order() -> None:
    buffer = _filled(25, {}, rows=16)  # steps 9..24 remain
    batch = buffer.sample(2000, N_STEP, GAMMA, torch.Generator().manual_seed(1))
    env0 = batch.policy_obs[:, 0] < 100
    steps = batch.policy_obs[env0, 0]
    assert int(steps.min()) == 9 and int(steps.max()) == 24 - N_STEP
    assert torch.equal(batch.next_policy_obs[env0, 0], steps + N_STEP)
