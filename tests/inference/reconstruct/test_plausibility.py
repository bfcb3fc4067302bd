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
from inference.reconstruct.joint import JointConfig, Plan, PlanContact, _fit_with_ends, fit_joint
from inference.reconstruct.observations import contact_priors
from inference.reconstruct.plausibility import check_flights, penetration
from inference.physics import FlightModel
from inference.reconstruct.shooting import HitPrior

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


def test_a_missed_bounce_is_refitted_or_failed(padel):
    """Drop a floor bounce: the flight across it cannot be one flight above the floor. It is refitted with a
    contact inserted near the missed bounce (noted in segments.json), or, failing that, reported failed with
    the reason — never reported reconstructed while implausible."""
    _, obs = padel
    k = obs.event_labels.index("ground", 1)       # the bounce between two hits, mid-rally
    missed = int(obs.event_frames[k])
    frames = np.delete(obs.event_frames, k)
    labels = [lab for i, lab in enumerate(obs.event_labels) if i != k]
    fit = fit_joint(Observations(obs.court, obs.camera, obs.fps, obs.uv, frames, labels, obs.players))
    across = [s for s in fit.segments if s.segment.start < missed < s.segment.end]
    assert len(across) == 1
    s = across[0]
    if s.ok:
        notes = [note for frame, note in fit.extra.get("refits", []) if abs(frame - missed) <= 3]
        assert notes and "contact inserted" in notes[0] and s.figures["refit"]
        assert s.reproj_rms_px < 4.0
    else:
        assert "reprojection RMS" in s.reason or "below the floor" in s.reason
    pl = fit.extra["plausibility"]
    assert pl["flights_over_rms_limit"] == 0 and pl["contacts_below_floor"] == 0
    depth, _ = penetration(obs.court, fit.ball_3d().xyz)
    assert depth.max() < 0.05


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


def test_penetration_and_net_clearance():
    """What the flight checks measure: depth below the floor or behind a glass patch (not beside it, through
    the open side or above the wall), and the height over the net where a path crosses it."""
    from inference.court import load_court
    from inference.reconstruct.plausibility import net_clearance

    court = load_court("padel")
    r = court.ball.radius
    pts = np.array([[5.0, 5.0, 1.0], [5.0, 5.0, -0.3], [5.0, 20.4, 1.5], [5.0, 20.4, 5.5], [-0.5, 10.0, 4.5]])
    depth, where = penetration(court, pts)
    np.testing.assert_allclose(depth[:2], [0.0, 0.3 + r])
    assert where[1] == "floor" and depth[2] == pytest.approx(0.4 + r) and where[2].startswith("glass_far")
    assert depth[3] == 0.0 and depth[4] == 0.0      # above the 4 m mesh; above the side fence
    low = np.column_stack([np.full(10, 5.0), np.linspace(7.0, 13.0, 10), np.full(10, 0.4)])
    high = low + [0.0, 0.0, 1.0]
    assert net_clearance(court, low) < -0.4 and net_clearance(court, high) > 0.4


def test_a_flight_launched_impossibly_fast_is_failed(padel):
    """A flight faster than ``max_speed_ms`` at its contact is failed with the speed as the reason, not
    reported reconstructed (on a broadcast clip a hit 2 frames before a net event fitted at 2,493 km/h):
    with the limit just under the rally's fastest shot, exactly the shots above it fail."""
    _, obs = padel
    fit = fit_joint(obs, JointConfig(refit=False))
    speeds = {s.segment.index: float(np.linalg.norm(s.velocity)) for s in fit.segments if s.ok and s.end is not None
              and s.start is not None}
    assert max(speeds.values()) < JointConfig().max_speed_ms
    limit = max(speeds.values()) - 0.5
    slow = fit_joint(obs, JointConfig(refit=False, max_speed_ms=limit))
    by_index = {s.segment.index: s for s in slow.segments}
    fast = [i for i, v in speeds.items() if v > limit]
    assert fast
    for i in fast:
        assert not by_index[i].ok and "km/h" in by_index[i].reason
    for s in slow.segments:           # a flight shares its first frame with the one before: that one may fail too
        assert s.ok or ({s.segment.index, s.segment.index + 1} & set(fast) and "km/h" in s.reason)
    assert slow.extra["plausibility"]["failed"] >= len(fast)


def test_a_contact_below_the_floor_fails_its_flights(padel):
    """A contact point is checked like the frames: a hit (or a contact on the net's unbounded plane) fitted
    below the floor fails the flights on both sides of it, naming the contact, even where no whole frame of
    the flights sinks (on a broadcast clip a net contact at z = −0.04 m was reported reconstructed)."""
    _, obs = padel
    cfg = JointConfig(refit=False)
    fit = _fit_with_ends(obs, Plan([PlanContact(p, i) for i, p in enumerate(contact_priors(obs))]), cfg,
                         FlightModel.from_ball(obs.court.ball), HitPrior.from_court(obs.court))
    assert all(c.ok for c in fit.checks)
    ch = fit.problem.chain
    k = next(i for i, c in enumerate(ch.contacts) if c.kind == "hit")
    ct = ch.contacts[k]
    # the contact point only, 0.3 m below the floor: the flights' frames stay put
    ct.origin = ct.origin - np.array([0.0, 0.0, ch.point(fit.sol.theta, k)[2] + 0.3])
    checks = check_flights(fit.problem, fit.sol, cfg)
    touching = [s for s, f in enumerate(ch.flights) if k in (f.start, f.end)]
    assert touching
    for s in touching:
        assert not checks[s].ok and "below the floor" in checks[s].reason and f"contact (frame {ct.frame})" in checks[s].reason
    assert all(c.ok for s, c in enumerate(checks) if s not in touching)


def test_failed_flights_count_in_the_clip_verdict(padel):
    """segments.json's clip-level ``plausible`` also judges the flights that failed, not only those reported."""
    from inference.reconstruct.plausibility import MAX_FAILED_SHARE, summary

    _, obs = padel
    fit = reconstruct(obs)
    n = len(fit.segments)
    assert summary(fit, obs)["plausible"] and summary(fit, obs)["not_plausible_because"] == []
    k = int(np.floor(MAX_FAILED_SHARE * n)) + 1  # just over the allowed share
    segs = [replace(s, ok=False, reason="too few detections") if i < k else s for i, s in enumerate(fit.segments)]
    pl = summary(replace(fit, segments=segs), obs)
    assert pl["failed"] == k and pl["failed_share"] == pytest.approx(k / n, abs=1e-4)
    assert not pl["plausible"] and f"{k}/{n} flights failed" in pl["not_plausible_because"]
    if k > 1:  # one failed flight of many is still a plausible rally
        one = [replace(s, ok=False, reason="too few detections") if i == 0 else s for i, s in enumerate(fit.segments)]
        assert summary(replace(fit, segments=one), obs)["plausible"]
