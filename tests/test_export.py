"""Export and sim2sim: the TorchScript file acts like the training actor, the deploy loop sees what the
training environment sees, `policy.json` is checked field by field, and the smoke DAG validates."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import RETARGETED_DIR, ReferenceSeeds, check_smoke_training_and_export, cli, video_frames
from rerun.chunk import RrdReader
from tensordict import TensorDict

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.deploy import DeployController
from rd_pipeline.export.exporter import build_policy_spec, load_actor, script_actor
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.policy_runtime import OnnxPolicy
from rd_pipeline.policy_spec import load_policy_spec
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds
from rd_pipeline.training.evaluate import nominal
from rd_pipeline.training.ppo import build_ppo
from rd_pipeline.training.ppo_config import PpoConfig


def _env(robot_name: str, motion: str, config: EnvConfig):
    robot = load_robot(robot_name)
    reference = import_retargeted_csv(
        RETARGETED_DIR / robot_name / f"{motion}.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference.frames(0, 600)
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=0)
    return robot, reference, TrackingEnv(robot, reference, sampler, starts, lengths, config, seed=0)


@pytest.mark.parametrize(
    ("robot_name", "motion", "mode", "future"),
    [("g1", "dance1_subject2", "selective", ()), ("h1_2", "dance2_subject4", "all", (5, 25))],
)
def test_deploy_observations_equal_the_training_environment(
    robot_name: str, motion: str, mode: str, future: tuple[int, ...]
) -> None:
    config = nominal(EnvConfig(), 4)
    config = dataclasses.replace(
        config,
        actions=dataclasses.replace(config.actions, mode=mode),
        observations=dataclasses.replace(config.observations, ref_future_steps=future),
    )
    robot, reference, env = _env(robot_name, motion, config)
    spec = build_policy_spec(robot, config, env.num_actions, "import", "k", (0, reference.n_frames))
    terms = {term["name"]: term["size"] for term in spec.get("observation.terms")}
    assert terms.get("ref_joint_pos_future", 0) == len(future) * len(spec.get("joints.policy"))
    model = env.backend.models[0]
    deploy = DeployController(spec, model, reference, env.num_envs)
    # The last start looks 25 steps past the reference's end: both clamp to its last frame.
    starts = torch.tensor([0, 37, 150, 585])
    env.reset(torch.arange(4), frames=starts)
    obs = env.get_observations()["policy"]
    state = env.backend.state
    deploy.reset(state.qpos, state.qvel, starts.numpy())
    # Identical up to float32 rounding: the deploy loop computes in float64 and casts once.
    assert np.allclose(deploy.current(), obs.numpy(), rtol=0, atol=1e-6)
    generator = torch.Generator().manual_seed(0)
    alive = np.ones(4, dtype=bool)  # an environment that ends is reset by the env and leaves the comparison
    for _ in range(25):
        actions = 0.5 * torch.randn(4, env.num_actions, generator=generator)
        ctrl = deploy.targets(actions.numpy())
        obs, _, dones, _ = env.step(actions)
        alive &= ~dones.numpy()  # an ended environment's queue was reset with it
        assert np.allclose(ctrl[alive], env.target_queue[alive, 0].numpy(), rtol=0, atol=1e-6)  # same PD targets
        state = env.backend.state
        deployed = deploy.observe(state.qpos, state.qvel)
        gap = np.abs(deployed - obs["policy"].numpy())[alive]
        assert gap.size == 0 or gap.max() <= 1e-5, gap.max()
    assert alive.sum() >= 2 and deployed.shape[1] == spec.get("observation.size")


def test_exported_module_matches_the_training_actor(tmp_path: Path) -> None:
    torch.manual_seed(0)
    _, _, env = _env("g1", "dance1_subject2", nominal(EnvConfig(), 8))
    ppo = build_ppo(env.get_observations(), env.num_envs, env.num_actions, len(GROUPS), PpoConfig())
    recorded = []
    with torch.inference_mode():
        obs = env.get_observations()
        while sum(len(o) for o in recorded) < 1000:
            recorded.append(obs["policy"].clone())
            obs, *_ = env.step(ppo.act(obs))
    observations = torch.cat(recorded)[:1000]
    ppo.actor.update_normalization(TensorDict({"policy": observations}, batch_size=[1000]))
    torch.save({"algorithm": ppo.save()}, tmp_path / "model_1.pt")
    actor = load_actor(tmp_path / "model_1.pt", observations.shape[1], env.num_actions, list(PpoConfig().hidden_dims))
    scripted = script_actor(actor)
    scripted.save(str(tmp_path / "policy.pt"))
    loaded = torch.jit.load(str(tmp_path / "policy.pt"))
    ppo.actor.eval()
    with torch.inference_mode():
        expected = ppo.actor(TensorDict({"policy": observations}, batch_size=[1000]), stochastic_output=False)
        exported = loaded(observations)
    assert exported.shape == (1000, 23)  # selective: every G1 policy joint has an output
    assert (exported - expected).abs().max().item() <= 1e-5
    assert expected.abs().max().item() > 0.01  # a real, non-trivial actor


def test_policy_json_names_the_missing_field(tmp_path: Path) -> None:
    robot = load_robot("g1")
    spec = build_policy_spec(robot, EnvConfig(), 23, "retarget", "abc", (0, 500))
    path = tmp_path / "policy.json"
    spec.save(path)
    loaded = load_policy_spec(path)
    assert loaded.get("action.residual_mask") == [0, 3, 6, 9]
    semantics = loaded.get("action.semantics")
    assert [i for i, kind in enumerate(semantics) if kind == "residual"] == [0, 3, 6, 9]
    assert semantics.count("absolute") == 19 and len(loaded.get("action.outputs")) == 23
    data = json.loads(path.read_text())
    del data["action"]["scale"]
    path.write_text(json.dumps(data))
    with pytest.raises(PipelineError, match=r"policy.json: field 'action.scale' is missing$"):
        load_policy_spec(path)
    data = json.loads(json.dumps(spec.data))
    data["joints"]["kp"] = data["joints"]["kp"][:-1]
    path.write_text(json.dumps(data))
    with pytest.raises(PipelineError, match=r"field 'joints.kp' has 22 values, expected 23"):
        load_policy_spec(path)
    data = json.loads(json.dumps(spec.data))
    data["rates"]["control_hz"] = "fifty"
    path.write_text(json.dumps(data))
    with pytest.raises(PipelineError, match=r"field 'rates.control_hz' must be an integer or a number, got 'fifty'"):
        load_policy_spec(path)
    del data["rates"]
    path.write_text(json.dumps(data))
    with pytest.raises(PipelineError, match=r"field 'rates' is missing"):
        load_policy_spec(path)
    data = json.loads(json.dumps(spec.data))
    data["observation"]["ref_future_steps"] = [5, "25"]
    path.write_text(json.dumps(data))
    with pytest.raises(
        PipelineError, match=r"field 'observation.ref_future_steps' must be a list of integers of 1 or more$"
    ):
        load_policy_spec(path)
    data["observation"]["ref_future_steps"] = [5, 25]
    path.write_text(json.dumps(data))
    holds = r"names 2 steps of 23 joints, but the term 'ref_joint_pos_future' holds 0 values$"
    with pytest.raises(PipelineError, match=holds):
        load_policy_spec(path)


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "motion"), [("g1", "dance1_subject2"), ("h1_2", "dance2_subject4")])
def test_smoke_profile_trains_exports_and_validates(
    robot: str, motion: str, artifacts: Path, reference_seeds: ReferenceSeeds
) -> None:
    if robot == "g1":  # the BVH take; H1-2's dance comes from the dataset CSV
        reference_seeds.into(artifacts, robot, motion)
    result = cli("run", "--robot", robot, "--motion", motion, "--profile", "smoke")
    assert result.returncode == 0, result.stderr
    assert "torchvision" not in result.stderr and "Warning" not in result.stderr  # the exporter's own noise
    (export,) = (artifacts / "export" / robot / motion).iterdir()
    spec = load_policy_spec(export / "policy.json")
    assert (export / "policy.pt").is_file() and spec.get("robot") == robot
    (validate,) = (artifacts / "validate" / robot / motion).iterdir()
    report = json.loads((validate / "report.json").read_text())
    for controller in ("policy", "zero_action"):
        grid = report["nominal"][controller]["fixed_grid"]
        assert grid["rollouts"] == report["protocol"]["starts"] == {"g1": 14, "h1_2": 23}[robot]  # every 10 s
        assert 0.2 < grid["mean_survival_s"] < 10 and grid["E_g_mpbpe"] > 0
        assert len(report["nominal"][controller]["drift"]) == 6
        # Per start: the fixed grid's starts in order, their mean the grid's, the first start-zero's.
        per_start = report["nominal"][controller]["per_start"]
        grid_starts = [k * report["protocol"]["grid_s"] for k in range(grid["rollouts"])]
        assert per_start["start_s"] == pytest.approx(grid_starts)
        assert np.mean(per_start["survival_s"]) == pytest.approx(grid["mean_survival_s"], abs=0.005)
        start_zero = report["nominal"][controller]["start_zero"]["mean_survival_s"]
        assert per_start["survival_s"][0] == pytest.approx(start_zero, abs=0.005)
        # A start can last at most what is left of the clip; the grid's ceiling is their mean.
        # (the last frame is one control step before the clip's end)
        step = 1 / report["rates"]["control_hz"]
        left = [report["reference"]["duration_s"] - start - step for start in per_start["start_s"]]
        assert per_start["most_s"] == pytest.approx(left, abs=1e-6)
        assert all(s <= most for s, most in zip(per_start["survival_s"], per_start["most_s"]))
        assert grid["mean_survival_ceiling_s"] == pytest.approx(np.mean(left), abs=5e-4)
        # What ended each: a failure named, or nothing where the start lasted to the clip's end.
        ended = per_start["ended_by"]
        assert len(ended) == grid["rollouts"]
        assert all(
            s == pytest.approx(most) for s, most, e in zip(per_start["survival_s"], per_start["most_s"], ended) if not e
        )
        assert all(part.split()[0] in ("tilted", "far", "floor") for e in ended if e for part in e.split(" + "))
    ceiling = report["nominal"]["policy"]["fixed_grid"]["mean_survival_ceiling_s"]
    assert json.loads((validate / "manifest.json").read_text())["metrics"]["mean_survival_ceiling_s"] == ceiling
    assert f"the mean survival can be at most {ceiling:.2f} s." in (validate / "report.md").read_text()
    markdown = (validate / "report.md").read_text()
    for controller in ("policy", "zero_action"):  # the table counts what per_start says ended each rollout
        ended = Counter(cause or "the clip's end" for cause in report["nominal"][controller]["per_start"]["ended_by"])
        cells = ", ".join(f"{cause}: {count}" for cause, count in sorted(ended.items(), key=lambda c: (-c[1], c[0])))
        assert f"| {controller} | {cells} |" in markdown
    assert any(report["nominal"]["zero_action"]["per_start"]["ended_by"])  # zero action falls from some start
    for name in ("report.md", "drift.png", "survival_per_start.png", "sim2sim.rrd"):
        assert (validate / name).stat().st_size > 0, name
    assert "| zero_action |" in (validate / "report.md").read_text()
    # Every protocol beside nominal, the rule that chose the checkpoint, and the pictures, linked.
    assert set(report["protocols"]) == {"nominal", "randomized", "other_physics"}
    assert report["protocols"]["randomized"]["runs"] == 1  # the smoke profile's one seed
    last = "the run's last checkpoint, fixed by iteration before looking"
    assert report["checkpoint"] == {"iteration": 2, "rule": last}
    assert report["pictures"] == {"filmstrip": "filmstrip.png", "video": "rollout.mp4"}
    assert "![start-zero rollout beside its reference](filmstrip.png)" in markdown
    assert f"Checkpoint: iteration 2, chosen by {last}." in markdown
    video = video_frames(validate / "rollout.mp4")
    assert len(video) > 3 and all(frame.std() > 10 for frame in video)  # not blank
    assert max(np.abs(b.astype(int) - a).mean() for a, b in zip(video, video[1:])) > 0.5  # moving
    # policy.onnx: the same function as policy.pt on what the loop fed it, labelled like policy.json.
    assert report["runtime"]["onnx_vs_torchscript_max_abs_diff"] < 1e-5
    assert report["runtime"]["observations_compared"] == 2000
    metadata = OnnxPolicy(export / "policy.onnx").metadata
    assert metadata["joint_names"].split(",") == spec.get("joints.policy")
    assert metadata["action_semantics"].split(",") == spec.get("action.semantics")
    assert float(metadata["action_scale"]) == spec.get("action.scale")
    onnx_run = cli("run", "--robot", robot, "--motion", motion, "--profile", "smoke", "--set", "validate.runtime=onnx")
    assert onnx_run.returncode == 0, onnx_run.stderr
    (onnx_validate,) = [f for f in (artifacts / "validate" / robot / motion).iterdir() if f != validate]
    on_onnx = json.loads((onnx_validate / "report.json").read_text())
    assert on_onnx["runtime"]["ran"] == "onnx"
    for protocol in ("fixed_grid", "start_zero"):
        assert on_onnx["nominal"]["policy"][protocol]["mean_survival_s"] == pytest.approx(
            report["nominal"]["policy"][protocol]["mean_survival_s"], abs=0.02 + 1e-9
        )
    if robot == "g1":  # `view` puts the tracked robot of the validation its params name beside the reference
        out = artifacts.parent / "view.rrd"
        onnx_view = ("--set", "validate.runtime=onnx", "--out", str(out))
        assert cli("view", "--robot", robot, "--motion", motion, "--profile", "smoke", *onnx_view).returncode == 0
        rows: dict[str, int] = {}
        for chunk in RrdReader(str(out)).store().stream():
            if not chunk.is_static:
                rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
        steps = round(on_onnx["nominal"]["policy"]["start_zero"]["mean_survival_s"] * 50)
        # Every pose, and the mesh once at the first.
        assert rows["/robot/tracked/pelvis"] == steps + 2 and rows["/robot/retarget/pelvis"] == 6575 + 1
        assert rows["/human/joints"] == 3945
        # Its tracking errors plotted, one value per step it survived.
        assert rows["/tracking/body_error_m"] == rows["/tracking/joint_error_rad"] == steps
    check_smoke_training_and_export(artifacts, robot, motion)
