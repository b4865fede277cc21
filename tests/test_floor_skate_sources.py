"""`bench/floor_skate_sources.py` splits a real floor cut's skate into three kinds of frame that
together are the ruler's stance frames and its whole summed speed."""

from __future__ import annotations

import pytest

from bench import floor_skate_sources

KINDS = ("planted_near", "planted_far", "not_planted")


@pytest.mark.slow
def test_a_floor_cut_skate_splits_into_kinds_that_cover_it() -> None:
    row = {
        "robot": "g1",
        "take": "fallAndGetUp1_subject1",
        "variant": "floor_cut",
        "clip": "fallAndGetUp1_subject1 68-88 s",
    }
    split = floor_skate_sources._sources(row, near_m=0.015)
    assert split["skate_mm_s"] > 0.0
    assert sum(split[f"{kind}_frames"] for kind in KINDS) == split["stance_frames"]
    assert sum(split[f"{kind}_share"] for kind in KINDS) == pytest.approx(1.0, abs=0.002)
    tighter = floor_skate_sources._sources(row, near_m=0.001)
    assert tighter["planted_near_frames"] < split["planted_near_frames"]
