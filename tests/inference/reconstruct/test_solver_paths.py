"""The joint solver's fast paths against the paths they replace: RK4 steps spanning several frames against one
step per frame, batched flights against flights integrated alone, LM trials integrated in batches against
one at a time — on generated flights and on the padel sample with 2 px noise."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from inference.clipio import Clip
from inference.court import load_court
from inference.physics import FlightModel
from inference.reconstruct import shooting
from inference.reconstruct.evaluate import Setting, prepare
from inference.reconstruct.joint import JointConfig, fit_joint
from inference.reconstruct.shooting import N_IN, integrate

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"


def random_flights(S: int, fps: float, seed: int = 0):
    """S tennis flights (speeds 10–60 m/s, spins ~100 rad/s), half forwards with an end contact, half backwards."""
    rng = np.random.default_rng(seed)
    inp = np.zeros((S, N_IN))
    inp[:, :3] = rng.uniform([1, 1, 0.1], [9, 20, 2.5], (S, 3))
    inp[:, 3:6] = rng.normal(0, 8, (S, 3)) + np.array([0, 25, 3])
    inp[:, 6:9] = rng.normal(0, 100, (S, 3))
    F0 = rng.integers(0, 50, S)
    inp[:, 9] = F0 + rng.uniform(-0.5, 0.5, S)
    inp[:, 10] = 1.0
    direction = np.where(np.arange(S) % 2, 1, -1)
    L = int(0.8 * fps)
    tau_end = np.where(direction > 0, F0 + L - 2.3, np.nan)
    return inp, F0, direction, L, tau_end


@pytest.mark.parametrize(("fps", "stride"), [(25.0, 2), (30.0, 2), (50.0, 3), (60.0, 4)])
def test_steps_spanning_frames_match_one_step_per_frame(fps, stride):
    """Steps of up to 0.08 s (the default takes at least 15 per second) against one step per frame."""
    model = FlightModel.from_ball(load_court("tennis").ball)
    inp, F0, d, L, tau_end = random_flights(12, fps)
    assert stride <= fps / 12.5
    ref = integrate(inp, F0, d, L, tau_end, fps, model, 1, True, 1)
    fast = integrate(inp, F0, d, L, tau_end, fps, model, 1, True, stride)
    # flights that stay below 70 m/s (faster than any recorded shot; lead-ins integrated backwards speed up)
    real = np.linalg.norm(ref.V[:, 0], axis=-1).max(axis=1) < 70
    assert real.sum() >= 8
    assert np.abs(fast.P - ref.P)[real].max() < 2e-4       # positions (and their perturbations) within 0.2 mm
    assert np.abs(fast.P - ref.P).max() < 2e-3             # and within 2 mm at 100+ m/s
    assert np.abs(fast.end - ref.end).max() < 1e-4
    assert np.abs(fast.vend - ref.vend).max() < 1e-2       # velocity at the end contact within 1 cm/s
    # the Jacobian's finite differences (perturbed − base, per unit input) agree too
    dref = (ref.P[:, 1:] - ref.P[:, :1]) / shooting.EPS[None, :, None, None]
    dfast = (fast.P[:, 1:] - fast.P[:, :1]) / shooting.EPS[None, :, None, None]
    assert np.abs(dfast - dref)[real].max() < 3e-3         # dP/dv is up to ~0.8 m per m/s here
    # position perturbations as translations (a flight does not depend on where it starts), the drag one left
    # out: the same flights as integrating every perturbation
    part = integrate(inp, F0, d, L, tau_end, fps, model, 1, True, stride, tuple(range(3, 10)))
    np.testing.assert_allclose(part.P[:, :10], fast.P[:, :10], rtol=0, atol=1e-9)
    np.testing.assert_allclose(part.end[:, :10], fast.end[:, :10], rtol=0, atol=1e-9)
    np.testing.assert_allclose(part.vend[:, :10], fast.vend[:, :10], rtol=0, atol=1e-9)
    # and a wrong stride would be caught: steps of 4 × as many frames are visibly off
    coarse = integrate(inp, F0, d, L, tau_end, fps, model, 1, True, 4 * stride)
    assert np.abs(coarse.P - ref.P)[real].max() > 1e-3


@pytest.fixture(scope="module")
def sample_obs():
    obs, _, _ = prepare(Clip(SAMPLE), Setting(noise_px=2.0, players="gt", seed=3))
    return obs


def test_flights_integrated_together_equal_flights_integrated_alone(sample_obs):
    fit = fit_joint(sample_obs)
    assert fit.segments and all(s.ok for s in fit.segments)
    # a chain problem at two different θ: the batch's flights are exactly each θ's own
    from inference.reconstruct.joint import Plan, PlanContact, _fit_plan
    from inference.reconstruct.observations import contact_priors
    from inference.reconstruct.shooting import HitPrior
    cfg = JointConfig()
    plan = Plan([PlanContact(p, i) for i, p in enumerate(contact_priors(sample_obs))])
    chain_fit = _fit_plan(sample_obs, plan, cfg, FlightModel.from_ball(sample_obs.court.ball),
                          HitPrior.from_court(sample_obs.court))
    pb, theta = chain_fit.problem, chain_fit.sol.theta
    other = theta.copy()
    other[[f.vel[0] for f in pb.chain.flights]] += 0.5
    other[[ct.tau for ct in pb.chain.contacts]] += 0.7       # other grids (first frames, lengths)
    other = pb.clamp(other)
    both = pb.flights_batch([theta, other], perturb=True)
    for t, fl in zip((theta, other), both):
        alone = pb.flights(t, perturb=True)
        n = alone.P.shape[2]
        np.testing.assert_array_equal(fl.P[:, :, :n], alone.P)
        np.testing.assert_array_equal(fl.end, alone.end)
        np.testing.assert_array_equal(fl.vend, alone.vend)


def test_batched_lm_trials_follow_the_one_at_a_time_path(sample_obs, monkeypatch):
    fast = fit_joint(sample_obs).ball_3d()
    monkeypatch.setattr(shooting, "LM_BATCHES", (1,) * 8)
    one = fit_joint(sample_obs).ball_3d()
    assert fast.frame.tolist() == one.frame.tolist()
    np.testing.assert_allclose(fast.xyz, one.xyz, rtol=0, atol=1e-9)


def test_fast_solver_matches_the_reference_path(sample_obs, monkeypatch):
    """Default solver against one RK4 step per frame and one LM trial per integration (the slower path):
    the same positions within millimetres, and the same accuracy against the ground truth."""
    gt = Clip(SAMPLE).read_ball_3d(gt=True)
    fast = fit_joint(sample_obs).ball_3d()
    monkeypatch.setattr(shooting, "LM_BATCHES", (1,) * 8)
    ref = fit_joint(sample_obs, JointConfig(steps_per_second=sample_obs.fps)).ball_3d()
    assert fast.frame.tolist() == ref.frame.tolist()
    diff = np.linalg.norm(fast.xyz - ref.xyz, axis=1)
    assert np.median(diff) < 1e-3 and np.percentile(diff, 90) < 5e-3

    def err(b):
        i = np.searchsorted(gt.frame, b.frame)
        return np.linalg.norm(b.xyz - gt.xyz[i], axis=1)

    assert abs(np.median(err(fast)) - np.median(err(ref))) < 2e-3
    assert np.median(err(fast)) < 0.1


def test_a_flight_sent_flying_by_a_wild_start_is_capped_and_the_covariance_holds(sample_obs, monkeypatch):
    """A flight that nothing pins along the line of sight (a run-out the first pass leaves free, with few or
    no 2D points) could fly off to 10⁸ m/s: its hinge rows then swamped the normal matrix and every frame's σ
    collapsed to the 1 mm floor (a held-out padel clip: 2-σ coverage 0.03). Every LM trial is projected to
    speeds ≤ ``speed_cap`` (1000 m/s: a guard, not physics); from a start with the run-out at 10⁶ m/s the fit
    still ends with σ's of centimetres (the old code lost the whole clip from that start)."""
    from inference.reconstruct import joint

    init = joint._init_velocities

    def wild(obs, chain, theta, cfg):
        init(obs, chain, theta, cfg)
        f = chain.flights[-1]
        assert f.end is None                                     # the run-out
        theta[f.vel] = [0.0, -1e6, 0.0]

    monkeypatch.setattr(joint, "_init_velocities", wild)
    fit = fit_joint(sample_obs)
    _, cov = fit.covariances()
    across = np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, 0], 0.0))
    assert np.median(across) > 0.003, np.median(across)      # m: 6.8 mm here; collapsed, 1 mm
    ok = [s for s in fit.segments if s.ok]
    assert len(ok) >= len(fit.segments) - 2


def test_a_diverged_fit_gives_a_reason_in_words_not_the_librarys(sample_obs, monkeypatch):
    """A solver step that turns a contact time into NaN fails the plan with a reason that names the frames and
    what to check — never the exception text of the library underneath (issue 42)."""
    import inference.reconstruct.joint as joint
    from inference.reconstruct.joint import Plan, PlanContact, _fit_plan
    from inference.reconstruct.observations import contact_priors
    from inference.reconstruct.shooting import HitPrior

    def wild(problem, theta):
        raise ValueError("cannot convert float NaN to integer")

    monkeypatch.setattr(joint, "solve", wild)
    plan = Plan([PlanContact(p, i) for i, p in enumerate(contact_priors(sample_obs))])
    why = _fit_plan(sample_obs, plan, JointConfig(), FlightModel.from_ball(sample_obs.court.ball),
                    HitPrior.from_court(sample_obs.court))
    assert isinstance(why, str) and why.startswith("the fit diverged between frames")
    assert "NaN" not in why and "convert" not in why and "check the 2D ball" in why
