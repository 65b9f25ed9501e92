"""Shared loop runs on the analytic pellet (tests/loop/toy_pellet.py): each made once per
session, as they take seconds each."""
from __future__ import annotations

import pytest
from toy_pellet import BOUNDS, FIT, HELD, LIBRARY, PACKING, START, TRUTH, toy

from pelletdem.loop import FunctionSimulator, close_loop, synthetic_dataset

_RUNS = {}


def toy_loop(extra, draw=0, **kw):
    """close_loop on toy data with ``extra`` hidden, replicates from packings 1000 + 10 draw
    + k (k < 5), 2 % noise, 90 MPa held out; memoised by (extra, draw, kw)."""
    key = (tuple(sorted(extra.items())), draw, tuple(sorted(kw.items())))
    if key not in _RUNS:
        sim = FunctionSimulator(toy, packing_params=PACKING)
        data = synthetic_dataset(sim, {**TRUTH, **extra}, FIT + HELD, noise=0.02, compaction_points=4,
                                 seeds=[1000 + 10 * draw + k for k in range(5)], seed=draw)
        _RUNS[key] = close_loop(sim, data, BOUNDS, START, held_out=lambda c: c in HELD,
                                library=kw.pop("library", LIBRARY), **kw)
    return _RUNS[key]


@pytest.fixture
def run_toy_loop():
    """:func:`toy_loop` as a fixture."""
    return toy_loop
