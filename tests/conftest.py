"""Tests read the real data from ../shared (SPEC); each test gets its own artifact store."""

from __future__ import annotations

import fcntl
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
import pytest

from rd_pipeline.retarget.config import IkConfig
from rd_pipeline.robots import Robot, load_robot

PROJECT = Path(__file__).resolve().parent.parent
SHARED = PROJECT.parent / "shared"

for variable, default in {
    "RD_LAFAN_DIR": SHARED / "data" / "lafan1" / "bvh",
    "RD_RETARGETED_DIR": SHARED / "data" / "lafan1_retargeted",
    "RD_ROBOT_ASSETS": SHARED / "robots",
}.items():
    os.environ.setdefault(variable, str(default))

# Two test workers share the machine's cores: torch on one thread in each (and in the runs they
# start), or the idle threads of one worker's PPO update spin on the cores the other needs.
os.environ.setdefault("OMP_NUM_THREADS", "1")

LAFAN_DIR = Path(os.environ["RD_LAFAN_DIR"])
RETARGETED_DIR = Path(os.environ["RD_RETARGETED_DIR"])
ROBOT_ASSETS = Path(os.environ["RD_ROBOT_ASSETS"])
MISSING_DATA = [str(p) for p in (LAFAN_DIR, RETARGETED_DIR, ROBOT_ASSETS) if not p.is_dir()]


@pytest.fixture(scope="session")
def g1() -> Robot:
    """The G1 model, loaded once."""
    return load_robot("g1")


