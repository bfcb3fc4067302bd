"""Physically possible output or a flag: implausible flights are failed with their reason, landings beyond
the court polygon are kept and flagged, and segments.json carries a clip-level plausibility summary."""
from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from inference.clipio import Clip
from inference.reconstruct import Observations, reconstruct
from inference.reconstruct.evaluate import Setting, prepare
from inference.reconstruct.joint import fit_joint
from inference.reconstruct.plausibility import implausible, penetration
from inference.reconstruct.results import SegmentFit

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"


@pytest.fixture(scope="module")
def padel():
    clip = Clip(SAMPLE / "padel_sample")
    obs, _, _ = prepare(clip, Setting(noise_px=2.0, players="gt"))
    return clip, obs


def test_clean_rally_is_plausible_and_summarised(padel, tmp_path):
    clip, obs = padel
    fit = reconstruct(obs)
    pl = fit.extra["plausibility"]
    assert pl["plausible"] and pl["failed"] == 0 and pl["reconstructed"] == pl["flights"] == len(fit.segments)
    assert pl["frames_inside_court"] >= 0.98 and pl["contacts_below_floor"] == 0
    assert pl["flights_over_rms_limit"] == 0 and pl["max_reprojection_rms_px"] < 8.0
    depth, _ = penetration(obs.court, fit.ball_3d().xyz)
    assert depth.max() < 0.05
    shutil.copytree(clip.root, tmp_path / "copy")
    out = Clip(tmp_path / "copy")
    fit.save(out)
    assert json.loads(out.segments_path.read_text())["plausibility"] == json.loads(json.dumps(pl))


def test_a_missed_bounce_fails_its_flight_with_the_reason(padel):
    """Drop a floor bounce: the flight across it cannot be one flight above the floor (it either misses the
    2D track or dips through the floor), so it is reported failed, never reconstructed; the flights around
    it stay reconstructed."""
    _, obs = padel
    k = obs.event_labels.index("ground", 3)
    frames = np.delete(obs.event_frames, k)
    labels = [lab for i, lab in enumerate(obs.event_labels) if i != k]
    fit = fit_joint(Observations(obs.court, obs.camera, obs.fps, obs.uv, frames, labels, obs.players))
    bad = [s for s in fit.segments if not s.ok]
    assert len(bad) >= 1 and all("reprojection RMS" in s.reason or "below the floor" in s.reason for s in bad)
    assert any(s.segment.start < obs.event_frames[k] < s.segment.end for s in bad)
    assert sum(s.ok for s in fit.segments) >= len(fit.segments) - 2
    pl = fit.extra["plausibility"]
    assert pl["failed"] == len(bad) and sum(pl["failure_reasons"].values()) == len(bad)
    assert all(s.reproj_rms_px <= 8.0 for s in fit.segments if s.ok)


def test_landing_beyond_the_floor_polygon_is_kept_and_flagged(padel):
    """A bounce just beyond a (shrunk) floor polygon is fitted on the unbounded plane with a flag, not lost."""
    _, obs = padel
    k = obs.event_labels.index("ground", 2)
    floor = next(p for p in obs.court.planes if p.name == "floor")
    uv = obs.uv[obs.event_frames[k]]
    o, d = obs.camera.rays(uv[None])
    y_bounce = float((o[0] + (-o[0][2] / d[0][2]) * d[0])[1])
    poly = floor.polygon.copy()
    if y_bounce > obs.court.net_y:   # cut the floor just short of the bounce
        poly[:, 1] = np.minimum(poly[:, 1], y_bounce - 0.5)
    else:
        poly[:, 1] = np.maximum(poly[:, 1], y_bounce + 0.5)
    court = replace(obs.court, planes=[replace(p, polygon=poly) if p is floor else p for p in obs.court.planes])
    fit = fit_joint(Observations(court, obs.camera, obs.fps, obs.uv, obs.event_frames, obs.event_labels, obs.players))
    frame = int(obs.event_frames[k])
    touching = [s for s in fit.segments if frame in (s.segment.start, s.segment.end)]
    assert touching and all(s.ok for s in touching)
    assert any("beyond the surface's extent" in f for s in touching for f in s.figures.get("flags", []))
    assert fit.extra["plausibility"]["flags"]


def test_checks_of_one_flight():
    """implausible() names what is wrong: below the floor, behind the glass, through the net, off the 2D."""
    from inference.court import load_court
    from inference.reconstruct.observations import Segment

    court = load_court("padel")
    r = court.ball.radius
    frames = np.arange(10)
    line = np.column_stack([np.full(10, 5.0), np.linspace(2.0, 8.0, 10), np.full(10, 1.0)])

    def flight(xyz, rms=1.0, start="player_near", end="ground"):
        return SegmentFit(Segment(0, 0, 9, start, end), True, frames=frames, xyz=xyz, start=xyz[0], end=xyz[-1],
                          reproj_rms_px=rms)

    assert implausible(flight(line), court, 8.0) == ""
    low = line.copy()
    low[5, 2] = -0.3
    assert "0.33 m below the floor at frame 5" in implausible(flight(low), court, 8.0)
    behind = line.copy()
    behind[:, 1] = np.linspace(15.0, 20.4, 10)
    assert "behind the glass" in implausible(flight(behind), court, 8.0)
    through = np.column_stack([np.full(10, 5.0), np.linspace(7.0, 13.0, 10), np.full(10, 0.4)])
    assert "through the net" in implausible(flight(through), court, 8.0)
    assert implausible(flight(through, start="net"), court, 8.0) == ""
    assert "reprojection RMS 20.0 px" in implausible(flight(line, rms=20.0), court, 8.0)
    sunk = flight(line)
    sunk.end = np.array([5.0, 8.0, r - 0.2])
    assert "below the floor at its contact" in implausible(sunk, court, 8.0)
