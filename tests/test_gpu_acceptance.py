"""The GPU acceptance bench runs on Warp's CPU device and its figures hold; the backend factory
refuses CUDA with a CPU torch before touching Warp; the warp backend's diagnostics."""

from __future__ import annotations

import copy
import json
import sys

import pytest
import torch
from conftest import PROJECT

from rd_pipeline.env.physics import make_backend
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.errors import PipelineError
from rd_pipeline.robots import load_robot

GAP_TOLERANCE = {
    "qpos": 1e-4,
    "body_pos": 1e-4,
    "body_quat": 1e-4,
    "qvel": 1e-2,
    "body_vel": 1e-2,
    "actuator_force": 0.05,
    "contact_force": 0.5,
}
"""Largest gap, float32 Warp against float64 C MuJoCo, after 10 control steps (0.2 s) from
reference states on randomized models with random joint forces and a push (rad, m, m/s, N m, N).
Measured: qpos 4e-6, body_pos 1.4e-6, body_quat 1.6e-6, qvel 1.3e-4, body_vel 1.4e-4,
actuator_force 3e-4, contact_force 3e-3 (of 470 N)."""


@pytest.fixture(scope="module")
def bench_result(tmp_path_factory: pytest.TempPathFactory) -> dict:
    pytest.importorskip("mujoco_warp", reason="the gpu extra (mujoco-warp) is not installed")
    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.syspath_prepend(str(PROJECT))
    from bench.gpu_acceptance import main

    out = tmp_path_factory.mktemp("gpu_acceptance") / "result.json"
    argv = ["--device", "cpu", "--envs", "4", "--steps", "20", "--split-steps", "3", "--raw-steps", "3"]
    argv += ["--iterations", "2", "--steps-per-env", "4", "--compare-envs", "4", "--push-interval", "0.1", "0.2"]
    try:
        result = main([*argv, "--out", str(out)])
    finally:
        monkeypatch.undo()
    assert json.loads(out.read_text()) == json.loads(json.dumps(result))
    return result


@pytest.mark.slow
def test_warp_matches_c_mujoco_on_randomized_models_with_pushes(bench_result: dict) -> None:
    equality = bench_result["c_backend_equality"]
    assert equality["control_steps"] == 10 and equality["envs"] == 4
    gaps = equality["max_abs_gap"]
    assert set(gaps) == set(GAP_TOLERANCE)
    assert all(gaps[name] < GAP_TOLERANCE[name] for name in gaps), gaps
    assert equality["max_abs_value"]["contact_force"] > 100  # the feet carry the robot: contacts compared
    peaks = equality["contacts_peak_world"]
    assert abs(peaks["c"] - peaks["warp"]) <= 2 and peaks["c"] > 0


@pytest.mark.slow
def test_bench_reports_the_cpu_fallback_and_throughput(bench_result: dict) -> None:
    reason = bench_result["capture"]["fallback_reason"]
    assert "'cpu' is not a CUDA device" in reason and not bench_result["capture"]["graphs"]
    versions = bench_result["versions"]
    assert versions["mujoco_warp"] == "4.0.0"
    (envs,) = bench_result["envs"]
    assert envs["capture_fallback_reason"] == reason
    assert envs["nonfinite_worlds"] == 0
    # Both rates are rounded to 0.1: ten times the one is within 0.5 + 0.05 of the other.
    assert envs["env_steps_per_s"] > 0 and envs["env_physics_steps_per_s"] == pytest.approx(
        10 * envs["env_steps_per_s"], abs=0.6
    )
    assert envs["raw_physics_steps_per_s"] > 0
    split = envs["split_ms_per_env_step"]
    assert split["graph"] > 0 and split["refresh"] > 0 and split["total"] >= split["graph"]
    # Kernel by kernel on the CPU: hundreds of launches per step, no graph, no torch sync count.
    counts = envs["per_step_counts"]
    assert counts["warp_kernel_launches"] > 100 and counts["graph_launches"] == 0
    assert counts["torch_host_syncs"] is None
    assert envs["memory"] == {"torch_max_allocated_mib": None, "warp_mempool_high_mib": None}


