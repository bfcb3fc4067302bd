"""Events the model is unsure of are reported for a check (the infer summary, rally3d events), not hidden."""
from __future__ import annotations

import numpy as np

from inference.clipio import HitEvents
from inference.events.detector import EventResult


def test_low_confidence_events_are_reported():
    r = EventResult(events=HitEvents([10, 40, 70], ["ground", "player_far", "ground"]), probs=np.zeros((80, 4)),
                    classes=("none", "ground", "player_near", "player_far"), coarse=["ground", "player_far", "ground"],
                    confidence=np.array([0.9, 0.31, 0.45]))
    line = r.unsure()
    assert line.startswith("2 events below 0.5") and "player_far 40 (0.31)" in line and "ground 70" in line
    r.confidence = np.array([0.9, 0.8, 0.7])
    assert r.unsure() == ""
