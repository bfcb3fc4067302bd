"""The real-footage bench's far-hit gap breakdown (bench/bench_real.py), on arrays made here: no real data."""
import importlib.util
import sys
from pathlib import Path

import numpy as np

_SPEC = importlib.util.spec_from_file_location("bench_real", Path(__file__).parents[1] / "bench" / "bench_real.py")
bench_real = importlib.util.module_from_spec(_SPEC)
sys.modules["bench_real"] = bench_real   # its dataclasses look their module up
_SPEC.loader.exec_module(bench_real)


def test_far_hits_binned_by_the_gap_at_their_contact():
    seen = np.ones(200, bool)
    seen[50:75] = False            # a 25-frame gap holds the hit at 60
    seen[120:125] = False          # a 5-frame gap ends 1 frame before the hit at 126
    bins = {k: [0, 0] for k in bench_real.FAR_GAP_BINS}
    labels = np.array([20, 60, 126])
    found = np.array([21, 66, 126])   # the hit in the long gap is found 6 frames late: not found
    bench_real.far_gaps(seen, labels, found, bins)
    assert bins["0"] == [1, 1]
    assert bins["21+"] == [0, 1]
    assert bins["4-12"] == [1, 1]
    assert sum(n for _, n in bins.values()) == 3
