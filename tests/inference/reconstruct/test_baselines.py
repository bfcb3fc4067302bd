"""The four published single-segment baselines and the batched flight sampler, on ground-truth synthetic
clips (gt camera, gt 2D ball, gt events).

Run with ``-s`` to see each method's 3D errors, reprojection errors and speed.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.clipio import Clip
from inference.court import load_court
from inference.physics import FlightModel, integrate
from inference.reconstruct import Observations, contact_priors
from inference.reconstruct.baselines import BASELINES, fit_players, fit_rally, fit_reprojection
from inference.reconstruct.flight import sample_flight, substeps_per_frame, vacuum_positions

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"
OPTIMISING = ("drag_shooting", "reprojection", "players")


# ------------------------------------------------------------------------------------------ helpers
def gt_observations(root: Path) -> Observations:
    clip = Clip(root)
    return Observations.from_clip(clip, camera=clip.read_camera(gt=True))


def segment_errors(fit, gt) -> np.ndarray:
    """(n,) 3D distances (m) of one segment fit to ground truth."""
    i = np.searchsorted(gt.frame, fit.frames)
    assert np.array_equal(gt.frame[i], fit.frames)
    return np.linalg.norm(fit.xyz - gt.xyz[i], axis=1)


def is_hit_segment(fit) -> bool:
    return "player" in fit.segment.start_event or "player" in fit.segment.end_event


def pooled(fits, gt, keep=lambda f: True) -> np.ndarray:
    errs = [segment_errors(f, gt) for f in fits if f.ok and keep(f)]
    return np.concatenate(errs) if errs else np.zeros(0)


def summary(name: str, rally, obs: Observations, gt) -> str:
    e = pooled(rally.segments, gt)
    px = rally.reprojection_errors(obs.camera, obs.uv)
    n = sum(s.segment.duration_frames for s in rally.segments)
    ok = sum(s.ok for s in rally.segments)
    return (f"{name:>8s} {rally.method:>13s}: {ok}/{len(rally.segments)} segments, 3D mean {e.mean():.3f} m "
            f"median {np.median(e):.3f} m, reprojection RMS {np.sqrt(np.mean(px**2)):.2f} px "
            f"median {np.median(px):.2f} px, {n / rally.seconds:.0f} frames/s")


# ----------------------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def padel():
    """The embedded padel sample (no players.csv): observations, ground truth, one fit per method."""
    obs = gt_observations(SAMPLE / "padel_sample")
    gt = Clip(SAMPLE / "padel_sample").read_ball_3d(gt=True)
    return obs, gt, {m: fit_rally(obs, m) for m in BASELINES}


@pytest.fixture(scope="module")
def walls(tmp_path_factory):
    """A generated padel rally with glass contacts and the players' gt court positions in players.csv."""
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("baselines") / "clip"
    config = SynthConfig(sport="padel", randomise_camera=False, width=1280, height=720, fps=30.0,
                         codec="mp4v", randomise_look=False)
    generate_clip(root, seed=2, config=config)
    shutil.copy(root / "gt" / "players.csv", root / "players.csv")
    obs = gt_observations(root)
    gt = Clip(root).read_ball_3d(gt=True)
    return obs, gt, {m: fit_rally(obs, m) for m in BASELINES}


# ------------------------------------------------------------------------------------------- flight
@pytest.fixture(scope="module")
def model():
    return FlightModel.from_ball(load_court("padel").ball)


def launches(b: int = 4, seed: int = 0):
    rng = np.random.default_rng(seed)
    p0 = rng.uniform([1, 1, 0.5], [9, 19, 2.5], (b, 3))
    v0 = rng.uniform([-5, -30, -2], [5, 30, 10], (b, 3))
    w0 = rng.uniform(-300, 300, (b, 3))
    return p0, v0, w0


@pytest.mark.parametrize("fps", [30.0, 25.0, 60.0])
@pytest.mark.parametrize("spin", [True, False])
def test_sample_flight_matches_integrate(model, fps, spin):
    p0, v0, w0 = launches()
    w0 = w0 if spin else np.zeros_like(w0)
    k = substeps_per_frame(fps)
    n = 17
    ref = integrate(p0, v0, w0, duration=n / fps, model=model, dt=1 / (fps * k), every=k)
    assert len(ref.t) == n + 1 and np.allclose(ref.t, np.arange(n + 1) / fps)
    got = sample_flight(p0, v0, w0 if spin else None, n, fps, model)
    assert got.shape == (4, n + 1, 3)
    np.testing.assert_allclose(got, ref.pos.transpose(1, 0, 2), atol=1e-9)


