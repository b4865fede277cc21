"""Full disks, signals, damaged checkpoints, a store removed under a run: issue 67's cases, each
reproduced as a user meets it, through the command line."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import pytest
from conftest import PROJECT, cli, start_cli

from rd_pipeline.training.log import LOG_FILE, checkpoint_path, intact_checkpoints, read_training_log

TAKE = ("--robot", "g1", "--motion", "dance1_subject2", "--source", "csv", "--clip", "0:4")
TRAIN = ("run", *TAKE, "--until", "train", "--set", "train.checkpoint_every=2")
SHORT = (*TRAIN, "train.iterations=12")
"""A training a signal reaches in its middle: a checkpoint every 2 of 12 iterations (each about
a second with its scoring, so one sent at the fourth lands before the end)."""
LONG = (*TRAIN, "train.iterations=400")
"""A training that is still running whenever a test acts on it."""


@pytest.fixture(scope="module")
def seed_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """G1 dance1_subject2 (dataset CSV, first 4 s) through export, made once for the module."""
    root = tmp_path_factory.mktemp("faults") / "seed"
    made = cli("run", *TAKE, "--until", "export", env={"RD_ARTIFACTS": str(root)})
    assert made.returncode == 0, made.stderr
    return root


def _store(seed: Path, artifacts: Path, *stages: str) -> Path:
    for stage in stages:
        shutil.copytree(seed / stage, artifacts / stage)
    return artifacts


def _work_with_checkpoint(artifacts: Path, iteration: int, timeout_s: float = 300) -> Path:
    """The training work folder once the checkpoint of `iteration` is saved and sealed."""
    folder = artifacts / "train" / "g1" / "dance1_subject2"
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        for work in folder.glob(".work-*"):
            if (work / ".seals" / f"model_{iteration}.json").is_file():
                return work
        time.sleep(0.1)
    raise AssertionError(f"no checkpoint {iteration} in {folder} within {timeout_s} s")


def _train_states(env: Mapping[str, str], *sets: str) -> dict:
    status = subprocess.run(
        [sys.executable, "-m", "rd_pipeline", "status", *TAKE, "--json", "--set", *sets],
        capture_output=True,
        text=True,
        cwd=PROJECT,
        env=dict(env),
    )
    return {row["stage"]: row for row in json.loads(status.stdout)["pipelines"][0]["stages"]}["train"]


def _leftovers(artifacts: Path) -> list[str]:
    return sorted(p.name for p in artifacts.rglob(".*") if p.name.startswith((".tmp-", ".lock-")))


@pytest.fixture(scope="module")
def interrupted(seed_store: Path) -> Path:
    """A store whose training (SHORT) was stopped by SIGTERM after its fourth iteration, made
    once for the module: what it said and left is checked here."""
    artifacts = seed_store.with_name("interrupted")
    for stage in ("import", "stats", "prior"):
        shutil.copytree(seed_store / stage, artifacts / stage)
    env = {**os.environ, "RD_ARTIFACTS": str(artifacts)}
    run = subprocess.Popen(
        [sys.executable, "-m", "rd_pipeline", *SHORT], cwd=PROJECT, stderr=subprocess.PIPE, text=True, env=env
    )
    work = _work_with_checkpoint(artifacts, 4)
    running = _train_states(env, *SHORT[-2:])
    assert running["state"] == "running", running
    run.send_signal(signal.SIGTERM)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 143, stderr
    assert stderr.strip().splitlines()[-1] == (
        f"interrupted by SIGTERM: no partial artifact was kept; train kept its progress in {work}; "
        "the same command continues from it (--force starts over)"
    )
    assert _leftovers(artifacts) == []
    return artifacts


def _copy_interrupted(interrupted: Path, artifacts: Path) -> Path:
    """The interrupted store copied into the test's; its work folder."""
    shutil.copytree(interrupted, artifacts)
    (work,) = (artifacts / "train" / "g1" / "dance1_subject2").glob(".work-*")
    # On a loaded machine SIGTERM can land while a checkpoint is being saved: that one has no
    # seal and is passed over, as it should be. The tests below damage the newest sealed one.
    _, unsealed = intact_checkpoints(work)
    for path in unsealed:
        path.unlink()
    return work


