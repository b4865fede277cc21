"""`export`: the trained actor -> `policy.pt` (TorchScript) + `policy.json` (everything a deploy loop needs)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from rd_pipeline.artifacts.stage import Stage, StageContext, typed_config
from rd_pipeline.errors import PipelineError
from rd_pipeline.params import ParamRangeError
from rd_pipeline.robots.assets import model_files
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.log import ScoreFirst, best_held, checkpoints_by_iteration

Selection = Literal["last", "start_zero", "completion"]


@dataclass(frozen=True)
class ExportConfig:
    """Which checkpoint goes to the robot, and the rule that chose it (the validation report
    names it)."""

    checkpoint: int = 0
    """Training iteration of the checkpoint to export (0: as `best_by` says)."""
    best_by: Selection = "last"
    """`last`: the run's last checkpoint, fixed by iteration before anything is looked at, as the
    paper compares methods. `start_zero` or `completion`: the held checkpoint `train` scored best,
    that score first (`start_zero`: survival from the clip's first frame; `completion`: the mean
    fraction of the clip left that it survives from `train.scoring_starts` evenly spaced starts),
    ties to the other, then to the latest. Train scores on the training model under randomized
    physics drawn from `train.scoring_seed`, a score no validation protocol repeats. Only with
    `checkpoint` 0; refused beside a chosen one."""

    def __post_init__(self) -> None:
        # A chosen checkpoint with a ranking would key a second artifact of the same export.
        if self.checkpoint and self.best_by != "last":
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
    checkpoint, rule = _choose(train.path, ctx.params)
    return export_policy(trained, load_robot(ctx.robot_name), checkpoint, rule, ctx.out_dir)


def _choose(train: Path, params: ExportConfig) -> tuple[int, str]:
    """The checkpoint to export and the rule that chose it, in words."""
    if params.checkpoint:
        return params.checkpoint, f"export.checkpoint={params.checkpoint}, fixed by iteration"
    if params.best_by == "last":
        held = checkpoints_by_iteration(train)
        if not held:
            raise PipelineError(f"{train}: holds no checkpoint")
        return max(held), "the run's last checkpoint, fixed by iteration before looking"
    rule = (
        f"the best {params.best_by} score among held checkpoints, scored by train on the training "
        "model under randomized physics of its own seed (not a validation protocol)"
    )
    return _best(train, params.best_by), rule


def _best(train: Path, best_by: ScoreFirst) -> int:
    best = best_held(train, best_by)
    if best is None:
        raise PipelineError(f"{train}: holds no scored checkpoint")
    return best["iteration"]


STAGE = Stage(
    name="export",
    version=6,
    description="trained actor -> policy.pt (TorchScript) + policy.json (gains, scales, mask, obs layout, rates)",
    params=ExportConfig,
    provides="deployable_policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("policy", "reference"),
    headline=("checkpoint_iteration", "num_actions", "action_mode"),
)
