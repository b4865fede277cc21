"""The Python API's view of a plan's artifacts."""

from __future__ import annotations

from pathlib import Path

import pytest

from rd_pipeline import paths
from rd_pipeline.api import workspace
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.duration import csv_duration_s
from rd_pipeline.robots import load_robot


def test_a_plan_s_reference_is_the_one_its_providing_stage_made_and_a_missing_one_is_named(tmp_path: Path) -> None:
    # H1-2 dance2_subject4 exists only as the dataset's CSV: the import stage provides the reference.
    plan = workspace.plan("h1_2", "dance2_subject4", "smoke", store=tmp_path)
    message = "stage 'import' has no artifact for h1_2/dance2_subject4: run it first"
    with pytest.raises(PipelineError, match=f"^{message}$"):
        workspace.reference(plan)
    workspace.run(plan, until="import")
    reference = workspace.reference(plan)
    fps = plan.stage("import").params.fps
    source_fps = plan.stage("import").params.source_fps
    csv_seconds = csv_duration_s(paths.csv_path("h1_2", "dance2_subject4"), source_fps)
    assert reference.fps == fps
    assert reference.duration_s == pytest.approx(csv_seconds, abs=1.0 / fps)
    assert reference.joint_pos.shape == (reference.n_frames, len(load_robot("h1_2").qpos_indices))
    other = r"^stage 'retarget' is not in the csv pipeline \(stages: import, stats, prior, train, export, validate\)$"
    with pytest.raises(PipelineError, match=other):
        workspace.reference(plan, "retarget")


def test_seed_outranks_the_params_file_and_a_seed_override_outranks_it(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("stages:\n  train:\n    seed: 0\n")
    seeded = workspace.plan("g1", "dance1_subject2", "smoke", params_file=params, seed=3, store=tmp_path)
    assert seeded.stage("train").params.seed == 3
    overridden = workspace.plan(
        "g1", "dance1_subject2", "smoke", params_file=params, overrides=("train.seed=5",), seed=3, store=tmp_path
    )
    assert overridden.stage("train").params.seed == 5
    unseeded = workspace.plan("g1", "dance1_subject2", "smoke", params_file=params, store=tmp_path)
    assert unseeded.stage("train").params.seed == 0


@pytest.mark.parametrize(("text", "kind"), [("- a\n- b\n", "list"), ("just words\n", "str")])
def test_a_params_file_that_is_no_mapping_is_one_line(tmp_path: Path, text: str, kind: str) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(text)
    with pytest.raises(PipelineError) as error:
        workspace.plan("g1", "dance1_subject2", "smoke", params_file=params, store=tmp_path)
    assert str(error.value) == f"{params}: a params file is a mapping with a 'stages:' table, not a {kind}"
