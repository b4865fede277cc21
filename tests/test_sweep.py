"""Sweeps on a local Ray instance (a failing trial does not stop the others) and the ablation table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import PROJECT, cli

from rd_pipeline.api.sweeps import SHARED_UNTIL, Trial, run_sweep, shared_upstream_args, validation_report

FAST = ("train.iterations=1", "train.clip=0:4", "validate.render.enabled=false")
"""One PPO iteration on 4 s of motion: one validation start per trial (the smoke grid is 10 s),
no pictures (test_export looks at them)."""


@pytest.mark.usefixtures("g1_dance_store")
@pytest.mark.slow
def test_ray_sweep_reports_a_failing_trial_and_finishes_the_others(artifacts: Path) -> None:
    pytest.importorskip("ray", reason="the ray extra is not installed (CI installs it)")
    trials = [
        Trial("g1", "dance1_subject2", 0, "fast", FAST),
        Trial("g1", "dance1_subject2", 1, "fast", FAST),
        Trial("g1", "dance1_subject2", 0, "broken", ("train.iterations=1", "train.clip=0:0.5")),
    ]
    seen = []

    results = run_sweep(trials, "smoke", "ray", 2, None, lambda t: validation_report(t, "smoke"), seen.append)
    assert [r.ok for r in results] == [True, True, False]
    assert "must end more than 1 s after it starts, got '0:0.5'" in results[2].error
    assert results[0].metrics["zero_action_start_zero_survival_s"] > 0.2
    assert results[0].metrics["E_g_mpbpe"] != results[1].metrics["E_g_mpbpe"]  # two seeds, two policies
    # The shared upstream was computed once: one artifact per upstream stage.
    for stage in ("parse", "retarget", "stats", "prior"):
        folder = artifacts / stage / ("" if stage == "parse" else "g1")
        assert len(list(folder.glob("**/manifest.json"))) == 1, stage
    assert len(seen) == 3


@pytest.mark.usefixtures("g1_dance_store")
@pytest.mark.slow
def test_ablate_residual_writes_the_paper_table(artifacts: Path) -> None:
    result = cli(
        "ablate",
        "residual",
        "--robots",
        "g1",
        "--motions",
        "dance1_subject2",
        "--seeds",
        "0",
        "--arms",
        "absolute",
        "all",
        "selective",
        "--set",
        *FAST,
    )
    assert result.returncode == 0, result.stderr
    (folder,) = (artifacts / "sweeps").iterdir()
    table = json.loads((folder / "ablation.json").read_text())
    assert list(table["table"]) == ["absolute", "all", "selective"] and table["failed_trials"] == []
    for arm in table["table"].values():
        assert arm["E_g_mpbpe"]["n"] == 1 and arm["E_g_mpbpe"]["mean"] > 0 and arm["E_g_mpbpe"]["ci95"] is None
    markdown = (folder / "ablation.md").read_text()
    assert "| selective |" in markdown and "E_mpjve" in markdown
    summary = json.loads((folder / "summary.json").read_text())
    assert sorted(row["variant"] for row in summary) == ["absolute", "all", "selective"]
    # The baseline is the reference fed to PD in every arm, `absolute` included.
    assert len({row["zero_action_start_zero_survival_s"] for row in summary}) == 1


def test_difference_interval_is_welchs_and_exact_without_spread() -> None:
    from scipy import stats

    from rd_pipeline.evaluation.metrics import difference_interval

    first = [9.98, 1.94, 9.64]
    second = [2.68, 9.98]
    interval = difference_interval(first, second)
    var_first = np.var(first, ddof=1) / 3
    var_second = np.var(second, ddof=1) / 2
    dof = (var_first + var_second) ** 2 / (var_first**2 / 2 + var_second**2 / 1)
    half = stats.t.ppf(0.975, dof) * np.sqrt(var_first + var_second)
    difference = np.mean(first) - np.mean(second)
    assert interval["difference"] == pytest.approx(difference, abs=1e-3)
    assert interval["low"] == pytest.approx(difference - half, abs=1e-3)
    assert interval["high"] == pytest.approx(difference + half, abs=1e-3)
    assert difference_interval([9.98, 9.98], [0.92, 0.92]) == {"difference": 9.06, "low": 9.06, "high": 9.06}
    assert difference_interval([9.98], [0.92, 0.96])["low"] is None


def test_findings_are_judged_by_the_side_of_zero_their_interval_lies_on(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(PROJECT))  # the paper's claims are study code
    from studies.findings import Claim, judge

    lower_error = Claim("SELECTIVE has a lower E_mpjpe than NONE", "E_mpjpe", "selective", "absolute", False)
    seeds = {
        "selective": [{"E_mpjpe": v} for v in (117.2, 137.5, 138.6)],
        "absolute": [{"E_mpjpe": v} for v in (144.1, 138.0, 146.3)],
        "all": [{"E_mpjpe": v} for v in (64.7, 75.5)],
    }
    assert judge(lower_error, seeds)["verdict"] == "undecided"
    assert judge(lower_error, seeds)["difference"] == pytest.approx(11.7, abs=0.05)
    all_lower = Claim("ALL has a lower E_mpjpe than SELECTIVE", "E_mpjpe", "all", "selective", False)
    assert judge(all_lower, seeds)["verdict"] == "supported"
    all_higher = Claim("ALL has a higher E_mpjpe than SELECTIVE", "E_mpjpe", "all", "selective", True)
    assert judge(all_higher, seeds)["verdict"] == "contradicted"
    seeds["all"] = seeds["all"][:1]
    assert judge(all_lower, seeds)["verdict"] == "not judged (under 2 seeds)"


def test_the_shared_upstream_is_made_with_the_overrides_every_trial_of_the_take_has() -> None:
    arms = [
        Trial("g1", "dance1_subject2", 0, "a", ("retarget.ik.max_iters=5", "train.env.actions.mode=all")),
        Trial("g1", "dance1_subject2", 1, "b", ("retarget.ik.max_iters=5", "train.env.actions.mode=absolute")),
    ]
    made = (
        f"run --robot g1 --motion dance1_subject2 --until {SHARED_UNTIL} --profile smoke --set retarget.ik.max_iters=5"
    )
    assert shared_upstream_args(arms, "smoke") == made.split()
    assert "--set" not in shared_upstream_args([Trial("g1", "dance1_subject2", 0)], None)
