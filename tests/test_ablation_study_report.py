"""`studies/ablation_study.py` renders its committed results again as the tables it wrote, and a
study whose trials kept no failure EMA gets no EMA table."""

from __future__ import annotations

import json
import sys

import pytest
from conftest import PROJECT

RESULTS = PROJECT / "studies" / "results"


@pytest.fixture(scope="module")
def markdown():
    sys.path.insert(0, str(PROJECT))
    try:
        from studies.ablation_study import markdown
    finally:
        sys.path.remove(str(PROJECT))
    return markdown


@pytest.mark.parametrize("study", ["residual_study", "sampler_study"])
def test_committed_results_render_as_the_committed_tables(markdown, study: str) -> None:
    result = json.loads((RESULTS / f"{study}.json").read_text())
    assert markdown(result) == (RESULTS / f"{study}.md").read_text()


def test_failure_ema_table_only_where_a_trial_kept_one(markdown) -> None:
    sampler = markdown(json.loads((RESULTS / "sampler_study.json").read_text()))
    assert "| combined | 0 | 20 | 19 | 0.36 |" in sampler
    residual = json.loads((RESULTS / "residual_study.json").read_text())
    assert all("failure_ema" not in seed for arm in residual["arms"] for seed in arm["seeds"])
    assert "failure EMA" not in markdown(residual)
