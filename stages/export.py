"""`export`: the trained actor -> `policy.pt` (TorchScript) + `policy.json` (everything a deploy loop needs)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext, typed_config
from rd_pipeline.errors import PipelineError
from rd_pipeline.params import ParamRangeError
from rd_pipeline.rl.training_config import TrainConfig
from rd_pipeline.rl.training_log import ScoreFirst, best_held
from rd_pipeline.robots.assets import model_files


@dataclass(frozen=True)
class ExportConfig:
    """Which checkpoint goes to the robot."""

    checkpoint: int = 0
    """Training iteration of the checkpoint to export (0: the one `train` scored best, as `best_by`
    orders the scores)."""
    best_by: ScoreFirst = "start_zero"
    """Which score of `train`'s checkpoint scoring comes first: `start_zero` (survival from the
    clip's first frame on nominal physics) or `completion` (the mean fraction of the clip left
    that it survives from `train.scoring_starts` evenly spaced starts, frame 0 among them, which
    favours a policy that also lasts from starts in the middle of the clip); ties go to the other
    score, then to the latest checkpoint. Train's `best_checkpoint` and its plot's star are the
    `start_zero` choice. Only with `checkpoint` 0; refused beside a chosen one."""

    def __post_init__(self) -> None:
        # A chosen checkpoint with a ranking would key a second artifact of the same export.
        if self.checkpoint and self.best_by != "start_zero":
            raise ParamRangeError(
                "best_by",
                f"ranks checkpoints only when checkpoint is 0, got checkpoint {self.checkpoint} (drop one of the two)",
            )


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.export.policy_export import TrainedPolicy, export_policy
    from rd_pipeline.robots import load_robot

    train = ctx.upstream["policy"]
    reference = ctx.upstream["reference"]
    manifest = train.manifest
    metrics = manifest["metrics"]
    trained = TrainedPolicy(
        folder=train.path,
        config=typed_config(TrainConfig, manifest["params"], "train"),
        observation_size=metrics["observation_size"],
        num_actions=metrics["num_actions"],
        clip_frames=tuple(metrics["clip_frames"]),
        reference_stage=reference.stage,
        reference_key=reference.key,
    )
    checkpoint = ctx.params.checkpoint or _best(train.path, ctx.params.best_by)
    return export_policy(trained, load_robot(ctx.robot_name), checkpoint, ctx.out_dir)


def _best(train: Path, best_by: ScoreFirst) -> int:
    best = best_held(train, best_by)
    if best is None:
        raise PipelineError(f"{train}: holds no scored checkpoint")
    return best["iteration"]


STAGE = Stage(
    name="export",
    version=5,
    description="trained actor -> policy.pt (TorchScript) + policy.json (gains, scales, mask, obs layout, rates)",
    params=ExportConfig,
    provides="deployable_policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("policy", "reference"),
    headline=("num_actions", "action_mode"),
)
