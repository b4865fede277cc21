"""Benchmark: G1 retarget speed against GMR's, side by side, alone on one core, takes interleaved.

    python -m bench.gmr_speed --gmr-python /path/to/gmr-venv/bin/python --gmr-repo /path/to/GMR
                              [--robot g1] [--motions ...] [--rounds 2] [--core 0] [--out bench/results/gmr_speed]
                              [--profile TAKE]

GMR (General Motion Retargeting, GitHub YanjieZe/GMR) is not on PyPI and pins nothing, so it
gets a venv of its own, and nothing of it enters this project:

    git clone <GMR> GMR && python -m venv gmr-venv && gmr-venv/bin/pip install torch==2.13.0 \\
        mink mujoco scipy "qpsolvers[proxqp]" daqp loop_rate_limiters rich tqdm natsort psutil \\
        "imageio[ffmpeg]" && gmr-venv/bin/pip install --no-deps -e GMR

(its package imports torch and a viewer module even for a BVH retarget; its `smplx` dependency,
from a git URL, is for SMPL-X input only and is left out.)

GMR's `scripts/bvh_to_robot.py` always opens a MuJoCo viewer, so GMR runs through `GMR_TAKE`
below, in its venv: the same steps as that script (`load_lafan1_file`, then
`GeneralMotionRetargeting("bvh", "unitree_g1").retarget` frame by frame, then the script's
`--save_path` pickle), without the viewer and its rate limiter. Each round runs every take once
with each tool in turn, a fresh process per run pinned to `--core`; each is the whole command as
a user would run it, timed from the outside (interpreter start, imports, reading the BVH, the
retarget, writing the result): this project's `rd-pipeline run --robot g1 --until retarget` into a
fresh store, GMR's driver into a temporary file. The real-time factor is the take's duration over
the median wall seconds. This project's `g1` is the 23-DoF G1 (`--robot g1_29dof` for the 29-DoF
one, GMR's `unitree_g1`), and it writes its reference at 50 frames/s where GMR keeps the BVH's 30, so
the two do not solve the same number of frames. Writes `<out>.json` and `<out>.md`.

`--profile TAKE` instead runs this project's command for that take under cProfile and writes the
functions with the most cumulative and the most own time to `<out>_profile_<TAKE>.md`.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.common import head_commit, write_result
from bench.retarget import shared_takes
from rd_pipeline import paths

GMR_TAKE = """
import json, pickle, sys, time
began = time.perf_counter()
import numpy as np
from general_motion_retargeting import GeneralMotionRetargeting
from general_motion_retargeting.utils.lafan1 import load_lafan1_file
imported = time.perf_counter()
frames, height = load_lafan1_file(sys.argv[1])
retargeter = GeneralMotionRetargeting(src_human="bvh", tgt_robot="unitree_g1", actual_human_height=height)
loaded = time.perf_counter()
qpos = np.array([retargeter.retarget(frame) for frame in frames])
solved = time.perf_counter()
motion = {"fps": 30, "root_pos": qpos[:, :3], "root_rot": qpos[:, [4, 5, 6, 3]], "dof_pos": qpos[:, 7:],
          "local_body_pos": None, "link_body_list": None}
with open(sys.argv[2], "wb") as f:
    pickle.dump(motion, f)
print(json.dumps({"frames": len(frames), "import_s": imported - began, "load_s": loaded - imported,
                  "retarget_s": solved - loaded}))
"""
"""GMR's `scripts/bvh_to_robot.py --robot unitree_g1 --save_path`, less the viewer: run in GMR's venv."""

SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""One core each: a BLAS that starts threads on a pinned process would only make them fight."""

PROFILE_ROWS = 25


def main() -> None:
    args = _parser().parse_args()
    if args.profile:
        profile(args.robot, args.profile, args.core, args.out)
        return
    if not (args.gmr_python and args.gmr_repo):
        _parser().error("--gmr-python and --gmr-repo are required (see the module docstring)")
    motions = args.motions or shared_takes()
    load_before = os.getloadavg()[0]
    runs: dict[str, dict[str, list[dict]]] = {motion: {"rd": [], "gmr": []} for motion in motions}
    for round_index in range(args.rounds):
        for motion in motions:
            # Each tool right after the other on the same take: a slow spell of the machine hits both.
            runs[motion]["rd"].append(_rd_run(args.robot, motion, args.core))
            runs[motion]["gmr"].append(_gmr_run(args.gmr_python, args.gmr_repo, motion, args.core))
            rd, gmr = runs[motion]["rd"][-1]["wall_s"], runs[motion]["gmr"][-1]["wall_s"]
            print(f"round {round_index + 1} {motion}: rd {rd:.1f} s, gmr {gmr:.1f} s", flush=True)
    result = {
        "commit": head_commit(),
        "gmr_commit": head_commit(args.gmr_repo),
        "robot": args.robot,
        "gmr_robot": "unitree_g1",
        "core": args.core,
        "rounds": args.rounds,
        # The machine's 1-minute load before and after: well above 1 means something else shared it.
        "load_avg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "takes": [_row(motion, runs[motion]) for motion in motions],
    }
    write_result(args.out, result, _table(result))


