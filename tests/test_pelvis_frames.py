"""`bench/pelvis_frames.py` finds the human feet the targets plant on their backs: many on a
floor cut that opens kneeling, none on a dance; and it learns each sole on the whole take, so a
cut that never stands reads the same soles."""

from __future__ import annotations

import numpy as np
import pytest

from bench.pelvis_frames import planted_on_back, sole_directions
from bench.retarget_variants import clips, floor_cut
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import RetargetTargets, build_targets
from rd_pipeline.robots import Robot

FPS = 50.0


def _targets(robot: Robot, human: HumanMotion) -> RetargetTargets:
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    return build_targets(human, robot, FPS, vertices, params.contact, params.shape, params.body_contact)


def _on_back(robot: Robot, take: str, clip: HumanMotion) -> int:
    whole = clips(take, "plain")[0][1]
    soles = sole_directions(whole, _targets(robot, whole))
    return int(planted_on_back(clip, _targets(robot, clip), soles).sum())


def test_feet_planted_on_their_backs_are_found_kneeling_and_not_dancing(g1: Robot) -> None:
    kneeling = floor_cut("ground2_subject2", "ground2_subject2 145-165 s")
    dance = clips("dance1_subject1", "plain")[0][1]
    assert _on_back(g1, "ground2_subject2", kneeling) > 300
    assert _on_back(g1, "dance1_subject1", dance) == 0


def test_soles_learnt_on_takes_of_two_performers_agree(g1: Robot) -> None:
    takes = ("ground2_subject2", "fallAndGetUp2_subject3")
    soles = [sole_directions(human, _targets(g1, human)) for human in (clips(t, "plain")[0][1] for t in takes)]
    angle = np.degrees(np.arccos(np.clip(np.sum(soles[0] * soles[1], axis=1), -1.0, 1.0)))
    assert angle.max() < 15.0


def test_a_clip_that_never_stands_has_no_sole_to_learn(g1: Robot) -> None:
    crawl = floor_cut("ground2_subject3", "ground2_subject3 164-184 s")
    message = "the human never stands on the LeftFoot foot: no sole direction to learn"
    with pytest.raises(PipelineError, match=f"^{message}$"):
        sole_directions(crawl, _targets(g1, crawl))
