"""The joint method's calibrated covariance (court YAML ``uncertainty``) and free ends the 2D track cannot pin
in depth (a serve's toss seen from behind the other baseline): kept, not slid along the line of sight."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from inference.camera import Camera
from inference.clipio import Clip, PlayerTracks
from inference.court import load_court
from inference.physics import FlightModel, integrate
from inference.reconstruct import Observations
from inference.reconstruct.evaluate import Setting, prepare
from inference.reconstruct.joint import JointConfig, fit_joint
from inference.reconstruct.shooting import Uncertainty

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"
GAUSS_3D = (0.1987, 0.7385)   # P(|x|² ≤ 1), P(|x|² ≤ 4) for a 3D standard normal


def sigma_coverage(clip: Clip, seed: int, shift: int, uncertainty: Uncertainty | None) -> tuple[float, float]:
    """Share of the frames where the ball is in the picture whose 3D error lies inside the reported 1-σ and
    2-σ ellipsoids (the frames of a lob above the picture are heavy-tailed: see the docstring below)."""
    obs, gt_frames, gt_xyz = prepare(clip, Setting(noise_px=2.0, players="gt", seed=seed, event_shift=shift))
    fit = fit_joint(obs, JointConfig(uncertainty=uncertainty))
    b = fit.ball_3d()
    _, cov = fit.covariances()
    d = b.xyz - gt_xyz[np.searchsorted(gt_frames, b.frame)]
    m2 = np.einsum("ni,nij,nj->n", d, np.linalg.inv(cov), d)
    seen = np.isfinite(obs.uv[b.frame]).all(axis=1)
    assert seen.sum() > 100
    return float(np.mean(m2[seen] <= 1)), float(np.mean(m2[seen] <= 4))


def within(c: tuple[float, float]) -> bool:
    """1-σ and 2-σ coverage within 10 points of the Gaussian 19.9 % / 73.9 %."""
    return abs(c[0] - GAUSS_3D[0]) <= 0.10 and abs(c[1] - GAUSS_3D[1]) <= 0.10


def test_padel_covariance_is_calibrated_per_clip():
    """Three noise draws (one with ±2-frame event jitter) of the padel sample, which the calibration (seeds
    300+) never saw: on the frames where the ball is in the picture the mean coverage of the draws lies within
    12 points of the Gaussian figures and each draw's within 15 (measured 29–33 % / 74–78 %, mean 31 / 77 %;
    one clip's frames share a few flights' errors, so one clip lies within 10 points of the Gaussian figures
    only about half the time even when calibrated: ``bench/bench_joint.py``'s oracle band; the calibration
    before the along/across one measured a mean of 29.8 / 71 % here, with its along-ray σ 23 points too wide and
    its across-ray σ 6 points too narrow, :func:`test_covariance_has_the_right_width_along_and_across_the_line_of_sight`);
    the uncalibrated Gauss-Newton covariance (scale 1, no model term) is too wide on the same draws.

    Not asserted, a known weakness: the 59 frames of the sample's lob above the picture are 2 cm off on one
    draw and 16 cm on another with the same reported σ (the first draw's 2-σ ellipsoids hold none of them);
    on 8 simulated padel clips no extra Gaussian term for unseen frames matched their 1-σ and 2-σ shares at
    once (``bench/bench_joint.py --calibrate``)."""
    clip = Clip(SAMPLE / "padel_sample")
    cal = [sigma_coverage(clip, seed, 2 if seed == 2 else 0, None) for seed in range(3)]
    raw = [sigma_coverage(clip, seed, 2 if seed == 2 else 0, Uncertainty()) for seed in range(3)]
    mean = np.mean(cal, axis=0)                                             # the clip's mean over draws
    assert abs(mean[0] - GAUSS_3D[0]) <= 0.12 and abs(mean[1] - GAUSS_3D[1]) <= 0.12, cal
    assert all(abs(c[0] - GAUSS_3D[0]) <= 0.15 and abs(c[1] - GAUSS_3D[1]) <= 0.15 for c in cal), cal
    assert not any(within(c) for c in raw), raw


def test_uncertainty_keys_are_checked():
    court = load_court("padel")
    u = Uncertainty.from_court(court)
    assert u.scale > 0 and u.model_m_per_s >= 0
    court.extra["uncertainty"] = {"scale": 1.0, "wrong": 2.0}
    with pytest.raises(ValueError, match="wrong"):
        Uncertainty.from_court(court)


def toss_then_serve() -> tuple[Observations, np.ndarray]:
    """A far server's toss (straight up and down, 12 frames at 25 fps), the serve at frame 12 and its flight
    to its bounce in the near service box, seen from behind the near baseline: the toss moves along the
    line of sight only by its perspective. The server stands 0.4 m behind the toss."""
    court = load_court("tennis")
    model = FlightModel.from_ball(court.ball)
    fps = 25.0
    toss = integrate(np.array([4.85, 23.9, 2.55]), np.array([0.0, 0.0, 3.2]), np.zeros(3), 12 / fps, model,
                     dt=1 / fps)
    serve = integrate(toss.pos[-1, 0], np.array([0.6, -27.0, -2.5]), np.zeros(3), 30 / fps, model, dt=1 / fps)
    land = int(np.flatnonzero(serve.pos[:, 0, 2] <= court.ball.radius)[0])
    xyz = np.concatenate([toss.pos[:-1, 0], serve.pos[:land, 0]])
    cam = Camera.from_look_at((5.5, -10.0, 5.0), (5.5, 12.0, 0.0), (1280, 720), fov_deg=45.0)
    uv = cam.project(xyz) + np.random.default_rng(0).normal(0.0, 2.0, (len(xyz), 2))
    n = len(xyz)
    server = PlayerTracks(frame=np.arange(n), player_id=np.zeros(n, int), team=["far"] * n, score=np.ones(n),
                          bbox=np.full((n, 4), np.nan), keypoints=np.full((n, 17, 3), np.nan),
                          court_xy=np.tile([4.85, 24.3], (n, 1)))
    obs = Observations(court, cam, fps, uv, np.array([12, n - 1]), ["player_far", "ground"], server)
    return obs, xyz


def test_a_toss_before_the_first_event_is_kept_in_depth():
    """Every frame is reconstructed, and the pull of the free end towards rest holds the toss's depth: without
    it the fit sends the toss away along the line of sight (metres off)."""
    obs, xyz = toss_then_serve()
    lead_err = {}
    for sigma in (8.0, 0.0):
        b = fit_joint(obs, JointConfig(free_end_speed_sigma=sigma)).ball_3d()
        assert b.frame.tolist() == list(range(len(xyz)))          # every frame with a 2D ball
        err = np.linalg.norm(b.xyz - xyz[b.frame], axis=1)
        lead_err[sigma] = float(np.median(err[b.frame < 12]))
    # converged (LM tolerance 1e-4): 1.14 m vs 2.65 m; the earlier 0.93 m was partly the solver stopping early
    assert lead_err[8.0] < 1.2 and lead_err[0.0] > 2.0 * lead_err[8.0], lead_err


def test_a_diverging_hypothesis_does_not_sink_the_clip():
    """A padel rally with the server's warm-up bounces and the ball after the point (not events): one of the
    refit hypotheses diverges (a NaN contact time); that hypothesis fails, the clip is still reconstructed."""
    from synth.generate import SynthConfig, SynthScene
    from synth.groundtruth import ball_3d_table, event_table, inside_image

    scene = SynthScene.build(4, SynthConfig(sport="padel", around_point=True))
    gt, ev = ball_3d_table(scene.rally), event_table(scene.rally)
    uv = np.full((scene.rally.n_frames, 2), np.nan)
    px = scene.camera.project(gt.xyz)
    ok = inside_image(px, scene.camera.image_size)
    uv[gt.frame[ok]] = px[ok] + np.random.default_rng(4).normal(0.0, 2.0, (ok.sum(), 2))
    obs = Observations(scene.court, scene.camera, scene.rally.fps, uv, ev.frame, list(ev.event))
    with np.errstate(all="ignore"):
        b = fit_joint(obs).ball_3d()
    inside = (b.frame >= ev.frame[0]) & (b.frame <= ev.frame[-1])
    seen = np.flatnonzero(np.isfinite(uv).all(axis=1))
    rally = seen[(seen >= ev.frame[0]) & (seen <= ev.frame[-1])]
    assert inside.sum() >= 0.98 * len(rally)


def test_free_end_rate_and_residual_inflation_scale_only_their_frames():
    """The along-ray model rate of free ends (``free_end_m_per_s``) widens only the lead-in's frames, along the
    line of sight; ``residual_power`` multiplies a flight's covariance by χ²^power only where χ² > 1."""
    obs, _ = toss_then_serve()
    base = Uncertainty(scale=0.8, model_m_per_s=0.5, floor_m=0.001)
    em = fit_joint(obs, JointConfig(uncertainty=base)).error_model
    free = fit_joint(obs, JointConfig(uncertainty=replace(base, free_end_m_per_s=3.0))).error_model
    assert em.free.any() and (~em.free).any()
    var_along = lambda m: np.einsum("mi,mij,mj->m", m.ray, m.covariances(), m.ray)   # noqa: E731
    grown = var_along(free) - var_along(em)
    expect = ((3.0**2 - 0.5**2) * em.dt**2) * em.factor
    np.testing.assert_allclose(grown[em.free], expect[em.free], rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(grown[~em.free], 0.0, atol=1e-9)
    # residual inflation: a flight's factor is max(χ², 1)^power
    chi2 = np.array([0.5, 1.0, 4.0, np.nan])
    np.testing.assert_allclose(replace(base, residual_power=2.0).flight_factor(chi2), [1.0, 1.0, 16.0, 1.0])
    big = fit_joint(obs, JointConfig(uncertainty=replace(base, residual_power=2.0))).error_model
    k = np.maximum(np.nan_to_num(em.flight_chi2, nan=1.0), 1.0) ** 2
    np.testing.assert_allclose(big.factor, k[em.own])
    iso = base.floor_m**2 * np.eye(3)
    np.testing.assert_allclose(big.covariances() - iso, big.factor[:, None, None] * (em.covariances() - iso),
                               rtol=1e-6, atol=1e-12)


def test_oracle_draws_follow_the_reported_covariance_and_share_a_flights_error():
    """The error model's joint draws (the oracle of bench_joint) have the reported per-frame covariance, and
    the frames of one flight move together (one depth error per flight), unlike independent frames."""
    obs, _ = toss_then_serve()
    em = fit_joint(obs).error_model
    d = em.draw(4000, np.random.default_rng(0))                        # (n, M, 3)
    cov = em.covariances()
    emp = np.einsum("smi,smj->mij", d, d) / len(d)
    m = len(em.frames) // 2
    np.testing.assert_allclose(emp[m], cov[m], rtol=0.15, atol=0.05 * np.abs(cov[m]).max())
    same = np.flatnonzero(em.own == em.own[m])
    a = d[:, m] @ em.ray[m]
    b = d[:, same[-1] if same[-1] != m else same[0]] @ em.ray[m]
    assert abs(np.corrcoef(a, b)[0, 1]) > 0.5


def test_along_scale_narrows_the_fit_along_the_line_of_sight_only():
    """``along_scale`` multiplies the Gauss-Newton width along the line of sight and leaves it across the line
    untouched (the raw covariance's errors are too wide along the ray and too narrow across it): with no model
    term and no floor, the along-ray variance scales by along_scale², the variance across it and the
    along/across independence of directions stay as they were."""
    from inference.reconstruct.evaluate import ray_basis

    obs, _ = toss_then_serve()
    base = Uncertainty(scale=0.9, model_m_per_s=0.0, floor_m=0.0)
    em = fit_joint(obs, JointConfig(uncertainty=base, sigma_floor_m=0.0)).error_model
    half = fit_joint(obs, JointConfig(uncertainty=replace(base, along_scale=0.5), sigma_floor_m=0.0)).error_model
    E = ray_basis(em.ray)
    v0 = np.einsum("mki,mij,mkj->mk", E, em.covariances(), E)
    v1 = np.einsum("mki,mij,mkj->mk", E, half.covariances(), E)
    np.testing.assert_allclose(v1[:, 0], 0.25 * v0[:, 0], rtol=1e-6)
    np.testing.assert_allclose(v1[:, 1:], v0[:, 1:], rtol=1e-6)
    # the oracle draws follow the same shape (bench_joint's per-clip bands)
    d = half.draw(3000, np.random.default_rng(1))
    m = len(half.frames) // 2
    emp = np.var(d[:, m] @ E[m].T, axis=0)
    np.testing.assert_allclose(emp, v1[m], rtol=0.15)
    court = load_court("padel")
    court.extra["uncertainty"] = {"scale": 1.0, "along_scale": 0.0}
    with pytest.raises(ValueError, match="along_scale"):
        Uncertainty.from_court(court)


@pytest.mark.parametrize("sport", ["padel", "tennis"])
def test_covariance_has_the_right_width_along_and_across_the_line_of_sight(sport):
    """Over three noise draws of each embedded sample (one with ±2-frame event jitter; the calibration never
    saw them), the share of the errors within the marginal 1 σ / 2 σ along the line of sight and across it is
    within 10 / 6 points of a Gaussian's 68 % / 95 % (measured: padel 77 / 94 % along, 70 / 96 % across;
    tennis 65 / 95 %, 70 / 95 %). The previous calibration (one scale for both directions and a large
    along-ray model term) fails it: padel 91 % along and 62 % across within 1 σ, tennis 89 % and 62 %."""
    from inference.reconstruct.evaluate import GAUSS_1D, direction_coverage

    clip = Clip(SAMPLE / f"{sport}_sample")
    old = {"padel": Uncertainty(0.7, 1.0, 0.001, None, 2.0), "tennis": Uncertainty(0.75, 1.0, 0.001, 2.0, 0.0)}[sport]
    got = {}
    for name, u in (("now", None), ("old", old)):
        d, cov, ray = [], [], []
        for seed in range(3):
            obs, gt_frames, gt_xyz = prepare(clip, Setting(noise_px=2.0, players="gt", seed=seed,
                                                           event_shift=2 if seed == 2 else 0))
            fit = fit_joint(obs, JointConfig(uncertainty=u))
            b = fit.ball_3d()
            seen = np.isfinite(obs.uv[b.frame]).all(axis=1)
            r = b.xyz - obs.camera.centre
            d.append((b.xyz - gt_xyz[np.searchsorted(gt_frames, b.frame)])[seen])
            cov.append(fit.covariances()[1][seen])
            ray.append((r / np.linalg.norm(r, axis=1)[:, None])[seen])
        got[name] = direction_coverage(*(np.concatenate(x) for x in (d, cov, ray)))

    def within(c: dict) -> bool:
        return all(abs(c[k][0] - GAUSS_1D[0]) <= 0.10 and abs(c[k][1] - GAUSS_1D[1]) <= 0.06 for k in c)

    assert within(got["now"]), got
    assert not within(got["old"]), got


def test_the_camera_pose_covariance_moves_the_frames_as_a_refit_does():
    """With a calibrated camera's pose covariance (camera.yaml ``pose_cov``) the reported covariance adds
    T Σc Tᵀ, T the frames' first-order response to the camera's pose at the optimum: on the padel sample a
    refit with the camera moved by a small pose step moves the frames by T·step (measured: within 3–6 % for a
    centre or focal step, 34 % for a 0.5 mrad tilt); without a pose covariance the term is absent."""
    obs, _, _ = prepare(Clip(SAMPLE / "padel_sample"), Setting(noise_px=2.0, players="gt", seed=0))
    base = fit_joint(obs).error_model
    assert base.camera_jac is None and np.allclose(base.camera_part(), 0.0)
    pose_cov = np.diag([0.05, 0.05, 0.05, 1e-3, 1e-3, 1e-3, 5.0]) ** 2
    cam = replace(obs.camera, meta={**obs.camera.meta, "pose_cov": pose_cov.tolist()})
    em = fit_joint(replace(obs, camera=cam)).error_model
    assert em.camera_jac is not None and em.camera_jac.shape == (len(em.frames), 3, 7)
    np.testing.assert_allclose(em.covariances() - base.covariances(), em.camera_part(), atol=1e-9)
    assert np.all(np.linalg.eigvalsh(em.camera_part()) > -1e-12)
    for step in (np.array([0.0, 0.05, 0.0, 0, 0, 0, 0]), np.array([0.0, 0.0, 0.05, 0, 0, 0, 0]),
                 np.array([0, 0, 0, 5e-4, 0.0, 0.0, 0]), np.array([0, 0, 0, 0, 0, 0, 5.0])):
        moved = fit_joint(replace(obs, camera=obs.camera.perturbed(step))).error_model
        assert moved.frames.tolist() == base.frames.tolist()
        got = moved.xyz - base.xyz                                         # (M, 3) the refit's response
        want = np.einsum("mdk,k->md", em.camera_jac, step)
        size = np.median(np.linalg.norm(want, axis=1))
        assert size > 0.01 and np.median(np.linalg.norm(got - want, axis=1)) <= 0.4 * size, step


def test_a_calibration_states_its_pose_covariance_as_its_errors_are():
    """`calibrate_court` writes the pose covariance (centre, rotation, focal) into the camera's meta; over
    click-noise draws (±1 px uniform on 26 tennis points) the true pose lies at a mean Mahalanobis² near 7 (the
    7 parameters); the pose round trip (perturbed / pose_difference) is exact to first order."""
    from inference.camera import Camera
    from inference.camera.calibration import calibrate_court

    court = load_court("tennis")
    true = Camera.from_look_at((5.5, -18.0, 8.0), (5.5, 11.9, 0.0), (1920, 1080), fov_deg=40.0)
    names = [n for n in court.point_names if n not in court.off_ground_points()]
    px = true.project(court.point_array(names))
    inside = np.isfinite(px).all(axis=1)
    rng = np.random.default_rng(0)
    m2 = []
    for _ in range(20):
        clicks = {n: xy + rng.uniform(-1.0, 1.0, 2) for n, xy, ok in zip(names, px, inside) if ok}
        cam = calibrate_court(court, clicks, true.image_size).camera
        C = cam.pose_covariance()
        assert C is not None and C.shape == (7, 7)
        dq = cam.pose_difference(true)
        m2.append(float(dq @ np.linalg.pinv(C) @ dq))
    assert 3.5 <= np.mean(m2) <= 14.0, m2
    step = np.array([0.02, -0.03, 0.01, 2e-4, -1e-4, 3e-4, 2.0])
    np.testing.assert_allclose(true.pose_difference(true.perturbed(step)), step, rtol=1e-3, atol=1e-9)
    bad = replace(true, meta={"pose_cov": [[1.0, 2.0]]})
    assert bad.pose_covariance() is None and true.pose_covariance() is None


def test_each_flight_says_what_pinned_its_depth():
    """Every reconstructed flight reports which evidence besides its 2D track decided its depth (the cue whose
    removal widens the along-ray σ most, by the Woodbury identity on the fit's own normal matrix). The serve
    seen from behind the far baseline is pinned by the racket hit's prior (the server's position): its reported
    ratio (×4.7) matches the along-ray σ of the same fit without players.csv (×4.7); without players that prior
    (then only the reach height) decides nothing (×1.0) and the net does (×1.8)."""
    obs, _ = toss_then_serve()
    raw = JointConfig(uncertainty=Uncertainty(scale=1.0, model_m_per_s=0.0, floor_m=0.0), sigma_floor_m=0.0)
    with_players = {s.segment.index: s for s in fit_joint(obs, raw).segments if s.ok}
    without = {s.segment.index: s for s in fit_joint(replace(obs, players=None), raw).segments if s.ok}
    serve = with_players[0]
    assert serve.figures["depth_from"].startswith("the racket hit"), serve.figures
    reported = serve.figures["depth_cues"]["hitter"]

    def along_sigma(seg):
        ray = seg.xyz - obs.camera.centre
        ray /= np.linalg.norm(ray, axis=1)[:, None]
        return float(np.sqrt(np.mean(np.einsum("mi,mij,mj->m", ray, seg.cov, ray))))

    actual = along_sigma(without[0]) / along_sigma(serve)
    assert reported > 2.0 and abs(reported / actual - 1.0) < 0.15, (reported, actual)
    assert without[0].figures["depth_cues"]["hitter"] < 1.1 and without[0].figures["depth_from"].startswith("the net")
    assert all(s.figures["depth_from"] for s in with_players.values())