def test_sample_flight_vacuum_is_the_parabola(model):
    p0, v0, _ = launches(3, seed=1)
    fps, n = 30.0, 40
    got = sample_flight(p0, v0, None, n, fps, model.vacuum())
    closed = vacuum_positions(p0, v0, np.arange(n + 1) / fps, model.gravity)
    np.testing.assert_allclose(got, closed, atol=1e-9)


def test_sample_flight_shapes(model):
    p0, v0, _ = launches(1)
    assert sample_flight(p0[0], v0[0], None, 5, 30.0, model).shape == (1, 6, 3)
    np.testing.assert_array_equal(sample_flight(p0, v0, None, 0, 30.0, model)[:, 0], p0)
    assert [substeps_per_frame(f) for f in (30.0, 29.97, 50.0, 600.0)] == [20, 21, 12, 1]


# ---------------------------------------------------------------------------------- reconstruction
@pytest.mark.parametrize("method", list(BASELINES))
def test_every_method_reconstructs_most_segments(padel, walls, method):
    for obs, gt, fits in (padel, walls):
        rally = fits[method]
        print(summary(Path(obs.source).name, rally, obs, gt))
        assert rally.method == method and rally.seconds > 0
        assert len(rally.segments) == len(obs.segments())
        assert not [s.reason for s in rally.segments if "internal error" in s.reason]
        assert sum(s.ok for s in rally.segments) >= 0.75 * len(rally.segments)
        for s in rally.segments:
            if not s.ok:
                assert s.reason
                continue
            assert s.frames.tolist() == s.segment.frames.tolist() and s.xyz.shape == (len(s.frames), 3)
            assert np.all(np.isfinite(s.xyz)) and np.all(s.spin == 0) and s.sigma is None
            np.testing.assert_array_equal(s.start, s.xyz[0])
            assert s.n_observed == int(np.isfinite(obs.uv[s.frames]).all(axis=1).sum())
            assert (s.start_plane is None) == ("player" in s.segment.start_event)


def test_contact_methods_join_the_contact_points(padel):
    """Methods 1 and 2 start exactly at the start prior and end at the end prior (drag within 1 cm)."""
    obs, _, fits = padel
    priors = contact_priors(obs)
    for method, tol in (("gravity", 1e-9), ("drag_shooting", 0.01)):
        for s in fits[method].segments:
            np.testing.assert_allclose(s.start, priors[s.segment.index].point, atol=1e-12)
            assert np.linalg.norm(s.end - priors[s.segment.index + 1].point) < tol
        drag = 0.0 if method == "gravity" else obs.court.ball.drag_k
        assert {s.drag_k for s in fits[method].segments} == {drag}


def test_plane_to_plane_segments_are_accurate(walls):
    """Between two surface contacts seen in the image, methods 1 and 2 are within ~0.3 m (median)."""
    obs, gt, fits = walls

    def plane_to_plane(f):
        seen = np.isfinite(obs.uv[[f.segment.start, f.segment.end]]).all()
        return seen and not is_hit_segment(f)

    assert any(plane_to_plane(f) for f in fits["gravity"].segments if f.ok)
    for method in ("gravity", "drag_shooting"):
        e = pooled(fits[method].segments, gt, plane_to_plane)
        assert np.median(e) < 0.3, method


def test_reprojection_methods_fit_the_image(padel):
    """Noise-free 2D: methods 3 and 4 reproject within a few pixels (the drag-only flight cannot follow the
    spin, and the event frame is only the frame nearest the contact)."""
    obs, _, fits = padel
    for method in ("reprojection", "players"):
        rms = [s.reproj_rms_px for s in fits[method].segments if s.ok]
        px = fits[method].reprojection_errors(obs.camera, obs.uv)
        assert np.median(rms) < 3.0 and np.sqrt(np.mean(px**2)) < 3.5, method
        assert np.median(rms) < np.median([s.reproj_rms_px for s in fits["gravity"].segments if s.ok])


def test_reprojection_beats_gravity_on_hit_segments(padel):
    _, gt, fits = padel
    e1 = pooled(fits["gravity"].segments, gt, is_hit_segment)
    for method in ("reprojection", "players"):
        e = pooled(fits[method].segments, gt, is_hit_segment)
        assert e.mean() < 0.6 * e1.mean() and np.median(e) < np.median(e1), method


