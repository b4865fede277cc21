"""Data-parallel PPO on CPU: two ranks (gloo) keep identical weights, and resume bit for bit."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from conftest import cli, h1_2_dance_job

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.actions import ActionConfig
from rd_pipeline.errors import PipelineError
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.distributed import Ranks
from rd_pipeline.training.launch import train_in_processes
from rd_pipeline.training.log import checkpoint_path, read_training_log
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.runner import TrainingRunner, run_job
from rd_pipeline.training.trainer import load_checkpoint

CONFIG = TrainConfig(
    iterations=3,
    checkpoint_every=1,
    scoring_starts=2,
    ranks=2,
    env=EnvConfig(num_envs=4, threads=2, actions=ActionConfig(mode="all")),
    ppo=PpoConfig(steps_per_env=6, hidden_dims=(32, 32)),
)


def _weights(path: Path) -> dict[str, torch.Tensor]:
    algorithm = torch.load(path, weights_only=False)["algorithm"]
    return {**algorithm["actor_state_dict"], **algorithm["critic_state_dict"]}


@pytest.mark.slow
def test_two_ranks_keep_identical_weights_and_a_resumed_run_continues_bit_for_bit(tmp_path: Path) -> None:
    rows: list[dict] = []
    outcome = train_in_processes(h1_2_dance_job(CONFIG, tmp_path / "whole"), rows.append)
    assert [row["iteration"] for row in rows] == [1, 2, 3]
    assert rows == read_training_log(tmp_path / "whole")
    # Each update leaves both ranks with the same weights, and every update changes them.
    digests = [row["rank_weights"] for row in rows]
    assert all(len(pair) == 2 and pair[0] == pair[1] for pair in digests)
    assert len({pair[0] for pair in digests}) == 3
    # One iteration learns from both ranks' environments.
    assert all(row["samples_per_s"] > 0 and "start_zero_s" in row for row in rows)
    assert outcome.num_actions > 0
    saved = torch.load(checkpoint_path(tmp_path / "whole", 3), weights_only=False)
    # Rank 0 saved both ranks' environments, and they are not the same draws.
    first, second = saved["ranks"]
    assert first["env"]["rng"] != second["env"]["rng"]
    # The same run stopped after 2 iterations and continued from that checkpoint ends the same.
    shutil.copytree(tmp_path / "whole" / "checkpoints", tmp_path / "resumed" / "checkpoints")
    checkpoint_path(tmp_path / "resumed", 3).unlink()
    resumed_job = h1_2_dance_job(CONFIG, tmp_path / "resumed", checkpoint_path(tmp_path / "resumed", 2))
    train_in_processes(resumed_job, lambda row: None)
    whole = _weights(checkpoint_path(tmp_path / "whole", 3))
    resumed = _weights(checkpoint_path(tmp_path / "resumed", 3))
    assert whole.keys() == resumed.keys()
    for name, value in whole.items():
        assert torch.equal(value, resumed[name]), name
    again = torch.load(checkpoint_path(tmp_path / "resumed", 3), weights_only=False)
    assert [r["env"]["rng"] for r in again["ranks"]] == [r["env"]["rng"] for r in saved["ranks"]]


@pytest.mark.slow
def test_a_checkpoint_continues_only_with_the_ranks_that_made_it(tmp_path: Path) -> None:
    single = replace(CONFIG, iterations=1, ranks=1)
    run_job(h1_2_dance_job(single, tmp_path / "one"), lambda row: None)
    checkpoint = checkpoint_path(tmp_path / "one", 1)
    runner = TrainingRunner(h1_2_dance_job(single, tmp_path / "one"))
    with pytest.raises(PipelineError) as error:
        load_checkpoint(checkpoint, runner.learner, runner.env, Ranks(rank=1, world_size=2))
    runner.close()
    assert str(error.value) == (
        f"{checkpoint}: made by 1 training processes, resumed with 2; continue it with train.ranks=1"
    )


def test_rank_seeds_keep_rank_zero_and_part_the_others() -> None:
    seeds = [Ranks(rank=r, world_size=3).seed(7) for r in range(3)]
    assert seeds[0] == 7
    assert len(set(seeds)) == 3


@pytest.mark.slow
def test_nproc_runs_the_train_stage_as_that_many_ranks(artifacts: Path) -> None:
    result = cli("run", "--until", "train", "--source", "csv", "--nproc", "2")
    assert result.returncode == 0, result.stderr
    (folder,) = (artifacts / "train" / "g1" / "dance1_subject2").iterdir()
    manifest = json.loads((folder / "manifest.json").read_text())
    params = manifest["params"]
    assert params["ranks"] == 2
    per_rank = params["iterations"] * params["env"]["num_envs"] * params["ppo"]["steps_per_env"]
    assert manifest["metrics"]["samples"] == 2 * per_rank
    checkpoint = torch.load(checkpoint_path(folder, params["iterations"]), weights_only=False)
    assert len(checkpoint["ranks"]) == 2
    # Two processes trained: each logged row holds both ranks' weight digests, equal after the update.
    digests = [row["rank_weights"] for row in read_training_log(folder)]
    assert digests and all(len(pair) == 2 and pair[0] == pair[1] for pair in digests)
    # Nothing of the launch is left beside the artifact.
    assert sorted(p.name for p in folder.parent.iterdir()) == [folder.name]
    refused = cli("run", "--until", "train", "--source", "csv", "--nproc", "0")
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines()[-1] == "error: parameter 'train.ranks' must be positive, got 0"


class _ScriptedRun:
    """Stands in for the rank processes: each poll runs the next step on the log; the last ends it."""

    def __init__(self, steps: list) -> None:
        self.steps = steps

    def poll(self) -> int | None:
        self.steps.pop(0)()
        return None if self.steps else 0


def test_a_resumed_run_is_followed_by_iteration_from_its_checkpoint(tmp_path: Path, monkeypatch) -> None:
    # The interrupted run logged iterations 1-5 but checkpointed after 3; the resumed run rewrites
    # the log up to 3 (a new file), logs 4 and 5 again, and 6 arrives in two writes. Following by
    # line count handed only 6.
    from rd_pipeline.training import launch

    monkeypatch.setattr(launch, "POLL_S", 0.0)
    log = tmp_path / "training_log.jsonl"

    def rows(*iterations: int) -> str:
        return "".join(json.dumps({"iteration": i}) + "\n" for i in iterations)

    log.write_text(rows(1, 2, 3, 4, 5))
    rewritten = tmp_path / "rewritten"

    def rewrite() -> None:
        rewritten.write_text(rows(1, 2, 3))
        rewritten.replace(log)

    def append(text: str):
        def write() -> None:
            with log.open("a") as file:
                file.write(text)

        return write

    run = _ScriptedRun([rewrite, append(rows(4, 5) + '{"itera'), append('tion": 6}\n')])
    handed: list[int] = []
    followed = launch._follow_log(log, run, lambda row: handed.append(row["iteration"]), after=3)
    assert handed == [4, 5, 6]
    assert followed == 3


def test_a_machine_whose_share_is_done_exits_0_with_one_line(monkeypatch, capsys) -> None:
    # Machines other than 0 of a multi-machine run finish their ranks without writing the
    # artifact: that is their job done, not an error (it exited 2 as one).
    from rd_pipeline.cli import app, commands
    from rd_pipeline.errors import ShareDone

    line = "train: the ranks of machine 1 finished; machine 0 (PET_NODE_RANK=0) writes the artifact"

    def share_done(command, console) -> int:
        raise ShareDone(line)

    monkeypatch.setattr(commands, "run", share_done)
    assert app.main(["run", "--robot", "g1", "--motion", "dance1_subject2"]) == 0
    assert capsys.readouterr().err.strip() == f"done: {line}"
