"""The retarget bench's variants of a take: mirrored, replayed at another tempo, floor work cut out."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import LAFAN_DIR

from bench.motion_variants import floor_cuts, mirrored, played_at
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, HumanMotion, human_motion_from_bvh


@pytest.fixture(scope="module")
def floor_take() -> HumanMotion:
    return human_motion_from_bvh(read_bvh(LAFAN_DIR / "ground2_subject2.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)


def test_mirroring_swaps_sides_and_reflects_across_the_sagittal_plane(floor_take) -> None:
    mirror = mirrored(floor_take)
    left = floor_take.names.index("LeftHand")
    right = floor_take.names.index("RightHand")
    np.testing.assert_allclose(mirror.pos_w[:, left], floor_take.pos_w[:, right] * [1.0, -1.0, 1.0])
    # Lengths are kept: the left forearm of the mirror is the right forearm of the take.
    elbow = floor_take.names.index("RightForeArm")
    twin_elbow = floor_take.names.index("LeftForeArm")
    before = np.linalg.norm(floor_take.pos_w[:, right] - floor_take.pos_w[:, elbow], axis=1)
    after = np.linalg.norm(mirror.pos_w[:, left] - mirror.pos_w[:, twin_elbow], axis=1)
    np.testing.assert_allclose(after, before)


def test_mirroring_twice_gives_the_take_back(floor_take) -> None:
    twice = mirrored(mirrored(floor_take))
    np.testing.assert_allclose(twice.pos_w, floor_take.pos_w, atol=1e-12)
    # q and -q are the same rotation.
    dots = np.abs(np.sum(twice.quat_w * floor_take.quat_w, axis=-1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-9)


def test_mirrored_orientations_are_rotations_that_reflect_the_bones(floor_take) -> None:
    """A bone's direction in the world, read from the mirrored orientation and the mirrored rest
    offset, is the reflection of the take's."""
    from scipy.spatial.transform import Rotation

    mirror = mirrored(floor_take)
    knee = floor_take.names.index("LeftLeg")
    foot = floor_take.names.index("LeftFoot")
    rotation = Rotation.from_quat(mirror.quat_w[:, knee][:, [1, 2, 3, 0]])
    predicted = mirror.pos_w[:, knee] + rotation.apply(mirror.offsets[foot])
    np.testing.assert_allclose(predicted, mirror.pos_w[:, foot], atol=1e-9)


def test_tempo_scales_the_frame_rate_only(floor_take) -> None:
    faster = played_at(floor_take, 1.25)
    assert faster.fps == pytest.approx(floor_take.fps * 1.25)
    assert faster.duration_s == pytest.approx(floor_take.duration_s / 1.25)
    np.testing.assert_array_equal(faster.pos_w, floor_take.pos_w)


def test_floor_cuts_open_on_the_floor(floor_take) -> None:
    cuts = floor_cuts(floor_take, "Hips", low_m=0.5, min_s=3.0, length_s=20.0, count=2)
    hips = floor_take.names.index("Hips")
    assert len(cuts) == 2
    for start_s, clip in cuts:
        assert clip.n_frames == round(20.0 * floor_take.fps)
        assert clip.pos_w[0, hips, 2] < 0.5
        first = round(start_s * floor_take.fps)
        np.testing.assert_array_equal(clip.pos_w[0], floor_take.pos_w[first])


def test_a_cut_further_into_its_stretch_starts_later_and_still_on_the_floor(floor_take) -> None:
    cut = {"pelvis": "Hips", "low_m": 0.5, "min_s": 3.0, "length_s": 20.0, "count": 2}
    early = floor_cuts(floor_take, **cut)
    late = floor_cuts(floor_take, **cut, into=0.75)
    hips = floor_take.names.index("Hips")
    for (early_s, _), (late_s, clip) in zip(early, late, strict=True):
        assert 3.0 < late_s - early_s < 20.0
        assert clip.pos_w[0, hips, 2] < 0.5