def _rd_command(robot: str, motion: str) -> list[str]:
    return [sys.executable, "-m", "rd_pipeline", "run", "--robot", robot, "--motion", motion, "--until", "retarget"]


def _rd_run(robot: str, motion: str, core: int) -> dict[str, float]:
    """The whole `rd-pipeline run --until retarget` into an empty store, so parse and retarget both
    run, and each stage's own seconds as its manifest records them."""
    with tempfile.TemporaryDirectory() as store:
        env = {**os.environ, **SINGLE_THREAD, "RD_ARTIFACTS": store}
        command = ["taskset", "-c", str(core), *_rd_command(robot, motion)]
        began = time.perf_counter()
        subprocess.run(command, env=env, capture_output=True, check=True)
        wall = time.perf_counter() - began
        stages = _stage_seconds(Path(store))
    return {"wall_s": wall, "parse_s": stages["parse"], "retarget_s": stages["retarget"]}


def _stage_seconds(store: Path) -> dict[str, float]:
    return {
        manifest.relative_to(store).parts[0]: json.loads(manifest.read_text())["duration_s"]
        for manifest in store.glob("*/**/manifest.json")
    }


def _gmr_run(gmr_python: Path, gmr_repo: Path, motion: str, core: int) -> dict[str, float]:
    """GMR's whole retarget of the take, and the parts its driver timed from inside."""
    with tempfile.TemporaryDirectory() as folder:
        # GMR first on the path, so the checkout given is the one measured even without its editable install.
        env = {**os.environ, **SINGLE_THREAD, "PYTHONPATH": str(gmr_repo)}
        bvh = paths.bvh_path(motion)
        command = ["taskset", "-c", str(core), str(gmr_python), "-c", GMR_TAKE, str(bvh), f"{folder}/{motion}.pkl"]
        began = time.perf_counter()
        done = subprocess.run(command, env=env, cwd=gmr_repo, capture_output=True, text=True, check=True)
        wall = time.perf_counter() - began
    return {"wall_s": wall, **json.loads(done.stdout.strip().splitlines()[-1])}


def _take_seconds(motion: str) -> tuple[int, float]:
    """Frames and duration from the BVH header (LAFAN1: 30 frames/s)."""
    frames, frame_time = 0, 0.0
    with paths.bvh_path(motion).open() as bvh:
        for line in bvh:
            if line.startswith("Frames:"):
                frames = int(line.split()[1])
            elif line.startswith("Frame Time:"):
                frame_time = float(line.split()[2])
                break
    return frames, frames * frame_time


def _row(motion: str, runs: dict[str, list[dict]]) -> dict:
    frames, duration = _take_seconds(motion)
    rd = {part: _median(runs["rd"], part) for part in ("wall_s", "parse_s", "retarget_s")}
    gmr = {part: _median(runs["gmr"], part) for part in ("wall_s", "import_s", "load_s", "retarget_s")}
    return {
        "motion": motion,
        "frames": frames,
        "take_s": round(duration, 2),
        "rd_rtf": round(duration / rd["wall_s"], 2),
        "gmr_rtf": round(duration / gmr["wall_s"], 2),
        "rtf_ratio_rd_to_gmr": round(gmr["wall_s"] / rd["wall_s"], 3),
        # Medians of each part, then every run: where each tool's seconds go.
        "rd_median_s": rd,
        "gmr_median_s": gmr,
        "rd_runs": [{part: round(v, 3) for part, v in run.items()} for run in runs["rd"]],
        "gmr_runs": [{part: round(v, 3) for part, v in run.items() if part != "frames"} for run in runs["gmr"]],
    }


def _median(runs: list[dict], part: str) -> float:
    return round(statistics.median(run[part] for run in runs), 3)


