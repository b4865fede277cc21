"""The DAG stages, one thin module each. `REGISTRY` lists the stages that exist, in pipeline order."""

from rd_pipeline.artifacts.stage import Stage
from rd_pipeline.stages import export, import_motion, parse, prior, retarget, stats, train, validate

REGISTRY: tuple[Stage, ...] = (
    parse.STAGE,
    retarget.STAGE,
    import_motion.STAGE,
    stats.STAGE,
    prior.STAGE,
    train.STAGE,
    export.STAGE,
    validate.STAGE,
)


def stage_names() -> list[str]:
    return [stage.name for stage in REGISTRY]
