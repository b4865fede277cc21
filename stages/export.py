"""`export`: the trained actor -> `policy.pt` (TorchScript) + `policy.json` (everything a deploy loop needs)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext, typed_config
from rd_pipeline.rl.training_config import TrainConfig
from rd_pipeline.robots.assets import model_files

REFERENCE_STAGES = ("retarget", "import")


@dataclass(frozen=True)
class ExportConfig:
    """Which checkpoint goes to the robot."""

    checkpoint: int = 0
    """Training iteration of the checkpoint to export (0: the one `train` scored best: the longest
    start-zero survival on nominal physics, then the highest completion, then the latest)."""


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.export.policy_export import TrainedPolicy, export_policy
    from rd_pipeline.robots import load_robot

    train = ctx.upstream["policy"]
    manifest = train.manifest
    metrics = manifest["metrics"]
    reference_stage = next(s for s in REFERENCE_STAGES if s in manifest["upstream"])
    trained = TrainedPolicy(
        folder=train.path,
        config=typed_config(TrainConfig, manifest["params"], "train"),
        observation_size=metrics["observation_size"],
        num_actions=metrics["num_actions"],
        best_checkpoint=metrics["best_checkpoint"],
        clip_frames=tuple(metrics["clip_frames"]),
        reference_stage=reference_stage,
        reference_key=manifest["upstream"][reference_stage],
    )
    return export_policy(trained, load_robot(ctx.robot_name), ctx.params.checkpoint, ctx.out_dir)


STAGE = Stage(
    name="export",
    version=4,
    description="trained actor -> policy.pt (TorchScript) + policy.json (gains, scales, mask, obs layout, rates)",
    params=ExportConfig,
    provides="deployable_policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("policy",),
    headline=("num_actions", "action_mode"),
)