@pytest.mark.slow
def test_sigterm_keeps_the_progress_and_a_damaged_checkpoint_is_passed_over(interrupted: Path, artifacts: Path) -> None:
    work = _copy_interrupted(interrupted, artifacts)
    newest = max((work / "checkpoints").glob("model_*.pt"), key=lambda p: int(p.stem[6:]))
    before = int(newest.stem[6:]) - 2
    # Finite bytes in place of a tensor's: torch loads it without a word.
    data = bytearray(newest.read_bytes())
    data[-4000:-3000] = bytes(1000)
    newest.write_bytes(bytes(data))
    state = _train_states(os.environ, *SHORT[-2:])
    assert state["state"] == "resumable"
    assert f"kept model_{before}.pt" in state["reason"]
    assert f"({newest.name}: its bytes changed since it was saved)" in state["reason"]
    rerun = cli(*SHORT)
    assert rerun.returncode == 0, rerun.stderr
    assert f"  {newest.name} is damaged (its bytes changed since it was saved): not continued from, deleted" in (
        rerun.stderr
    )
    assert f"  continuing the interrupted run from model_{before}.pt in {work}" in rerun.stderr
    (artifact,) = (artifacts / "train" / "g1" / "dance1_subject2").iterdir()
    assert [row["iteration"] for row in read_training_log(artifact)] == list(range(1, 13))
    assert not (artifact / ".seals").exists()


@pytest.mark.slow
def test_a_damaged_log_is_found_against_the_checkpoints(interrupted: Path, artifacts: Path) -> None:
    work = _copy_interrupted(interrupted, artifacts)
    log = work / LOG_FILE
    rows = log.read_text().splitlines(keepends=True)
    log.unlink()
    refused = cli(*SHORT)
    assert refused.returncode == 2
    last = refused.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {work}: no checkpoint there can be continued (model_")
    assert last.endswith(f"{LOG_FILE} no longer holds the rows it was saved with); `--force` starts over")
    assert _train_states(os.environ, *SHORT[-2:])["state"] == "damaged"
    # Rows past the second lost: the checkpoint of iteration 2 still matches its rows.
    log.write_text("".join(rows[:2]))
    rerun = cli(*SHORT)
    assert rerun.returncode == 0, rerun.stderr
    assert f"  continuing the interrupted run from {checkpoint_path(work, 2).name}" in rerun.stderr
    (artifact,) = (artifacts / "train" / "g1" / "dance1_subject2").iterdir()
    assert [row["iteration"] for row in read_training_log(artifact)] == list(range(1, 13))


@pytest.mark.slow
def test_a_store_removed_under_a_training_stops_it_in_one_line(seed_store: Path, artifacts: Path) -> None:
    _store(seed_store, artifacts, "import", "stats", "prior")
    run = start_cli(*LONG)
    work = _work_with_checkpoint(artifacts, 2)
    shutil.rmtree(artifacts)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 2, stderr
    assert stderr.strip().splitlines()[-1] == (
        f"error: {work} was removed while training ran; the run stops (its progress went with it)"
    )
    assert not artifacts.exists()  # nothing was made again in its place


def _processes_naming(text: str) -> list[str]:
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            words = cmdline.read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if text in words:
            found.append(words)
    return found


@pytest.mark.slow
def test_a_sigint_to_the_main_process_of_a_two_rank_run_stops_every_rank(seed_store: Path, artifacts: Path) -> None:
    _store(seed_store, artifacts, "import", "stats", "prior")
    run = start_cli(*LONG, "--nproc", "2")
    work = _work_with_checkpoint(artifacts, 2)
    assert len(_processes_naming(f"{work}.job.pt")) == 3  # torchrun and its two ranks
    # To the main process only, as `kill -INT` or a supervisor sends it (SIGTERM takes the same
    # path: it is turned into the same interrupt).
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert _processes_naming(str(artifacts)) == []
    assert _leftovers(artifacts) == []


def _namespaces_work() -> bool:
    try:
        done = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "true"], capture_output=True)
    except OSError:
        return False
    return done.returncode == 0


