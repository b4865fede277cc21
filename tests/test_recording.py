"""A sim2sim recording explains itself: it opens on its own layout, every source sits on one time
axis in seconds, the tracked robot has its tracking errors plotted and is cleared when its
rollout ends, with the cause left there."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from rd_pipeline.motion.reference import ReferenceMotion, reference_from_joint_trajectory
from rd_pipeline.robots import load_robot
from rd_pipeline.viz.recording import record_tracking
from rd_pipeline.viz.tracked import TrackedRollout

FPS = 50.0
CLIP_START = 20
STEPS = 30


def _standing(frames: int) -> ReferenceMotion:
    """G1 standing in its default pose at 50 fps."""
    robot = load_robot("g1")
    root_pos = np.tile([0.0, 0.0, 0.8], (frames, 1))
    root_quat = np.tile([1.0, 0.0, 0.0, 0.0], (frames, 1))
    joints = np.zeros((frames, len(robot.config.joint_names)))
    return reference_from_joint_trajectory(robot, FPS, root_pos, root_quat, joints, np.ones((frames, 2), dtype=bool))


def _rollout(reference: ReferenceMotion, ended_by: str) -> TrackedRollout:
    """`STEPS` control steps from the clip's first frame, standing where the reference stands."""
    model = load_robot("g1").model
    poses = np.zeros((STEPS + 1, model.nbody, 3))
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (STEPS + 1, model.nbody, 1))
    ids = [model.body(n).id for n in reference.body_names]
    poses[:, ids] = reference.body_pos_w[: STEPS + 1]
    return TrackedRollout(
        body_pos=poses,
        body_quat=quats,
        first_frame=CLIP_START,
        fps=FPS,
        body_error_m=np.linspace(0.0, 0.3, STEPS),
        joint_error_rad=np.linspace(0.0, 0.6, STEPS),
        ended_by=ended_by,
    )


def _record(folder: Path, ended_by: str) -> Path:
    clip = _standing(100).frames(CLIP_START, 100)
    tracked = folder / "tracked.npz"
    _rollout(clip, ended_by).save(tracked)
    return record_tracking(load_robot("g1").model, clip, tracked, "test", folder / "sim2sim.rrd")


@pytest.fixture(scope="module")
def fell(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _record(tmp_path_factory.mktemp("fell"), "tilted + floor torso_link")


def _chunks(path: Path, entity: str, static: bool = False) -> list[pa.RecordBatch]:
    """`entity`'s rows on the time axis (or its static ones)."""
    chunks = RrdReader(str(path)).stream()
    return [c.to_record_batch() for c in chunks if c.entity_path == entity and c.is_static == static]


def _seconds(batch: pa.RecordBatch) -> np.ndarray:
    return np.array(batch.column("time").cast(pa.int64()).to_pylist()) / 1e9


def _column(batches: list[pa.RecordBatch], name: str) -> list:
    return [value for batch in batches if name in batch.schema.names for value in batch.column(name).to_pylist()]


def test_the_recording_opens_on_a_large_scene_above_its_plots_on_the_time_axis(fell: Path) -> None:
    reader = RrdReader(str(fell))
    (blueprint,) = reader.blueprints()
    parts: dict[str, dict[str, list]] = {}
    for chunk in reader.stream(store=blueprint):
        batch = chunk.to_record_batch()
        found = {n: batch.column(n).to_pylist()[-1] for n in batch.schema.names if ":" in n}
        parts.setdefault(chunk.entity_path, {}).update(found)
    views = {
        p["ViewBlueprint:display_name"][0]: p["ViewBlueprint:class_identifier"][0]
        for p in parts.values()
        if "ViewBlueprint:display_name" in p
    }
    assert views == {
        "scene": "3D",
        "tracking error: bodies (m)": "TimeSeries",
        "tracking error: joints (rad)": "TimeSeries",
    }
    (shares,) = [p["ContainerBlueprint:row_shares"] for p in parts.values() if "ContainerBlueprint:row_shares" in p]
    assert shares == [3.0, 1.0]  # the scene three times the height of the plots
    assert parts["/time_panel"]["TimePanelBlueprint:timeline"] == ["time"]


def test_every_source_is_on_one_time_axis_in_seconds(fell: Path) -> None:
    timelines = {tuple(c.timeline_names) for c in RrdReader(str(fell)).stream() if not c.is_static}
    assert timelines == {("time",)}
    # The clip starts at its frame in the whole reference: reference and tracked robot in step.
    # Meshes and poses both start there (a mesh before its first pose would stand at the origin).
    for entity in ("/robot/reference/pelvis", "/robot/tracked/pelvis"):
        assert [_seconds(b)[0] for b in _chunks(fell, entity)] == pytest.approx([CLIP_START / FPS] * 2)


def test_tracking_errors_are_plotted_one_value_per_step(fell: Path) -> None:
    for entity, most in (("/tracking/body_error_m", 0.3), ("/tracking/joint_error_rad", 0.6)):
        batches = _chunks(fell, entity)
        values = np.array([v[0] for v in _column(batches, "Scalars:scalars")])
        assert len(values) == STEPS and values.min() >= 0.0 and values.max() == pytest.approx(most)
        # Step k's error belongs to the pose after it.
        seconds = np.concatenate([_seconds(b) for b in batches])
        assert seconds == pytest.approx((CLIP_START + 1 + np.arange(STEPS)) / FPS)


def test_the_tracked_robot_is_cleared_when_its_rollout_ends_with_the_cause_there(fell: Path) -> None:
    cleared = [b for b in _chunks(fell, "/robot/tracked") if "Clear:is_recursive" in b.schema.names]
    (clear,) = cleared
    assert clear.column("Clear:is_recursive").to_pylist() == [[True]]
    # One frame after its last pose, so the failing pose is still seen.
    last = CLIP_START + STEPS
    assert _seconds(clear) == pytest.approx([(last + 1) / FPS])
    (end,) = _chunks(fell, "/robot/tracked_end")
    assert _seconds(end) == pytest.approx([(last + 1) / FPS])
    assert end.column("Points3D:labels").to_pylist() == [
        [f"rollout ended at {last / FPS:.2f} s: tilted + floor torso_link"]
    ]


def test_a_rollout_that_reaches_the_clips_end_stays(tmp_path: Path) -> None:
    completed = _record(tmp_path, "")
    assert not [b for b in _chunks(completed, "/robot/tracked") if "Clear:is_recursive" in b.schema.names]
    assert not _chunks(completed, "/robot/tracked_end")


def test_reference_and_tracked_robot_differ_in_colour_and_say_who_they_are(fell: Path) -> None:
    def static(entity: str, component: str) -> list:
        return _column(_chunks(fell, entity, static=True), component)

    def mesh(entity: str) -> list:
        return _column(_chunks(fell, entity), "Mesh3D:albedo_factor")

    assert mesh("/robot/reference/pelvis") != mesh("/robot/tracked/pelvis")
    assert static("/robot/reference/label", "Points3D:labels") == [["reference"]]
    assert static("/robot/tracked/label", "Points3D:labels") == [["tracked (sim2sim)"]]
    assert static("/robot/reference/label", "Points3D:colors") != static("/robot/tracked/label", "Points3D:colors")
