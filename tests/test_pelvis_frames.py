"""`bench/pelvis_frames.py` finds the human feet the targets plant on their backs: many on a
floor cut that opens kneeling, none on a dance."""

from __future__ import annotations

from bench.pelvis_frames import planted_on_back
from bench.retarget_variants import clips
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import build_targets
from rd_pipeline.robots import Robot

FPS = 50.0


def _on_back(robot: Robot, clip: HumanMotion) -> int:
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    targets = build_targets(clip, robot, FPS, vertices, params.contact, params.shape, params.body_contact)
    return int(planted_on_back(clip, targets).sum())


def test_feet_planted_on_their_backs_are_found_kneeling_and_not_dancing(g1: Robot) -> None:
    kneeling = dict(clips("ground2_subject2", "floor_cut"))["ground2_subject2 145-165 s"]
    dance = clips("dance1_subject1", "plain")[0][1]
    assert _on_back(g1, kneeling) > 300
    assert _on_back(g1, dance) == 0
