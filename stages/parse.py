"""`parse`: a LAFAN1 BVH file -> human motion (global joint positions and orientations, Z-up, metres)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.markup import escape

from rd_pipeline import paths
from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import too_short
from rd_pipeline.motion.lafan import LAFAN_CM_TO_M, missing_lafan_joints
from rd_pipeline.params import require_positive


@dataclass(frozen=True)
class ParseConfig:
    """How BVH units map to the pipeline's world."""

    length_unit_m: float = LAFAN_CM_TO_M
    """Metres per BVH length unit (LAFAN1 is in centimetres)."""

    def __post_init__(self) -> None:
        require_positive(self, "length_unit_m")


def _inputs(robot: str | None, motion: str) -> dict[str, Path]:
    return {"bvh": paths.bvh_path(motion)}


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.motion.bvh import read_bvh
    from rd_pipeline.motion.human import HUMAN_MOTION_FILE, LAFAN_TO_Z_UP, human_motion_from_bvh

    clip = read_bvh(ctx.inputs["bvh"])
    missing = missing_lafan_joints(clip.names)
    if missing:
        raise PipelineError(f"{ctx.inputs['bvh']}: not a LAFAN1 skeleton; it lacks the joints {', '.join(missing)}")
    short = too_short(str(ctx.inputs["bvh"]), clip.channels.shape[0], 1.0 / clip.frame_time)
    if short:
        raise PipelineError(short)
    for warning in clip.warnings:
        ctx.console.print(f"[yellow]warning:[/] {escape(warning)}", highlight=False, soft_wrap=True)
    human = human_motion_from_bvh(clip, ctx.params.length_unit_m, LAFAN_TO_Z_UP)
    human.save(ctx.out_dir / HUMAN_MOTION_FILE)
    return {
        "frames": human.n_frames,
        "fps": round(human.fps, 6),
        "duration_s": round(human.duration_s, 4),
        "joints": len(human.names),
        "warnings": list(clip.warnings),
        "height_range_m": [round(float(human.pos_w[..., 2].min()), 4), round(float(human.pos_w[..., 2].max()), 4)],
    }


STAGE = Stage(
    name="parse",
    version=1,
    description="LAFAN1 BVH -> human motion (Z-up, metres)",
    params=ParseConfig,
    provides="human_motion",
    run=_run,
    inputs=_inputs,
    source="bvh",
    per_robot=False,
    headline=("frames", "duration_s"),
)
