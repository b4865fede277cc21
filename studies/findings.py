"""The paper's reported figures and findings that the CPU-scale ablation studies are compared with.

A finding is judged on the seeds of the two arms it compares: supported, contradicted or undecided
by Welch's 95% interval of the difference of their means.
"""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.evaluation.metrics import difference_interval

PAPER_TABLE_R5 = {
    "absolute": {
        "completion_pct": "23.6 ± 3.9",
        "mean_survival_s": "37.2 ± 15.5",
        "E_mpbpe": "445.4 ± 55.3",
        "E_mpjpe": "174.0 ± 12.4",
    },
    "selective": {
        "completion_pct": "38.6 ± 22.6",
        "mean_survival_s": "45.0 ± 15.7",
        "E_mpbpe": "424.2 ± 37.4",
        "E_mpjpe": "163.9 ± 3.4",
    },
    "all": {
        "completion_pct": "24.3 ± 74.8",
        "mean_survival_s": "37.0 ± 49.5",
        "E_mpbpe": "682.0 ± 190.7",
        "E_mpjpe": "124.6 ± 42.4",
    },
}
"""The paper's Table r5 (dance2_subject4, 3 seeds, 226 fixed starts, GPU scale), quoted for comparison."""
PAPER_RESAMPLING = {
    "uniform": {"success_10s_pct": "62.2 ± 10.2", "success_20s_pct": "29.9 ± 12.3", "success_30s_pct": "10.0 ± 9.2"},
    "distribution": {"success_10s_pct": "65.5 ± 3.8", "success_20s_pct": "37.3 ± 4.2", "success_30s_pct": "18.6 ± 4.0"},
    "failure": {"success_10s_pct": "69.8 ± 13.4", "success_20s_pct": "40.4 ± 21.6", "success_30s_pct": "22.0 ± 24.5"},
    "combined": {"success_10s_pct": "72.4 ± 3.4", "success_20s_pct": "45.7 ± 4.4", "success_30s_pct": "26.1 ± 6.7"},
}
"""The paper's resampling table (a), threshold success (dance2_subject4, 3 seeds, GPU scale)."""


@dataclass(frozen=True)
class Claim:
    """One of the paper's findings, judged on the seeds of two arms."""

    statement: str
    """The finding, as the paper states it."""
    metric: str
    """The per-seed figure it is judged on: a table column or a learning-curve statistic."""
    better: str
    """The arm the paper finds better."""
    than: str
    """The arm it is compared with."""
    higher_is_better: bool
    """Whether a larger value of `metric` is the better one."""


RESIDUAL_CLAIMS = (
    Claim("ALL learns faster early than SELECTIVE", "early_episode_length_s", "all", "selective", True),
    Claim("ALL learns faster early than NONE", "early_episode_length_s", "all", "absolute", True),
    *(
        Claim(f"SELECTIVE {verb} than {name}", metric, "selective", arm, True)
        for arm, name in (("absolute", "NONE"), ("all", "ALL"))
        for metric, verb in (
            ("late_reward", "reaches a higher late return"),
            ("completion_pct", "completes more fixed-grid starts"),
            ("mean_survival_s", "survives longer"),
        )
    ),
    Claim("SELECTIVE has a lower E_mpbpe than NONE", "E_mpbpe", "selective", "absolute", False),
    Claim("SELECTIVE has a lower E_mpjpe than NONE", "E_mpjpe", "selective", "absolute", False),
    Claim("ALL has a lower E_mpjpe than SELECTIVE", "E_mpjpe", "all", "selective", False),
    Claim("ALL has a higher E_mpbpe than SELECTIVE", "E_mpbpe", "selective", "all", False),
    Claim(
        "(our reading, not the paper's) the masked joints are residual, the others absolute: "
        "SELECTIVE survives start-zero longer than the reference-locked reading",
        "start_zero_s",
        "selective",
        "reference_locked",
        True,
    ),
)
"""The residual study's findings (NONE is the absolute-action arm)."""
SAMPLER_CLAIMS = (
    *(
        Claim(f"Combined sampling {verb} than {arm} sampling", metric, "combined", arm, True)
        for arm in ("uniform", "distribution", "failure")
        for metric, verb in (("completion_pct", "completes more starts"), ("mean_survival_s", "survives longer"))
    ),
    Claim(
        "Failure-only sampling is stronger than distribution-only at the final checkpoint",
        "completion_pct",
        "failure",
        "distribution",
        True,
    ),
)
"""The resampling ablation's findings (the paper's Table r5 resampling rows and their discussion)."""


def judge(claim: Claim, arms: dict[str, list[dict]]) -> dict:
    """A claim's verdict, from the difference of the two arms' means with Welch's 95% interval.

    The difference is oriented so that a positive value favours the claim (better minus other for a
    metric where higher is better, other minus better where lower is). Supported when the interval
    lies above zero, contradicted when it lies below, undecided when it holds zero; not judged below
    two seeds a side.
    """
    better = [seed[claim.metric] for seed in arms.get(claim.better, [])]
    than = [seed[claim.metric] for seed in arms.get(claim.than, [])]
    verdict = {"claim": claim.statement, "metric": claim.metric, "seeds": [len(better), len(than)]}
    if len(better) < 2 or len(than) < 2:
        return verdict | {"difference": None, "low": None, "high": None, "verdict": "not judged (under 2 seeds)"}
    interval = difference_interval(better, than) if claim.higher_is_better else difference_interval(than, better)
    low = interval["low"]
    high = interval["high"]
    if low is not None and low > 0:
        word = "supported"
    elif high is not None and high < 0:
        word = "contradicted"
    else:
        word = "undecided"
    return verdict | interval | {"verdict": word}