@pytest.mark.slow
def test_bench_trains_and_monitors_overflow(bench_result: dict) -> None:
    (envs,) = bench_result["envs"]
    training = envs["training"]
    assert training["iterations_run"] == 2 and training["finite"]
    assert training["samples_per_s"] > 0
    d = envs["diagnostics"]
    assert 0 < d["contacts_peak_world"] <= d["contacts_capacity_world"] == 48
    assert d["contacts_capacity_total"] == 4 * 48 and d["constraints_capacity_world"] == 256
    assert 0 < d["constraints_peak_world"] <= 256
    assert d["contact_overflow"] == d["constraint_overflow"] == d["overflow_worlds"] == 0
    assert 1 <= d["solver_iterations_mean"] <= d["solver_iterations_max"] <= d["solver_iterations_limit"]


@pytest.mark.offline
def test_cuda_with_a_cpu_torch_is_refused_before_warp(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setitem(sys.modules, "rd_pipeline.env.physics.warp", None)  # importing it would raise
    with pytest.raises(PipelineError) as error:
        make_backend("warp", [], threads=1, device="cuda")
    expected = (
        f"train.env.device 'cuda': torch {torch.__version__} has no CUDA: "
        'install the CUDA build, see docs/training.md "Training on a GPU"'
    )
    assert str(error.value) == expected


def test_warp_diagnostics_report_peaks_since_the_last_call() -> None:
    pytest.importorskip("mujoco_warp", reason="the gpu extra (mujoco-warp) is not installed")
    from rd_pipeline.env.physics.warp import MujocoWarpBackend

    base = simulation_model(load_robot("g1"), collision="primitive")
    lying = copy.copy(base)
    backend = MujocoWarpBackend([base, lying], device="cpu", contacts_per_world=8, constraints_per_world=64)
    qpos = torch.zeros(2, base.nq, dtype=torch.float64)
    qpos[:, 3] = 1.0
    qpos[0, 2] = 3.0  # in the air: no contact
    qpos[1, 2] = 0.1  # the pelvis at the floor: more contacts than its 8 per world
    backend.set_state(torch.arange(2), qpos, torch.zeros(2, base.nv, dtype=torch.float64))
    backend.step(torch.zeros(2, base.nu), 5)
    d = backend.diagnostics()
    assert d["contacts_capacity_world"] == 8 and d["contacts_capacity_total"] == 16
    # Contacts are pooled: the lying world takes the airborne one's share before anything is lost.
    assert d["contacts_peak_world"] > 8 and d["contacts_peak_total"] > 16
    assert d["contact_overflow"] == 1 and d["overflow_worlds"] >= 1
    assert d["constraints_peak_world"] > 0 and d["solver_iterations_max"] >= 1
    assert backend.diagnostics()["contacts_peak_world"] == 0  # read, then zeroed
    backend.close()


def test_c_backends_report_contact_peaks_since_the_last_call() -> None:
    """C MuJoCo has no contact capacity to overflow: its backends report how many there were,
    from MuJoCo's high-water marks over every physics step."""
    from rd_pipeline.env.physics import MujocoCpuBackend, MujocoRolloutBackend

    base = simulation_model(load_robot("g1"), collision="primitive", body_sensors=True)
    qpos = torch.zeros(2, base.nq, dtype=torch.float64)
    qpos[:, 3] = 1.0
    qpos[0, 2] = 3.0  # in the air
    qpos[1, 2] = 0.1  # fallen
    figures = []
    for backend in (MujocoCpuBackend([base, base], 1), MujocoRolloutBackend([base, base], 1)):
        backend.set_state(torch.arange(2), qpos, torch.zeros(2, base.nv, dtype=torch.float64))
        backend.diagnostics()
        backend.step(torch.zeros(2, base.nu), 5)
        figures.append(backend.diagnostics())
        assert backend.diagnostics() == {"contacts_peak_world": 0.0, "constraints_peak_world": 0.0}
        backend.close()
    assert figures[0] == figures[1] and figures[0]["contacts_peak_world"] > 10
