"""The reference options an aligned dataset was written with are read back from its ``aligned.json``; a dataset
written before the scene flow existed (its motion block names no model) was carried by the edges model, whatever
the default is now."""
from __future__ import annotations

import pytest

from align.pair_reference import MOTION_MODELS, ReferenceOptions


@pytest.mark.parametrize("model", MOTION_MODELS)
def test_options_read_back_as_written(model):
    meta = {"reference_edges": {"rule": "strict", "edge_rel": 0.05},
            "motion": {"enabled": False, "min_dt_ms": 2.5, "motion_model": model}}
    assert ReferenceOptions.from_meta(meta) == ReferenceOptions(reference_edges="strict", edge_rel=0.05, motion=False,
                                                                motion_min_dt_ms=2.5, motion_model=model)


def test_a_motion_block_without_a_model_was_the_edges_model():
    old = {"motion": {"enabled": True, "min_dt_ms": 1.0}}
    assert ReferenceOptions.from_meta(old).motion_model == "edges"
    assert ReferenceOptions().motion_model == "flow"                      # today's default
    assert ReferenceOptions.from_meta({}).motion_model == "flow"          # nothing written: the defaults