FULL_DISK_SCRIPT = """
set -e
mount -t tmpfs -o size=256m tmpfs "$STORE"
for stage in $STAGES; do cp -a "$SEED/$stage" "$STORE/"; done
avail=$(df --output=avail -B1024 "$STORE" | tail -1)
fallocate -l $(( (avail - FREE_KIB) * 1024 )) "$STORE/.filler"
set +e
i=0
while IFS= read -r line; do
  eval "timeout 300 $PYTHON -m rd_pipeline $line" 2> "$OUT/$i.err" > /dev/null
  echo $? > "$OUT/$i.rc"
  find "$STORE" -name '.tmp-*' -o -name '.lock-*' -o -name '*.partial*' > "$OUT/$i.left"
  i=$((i + 1))
done < "$OUT/commands"
"""


def _on_a_full_disk(
    seed: Path, store: Path, out: Path, stages: tuple[str, ...], *commands: str
) -> list[tuple[int, str, str]]:
    """Run each `rd-pipeline` command line on a store that is a 256 MiB tmpfs of its own (in a
    mount namespace, so no root is needed) holding the seed's `stages` and 256 KiB free; for each:
    exit code, stderr, and what it left half-written or locked."""
    out.mkdir()
    store.mkdir()
    (out / "commands").write_text("".join(f"{command}\n" for command in commands))
    env = {
        **os.environ,
        "STORE": str(store),
        "SEED": str(seed),
        "STAGES": " ".join(stages),
        "FREE_KIB": "256",
        "OUT": str(out),
        "PYTHON": sys.executable,
        "RD_ARTIFACTS": str(store),
    }
    namespace = ["unshare", "--user", "--map-root-user", "--mount", "bash", "-c", FULL_DISK_SCRIPT]
    subprocess.run(namespace, env=env, cwd=PROJECT, check=True, timeout=1200)
    return [
        (int((out / f"{i}.rc").read_text()), (out / f"{i}.err").read_text(), (out / f"{i}.left").read_text())
        for i in range(len(commands))
    ]


@pytest.mark.slow
@pytest.mark.skipif(not _namespaces_work(), reason="needs unshare (user and mount namespaces) for a small disk")
def test_a_full_disk_is_one_line_naming_the_folder_and_leaves_nothing_half_written(
    seed_store: Path, tmp_path: Path
) -> None:
    store = tmp_path / "store"
    take = " ".join(TAKE)
    commands = {
        "import": "run --robot h1_2 --motion dance2_subject4 --until import",
        "train": f"run {take} --until train --set train.iterations=4",
        "validate": f"run {take}",
        "views": f"view {take} --out {store}/views/take.rrd",
    }
    stages = ("import", "stats", "prior", "train", "export")
    results = _on_a_full_disk(seed_store, store, tmp_path / "out", stages, *commands.values())
    for (folder, command), (code, stderr, left) in zip(commands.items(), results):
        last = stderr.strip().splitlines()[-1]
        assert code == 2 and "Traceback" not in stderr, (command, stderr)
        where = store / folder
        if folder != "views":
            where = where / ("h1_2/dance2_subject4" if folder == "import" else "g1/dance1_subject2")
        assert last.startswith(f"error: cannot write {where}: no space left on its disk; it needed "), last
        assert last.endswith(" free there); free some space and run again"), last
        assert left == "", (command, left)


@pytest.mark.slow
def test_a_file_size_limit_is_one_line_and_the_key_is_free_again(artifacts: Path) -> None:
    # The portable stand-in for a full disk: a write past RLIMIT_FSIZE fails as one would.
    import resource

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, 2**20))

    args = ["run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "import"]
    done = subprocess.run(
        [sys.executable, "-m", "rd_pipeline", *args],
        cwd=PROJECT,
        capture_output=True,
        text=True,
        env=os.environ.copy(),
        preexec_fn=limited,
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    folder = artifacts / "import" / "h1_2" / "dance2_subject4"
    assert (
        done.stderr.strip()
        .splitlines()[-1]
        .startswith(
            f"error: cannot write {folder}: a file grew past this process's size limit (ulimit -f); it needed more than "
        )
    )
    assert list(folder.iterdir()) == []
    again = cli(*args)
    assert again.returncode == 0, again.stderr