def _table(result: dict) -> str:
    lines = [
        "| take | frames | take s | rd wall s | GMR wall s | rd RTF | GMR RTF | rd/GMR "
        "| rd start / parse / retarget s | GMR start / load / loop s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["takes"]:
        rd, gmr = row["rd_median_s"], row["gmr_median_s"]
        rd_start = rd["wall_s"] - rd["parse_s"] - rd["retarget_s"]
        gmr_start = gmr["wall_s"] - gmr["load_s"] - gmr["retarget_s"]
        lines.append(
            f"| {row['motion']} | {row['frames']} | {row['take_s']:.1f} | {rd['wall_s']:.2f} | {gmr['wall_s']:.2f} "
            f"| {row['rd_rtf']:.1f} | {row['gmr_rtf']:.1f} | {row['rtf_ratio_rd_to_gmr']:.2f} "
            f"| {rd_start:.1f} / {rd['parse_s']:.1f} / {rd['retarget_s']:.1f} "
            f"| {gmr_start:.1f} / {gmr['load_s']:.1f} / {gmr['retarget_s']:.1f} |"
        )
    ratios = [row["rtf_ratio_rd_to_gmr"] for row in result["takes"]]
    at_or_above = sum(ratio >= 1.0 for ratio in ratios)
    lines.append(
        f"\nWhole commands, each in a fresh process on one core ({result['core']}), median of "
        f"{result['rounds']} round(s): `rd-pipeline run --robot {result['robot']} --until retarget` into an empty "
        f"store, and GMR's BVH -> `{result['gmr_robot']}` retarget without its viewer. RTF = take duration / wall "
        f"seconds; rd/GMR = rd RTF / GMR RTF: median {statistics.median(ratios):.2f} ({min(ratios):.2f} to "
        f"{max(ratios):.2f}); rd at or above GMR on {at_or_above} of {len(ratios)} takes. Start = the wall less the "
        f"parts timed inside (interpreter, imports, store; GMR's start includes its imports). "
        f"Load average before and after {result['load_avg_1min']}. Commit {result['commit']}, GMR {result['gmr_commit']}."
    )
    return "\n".join(lines) + "\n"


def profile(robot: str, motion: str, core: int, out: Path) -> None:
    """This project's command for one take under cProfile: where its seconds go."""
    with tempfile.TemporaryDirectory() as store:
        stats_file = Path(store) / "run.prof"
        env = {**os.environ, **SINGLE_THREAD, "RD_ARTIFACTS": store}
        command = [sys.executable, "-m", "cProfile", "-o", str(stats_file), *_rd_command(robot, motion)[1:]]
        began = time.perf_counter()
        subprocess.run(["taskset", "-c", str(core), *command], env=env, capture_output=True, check=True)
        wall = time.perf_counter() - began
        stages = _stage_seconds(Path(store))
        stats = pstats.Stats(str(stats_file))
    frames, duration = _take_seconds(motion)
    lines = [
        f"# Profile: `rd-pipeline run --robot {robot} --motion {motion} --until retarget`\n",
        f"Commit {head_commit()}, one core ({core}), cProfile on, empty store. {frames} frames ({duration:.1f} s "
        f"of take). Wall {wall:.1f} s under the profiler: parse stage {stages['parse']:.1f} s, retarget stage "
        f"{stages['retarget']:.1f} s, the rest ({wall - stages['parse'] - stages['retarget']:.1f} s) interpreter, "
        "imports and store. cProfile slows Python-heavy code more than calls into C, so the shares lean towards "
        "Python.\n",
    ]
    for key, title in (("cumulative", "Most cumulative time"), ("tottime", "Most own time")):
        lines += [
            f"\n## {title}\n",
            "| function | calls | own s | cumulative s | cumulative % |",
            "|---|---|---|---|---|",
        ]
        lines += [_profile_row(entry, stats) for entry in _top(stats, key)]
    text = "\n".join(lines) + "\n"
    target = out.with_name(f"{out.name}_profile_{motion}.md")
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)
    print(text)


def _top(stats: pstats.Stats, key: str) -> list[tuple]:
    """The rows with the most `key` time; the import machinery's many frames only as one row, the
    outermost `_find_and_load` (all imports together: cProfile counts a recursive call once)."""
    column = {"cumulative": 4, "tottime": 3}[key]  # in (function, cc, nc, tt, ct, callers)
    entries = [(function, *values) for function, values in stats.stats.items()]  # type: ignore[attr-defined]
    kept = [entry for entry in entries if not _machinery(entry[0])]
    return sorted(kept, key=lambda entry: entry[column], reverse=True)[:PROFILE_ROWS]


def _machinery(function: tuple[str, int, str]) -> bool:
    filename, _, name = function
    if filename.startswith("<frozen importlib") or filename == "<frozen runpy>":
        return name != "_find_and_load"
    return name in ("<built-in method builtins.exec>", "<built-in method builtins.__import__>")


def _profile_row(entry: tuple, stats: pstats.Stats) -> str:
    (filename, line, name), _, calls, own, cumulative, _ = entry
    where = _short(filename)
    label = f"{where}:{line}({name})" if line else name
    return f"| `{label}` | {calls} | {own:.2f} | {cumulative:.2f} | {100 * cumulative / stats.total_tt:.0f} |"


def _short(filename: str) -> str:
    """A path from its package on: `site-packages/` and the checkout's root say nothing."""
    if "site-packages/" in filename:
        return filename.split("site-packages/", 1)[1]
    for package in ("/rd_pipeline/", "/stages/"):
        if package in filename:
            return package[1:] + filename.split(package, 1)[1]
    return Path(filename).name if filename.startswith("/") else filename


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gmr-python", type=Path, help="python of a venv with GMR installed (module docstring)")
    parser.add_argument("--gmr-repo", type=Path, help="checkout of GMR (its assets and IK configs)")
    parser.add_argument("--robot", default="g1", help="this project's robot (GMR's is always unitree_g1)")
    parser.add_argument("--motions", nargs="*", default=None)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--core", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("bench/results/gmr_speed"))
    parser.add_argument("--profile", metavar="TAKE", help="profile this project's retarget of TAKE instead")
    return parser


if __name__ == "__main__":
    main()