@pytest.fixture
def foot_positions() -> Callable[[Robot, np.ndarray], np.ndarray]:
    """(T, 2, 3) the robot's foot bodies' positions in each row of a (T, nq) motion."""

    def positions(robot: Robot, qpos: np.ndarray) -> np.ndarray:
        data = mujoco.MjData(robot.model)
        feet = [robot.body_ids[foot] for foot in robot.config.foot_bodies]
        out = np.empty((len(qpos), 2, 3))
        for t, q in enumerate(qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(robot.model, data)
            out[t] = data.xpos[feet]
        return out

    return positions


@pytest.fixture
def limit_breaches() -> Callable[[Robot, np.ndarray, float], tuple[int, int]]:
    """Counts, in a (T, nq) motion at `fps`: joint values outside the robot's retarget range, and
    frame steps over the IK's share of its velocity limits."""

    def count(robot: Robot, qpos: np.ndarray, fps: float) -> tuple[int, int]:
        joints = qpos[:, robot.qpos_indices]
        lower, upper = robot.retarget_range.T
        outside = int(np.sum((joints < lower) | (joints > upper)))
        step_limit = robot.config.velocity_limit / fps * IkConfig().velocity_margin + 1e-9
        too_fast = int(np.sum(np.abs(np.diff(joints, axis=0)) > step_limit))
        return outside, too_fast

    return count


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Test files holding the most slow tests first, so the two workers end together on the fast
    files (each file's tests keep their order); without the real data every test that reads it is
    skipped, saying which folder is missing."""
    slow_tests: dict[Path, int] = {}
    for item in items:
        slow_tests[item.path] = slow_tests.get(item.path, 0) + ("slow" in item.keywords)
    items.sort(key=lambda item: -slow_tests[item.path])
    if not MISSING_DATA:
        return
    reason = (
        f"needs the shared data, missing: {', '.join(MISSING_DATA)} "
        "(set RD_LAFAN_DIR, RD_RETARGETED_DIR and RD_ROBOT_ASSETS, or put the data in ../shared)"
    )
    for item in items:
        if "offline" not in item.keywords:
            item.add_marker(pytest.mark.skip(reason=reason))


@pytest.fixture
def artifacts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "artifacts"
    monkeypatch.setenv("RD_ARTIFACTS", str(root))
    return root


class ReferenceSeeds:
    """The parse and retarget artifacts of a BVH take, made once per test session and copied into
    a test's store: tests of the stages after retargeting start where a user's second run does, and
    the suite retargets each take it uses once instead of once per test. The test workers share
    the seeds: the first to need a take makes it while the others wait on its lock."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def into(self, store: Path, robot: str, motion: str) -> Path:
        """Copy `robot`/`motion`'s reference artifacts (default retarget params) into `store`."""
        seed = self.root / robot / motion
        seed.mkdir(parents=True, exist_ok=True)
        with (self.root / f"{robot}-{motion}.lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not (seed / "retarget").is_dir():
                made = cli(
                    "run", "--robot", robot, "--motion", motion, "--until", "retarget", env={"RD_ARTIFACTS": str(seed)}
                )
                assert made.returncode == 0, made.stderr
        for stage in ("parse", "retarget"):
            shutil.copytree(seed / stage, store / stage, dirs_exist_ok=True)
        return store


@pytest.fixture(scope="session")
def reference_seeds(tmp_path_factory: pytest.TempPathFactory) -> ReferenceSeeds:
    # Under xdist, beside the workers' own temporary folders: the same for every worker of this
    # session (and of no other).
    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if "PYTEST_XDIST_WORKER" in os.environ else base) / "reference_seeds"
    shared.mkdir(exist_ok=True)
    return ReferenceSeeds(shared)


@pytest.fixture
def g1_dance_store(artifacts: Path, reference_seeds: ReferenceSeeds) -> Path:
    """The test's store, already holding G1 dance1_subject2's reference (the embedded default)."""
    return reference_seeds.into(artifacts, "g1", "dance1_subject2")


def cli(*args: str, env: dict[str, str] | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `rd-pipeline` in a subprocess, as a user would."""
    return subprocess.run(
        [sys.executable, "-m", "rd_pipeline", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        cwd=cwd or PROJECT,
        timeout=600,
    )


def start_cli(*args: str) -> subprocess.Popen:
    """`rd-pipeline` in the background, stderr piped, as a user's terminal starts it: a shell that
    started pytest in the background ignores SIGINT and children inherit that, so the child gets
    the default disposition back (Python then raises KeyboardInterrupt)."""
    return subprocess.Popen(
        [sys.executable, "-m", "rd_pipeline", *args],
        cwd=PROJECT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ.copy(),
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def h1_2_dance_reference():
    """H1-2 dance2_subject4 from the dataset CSV, resampled to 50 fps."""
    from rd_pipeline.motion.contact import ContactThresholds
    from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
    from rd_pipeline.robots import load_robot

    robot = load_robot("h1_2")
    path = RETARGETED_DIR / "h1_2" / "dance2_subject4.csv"
    return import_retargeted_csv(path, robot, 30.0, 50.0, "cubic", ContactThresholds()).reference


def h1_2_dance_env(config, seed: int = 3, sampler_config=None):
    """A tracking environment on H1-2 dance2_subject4 (dataset CSV), one-second segments, the
    sampler of `sampler_config` (the default one when not given) on a flat balanced prior."""
    import torch

    from rd_pipeline.env.tracking_env import TrackingEnv
    from rd_pipeline.robots import load_robot
    from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
    from rd_pipeline.sampling.segments import segment_bounds

    reference = h1_2_dance_reference()
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(sampler_config or SamplerConfig(), torch.ones(len(starts)), seed=seed)
    return TrackingEnv(load_robot("h1_2"), reference, sampler, starts, lengths, config, seed=seed)


def h1_2_dance_job(config, work: Path, checkpoint: Path | None = None):
    """A training job on the first 10 s of H1-2 dance2_subject4, one-second segments, flat prior."""
    import numpy as np

    from rd_pipeline.robots import load_robot
    from rd_pipeline.sampling.segments import segment_bounds
    from rd_pipeline.training.runner import Segments, TrainingJob

    reference = h1_2_dance_reference().frames(0, 500)
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    segments = Segments(starts, lengths, np.zeros(len(starts)))
    return TrainingJob(load_robot("h1_2"), reference, segments, config, work, checkpoint)


def video_frames(path: Path) -> list[np.ndarray]:
    """The (height, width, 3) frames of an MP4, decoded by the ffmpeg that encoded it."""
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    width, height = next(reader)["size"]
    return [np.frombuffer(frame, np.uint8).reshape(height, width, 3) for frame in reader]


def check_smoke_training_and_export(artifacts: Path, robot: str, motion: str) -> None:
    """What a smoke run to export left in `artifacts`: two scored iterations, the paper's selective
    residuals, the last checkpoint exported unless `export.best_by` ranks them."""
    import json

    from rd_pipeline.training.log import read_training_log

    (folder,) = (artifacts / "train" / robot / motion).iterdir()
    assert (folder / "learning_curve.png").is_file() and (folder / "checkpoints" / "model_2.pt").is_file()
    metrics = json.loads((folder / "manifest.json").read_text())["metrics"]
    assert metrics["iterations"] == 2 and metrics["num_envs"] == 8
    # The paper's selective residuals: one output per policy joint, residual on hip and knee pitch,
    # absolute on every other joint.
    (exported,) = (artifacts / "export" / robot / motion).iterdir()
    action = json.loads((exported / "policy.json").read_text())["action"]
    assert action["mode"] == "selective"
    assert len(action["outputs"]) == {"g1": 23, "h1": 19, "h1_2": 21}[robot] == metrics["num_actions"]
    # Both checkpoints are scored; export takes the last, fixed by iteration, unless asked to rank.
    scores = {row["iteration"]: (row["start_zero_s"], row["completion"]) for row in read_training_log(folder)}
    assert metrics["best_checkpoint"] == max(scores, key=lambda it: (*scores[it], it))
    assert json.loads((exported / "manifest.json").read_text())["metrics"]["checkpoint_iteration"] == 2
    # export.best_by=completion orders the same scores completion first
    args = ("run", "--robot", robot, "--motion", motion, "--until", "export", "--profile", "smoke")
    by_completion = cli(*args, "--set", "export.best_by=completion")
    assert by_completion.returncode == 0, by_completion.stderr
    (other,) = [p for p in (artifacts / "export" / robot / motion).iterdir() if p != exported]
    completion_first = max(scores, key=lambda it: (scores[it][1], scores[it][0], it))
    assert json.loads((other / "manifest.json").read_text())["metrics"]["checkpoint_iteration"] == completion_first
    residual = [joint for joint, kind in zip(action["outputs"], action["semantics"]) if kind == "residual"]
    assert sorted(residual) == sorted(
        f"{side}_{joint}_joint" for side in ("left", "right") for joint in ("hip_pitch", "knee")
    )
    assert action["semantics"].count("absolute") == len(action["outputs"]) - 4