def test_players_constrain_the_hit_points(walls):
    """With players.csv, method 4 keeps racket hits within the hitter's reach and improves on method 3."""
    obs, gt, fits = walls
    lim = obs.court.hits
    priors = contact_priors(obs)
    checked = 0
    for s in fits["players"].segments:
        if not s.ok:
            continue
        for p, point in ((priors[s.segment.index], s.start), (priors[s.segment.index + 1], s.end)):
            if p.kind != "hit":
                continue
            assert p.hitter_xy is not None
            assert lim.height[0] - 0.01 <= point[2] <= lim.height[1] + 0.01
            assert np.linalg.norm(point[:2] - p.hitter_xy) <= lim.reach + 0.01
            assert lim.offset_y[0] - 0.01 <= point[1] - p.hitter_xy[1] <= lim.offset_y[1] + 0.01
            checked += 1
    assert checked >= 4
    assert fits["players"].extra["notes"] == []
    e3 = pooled(fits["reprojection"].segments, gt, is_hit_segment)
    e4 = pooled(fits["players"].segments, gt, is_hit_segment)
    assert e4.mean() < e3.mean()


def test_players_without_players_csv_is_method_3(padel):
    obs, _, fits = padel
    assert obs.players is None
    for a, b in zip(fits["players"].segments, fits["reprojection"].segments):
        assert a.ok == b.ok and a.reason == b.reason == ""
        np.testing.assert_allclose(a.xyz, b.xyz)
    notes = fits["players"].extra["notes"]
    assert len(notes) == len(obs.segments()) and "no hitter position" in notes[0]


@pytest.mark.parametrize("method", OPTIMISING)
def test_optimising_methods_are_fast(padel, method):
    """The thesis's optimising methods ran 44-175 frames/s."""
    _, _, fits = padel
    rally = fits[method]
    assert rally.n_frames / rally.seconds > 44


# ------------------------------------------------------------------------------------------ failures
def relabel(obs: Observations, index: int, label: str) -> Observations:
    labels = list(obs.event_labels)
    labels[index] = label
    return Observations(obs.court, obs.camera, obs.fps, obs.uv.copy(), obs.event_frames, labels, obs.players,
                        obs.source)


@pytest.mark.parametrize("method", list(BASELINES))
def test_line_of_sight_missing_its_plane(padel, method):
    """A floor bounce labelled as a far-glass contact: its two segments fail, the others reconstruct."""
    obs = relabel(padel[0], 2, "wall_far")  # frame 56, ground
    rally = fit_rally(obs, method)
    bad = {1, 2}
    for s in rally.segments:
        if s.segment.index in bad:
            assert not s.ok and "misses every wall_far surface" in s.reason and "frame 56" in s.reason
        else:
            assert s.ok, s.reason


@pytest.mark.parametrize("method", list(BASELINES))
def test_segment_without_2d_points(padel, method):
    obs = padel[0]
    seg = obs.segments()[5]
    uv = obs.uv.copy()
    uv[seg.start : seg.end + 1] = np.nan
    rally = fit_rally(obs.with_track(uv), method)
    s = rally.segments[5]
    assert not s.ok and s.reason
    if method in ("gravity", "drag_shooting"):
        assert s.reason.startswith("only 0 observed")
    assert all(f.ok for f in rally.segments[:4] + rally.segments[7:])


@pytest.mark.parametrize("method", list(BASELINES))
def test_nan_and_degenerate_tracks(padel, method):
    obs = padel[0]
    rally = fit_rally(obs.with_track(np.full_like(obs.uv, np.nan)), method)
    assert not any(s.ok for s in rally.segments)
    assert all(s.reason and "internal error" not in s.reason for s in rally.segments)
    uv = obs.uv.copy()
    uv[30:50:2, 0] = np.nan  # half-NaN rows count as unseen
    uv[41, 1] = np.inf
    rally = fit_rally(obs.with_track(uv), method)
    assert all(s.ok for s in rally.segments)
    assert rally.segments[1].n_observed == padel[2][method].segments[1].n_observed - 11


def test_short_segments_fail_for_the_reprojection_methods(padel):
    obs = padel[0]
    priors = contact_priors(obs)
    seg = obs.segments()[4]  # 3 frame intervals
    uv = obs.uv.copy()
    uv[seg.start + 1 : seg.end] = np.nan
    for fit in (fit_reprojection, fit_players):
        s = fit(obs.with_track(uv), priors, seg)
        assert not s.ok
        assert s.reason == f"only 2 observed 2D ball positions in frames {seg.start}-{seg.end} (need 3)"


def test_unknown_method():
    with pytest.raises(ValueError, match="unknown baseline"):
        fit_rally(gt_observations(SAMPLE / "tennis_sample"), "kalman")
