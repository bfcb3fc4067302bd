"""The default reconstruction: the whole rally fitted jointly, from the first to the last frame of the track.

One chain of flights per rally (:mod:`.shooting` fits it): every event's contact, the flights between them,
the *lead-in* before the first event and the *run-out* after the last one (free ends, trimmed where the
track stops looking like one flight). A clip with a single event is two free flights meeting at it. A
contact whose line of sight misses its surface or that has no 2D ball near it is bridged (its point
starts between its neighbours and is fitted like any other); a landing beyond a surface's polygon is fitted
on the unbounded plane and flagged.

Seen from behind the play the 2D track hardly says how far along the line of sight a racket hit or a free end
lies (a ball flying at the camera draws nearly the track of one flying away): the first fit is started again
from other depths there and the lowest-cost fit kept (:func:`_depth_restarts`).

Then the court is enforced (:mod:`.plausibility`): a flight whose reprojection RMS is far above the 2D noise
(or that leaves the court) is refitted under other contact hypotheses — a missed bounce, another surface,
another event class, no contact at all — and the best hypothesis is kept when it explains the track; what
still does not fit is reported failed with its reason, and its frames no longer pull its neighbours.

Per-frame 3×3 covariances come from the Gauss-Newton covariance of all unknowns (2D noise, contact times
and the hitter prior included), calibrated per sport (the court YAML's ``uncertainty``: a scale and an
along-ray model error growing with the time from the nearest contact; :class:`.shooting.Uncertainty`).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from inference.detection.smooth import track_runs
from inference.physics import FlightModel

from .observations import PLAYER_EVENTS, ContactPrior, Observations, Segment, contact_priors, nearest_observed
from .plan import Plan, PlanContact
from .plausibility import FlightCheck, check_flights, hypotheses, summary
from .results import RallyFit, SegmentFit
from .shooting import (BOUNCE_MATERIALS, JUMP_SHARE, Chain, HitPrior, Problem, ShootingConfig, Uncertainty,
                       build_chain, FrameErrorModel, depth_report, frame_error_model, net_height, solve)

__all__ = ["JointConfig", "fit_joint", "net_height"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class JointConfig(ShootingConfig):
    """The chain fit's weights (:class:`~.shooting.ShootingConfig`) and what the rally-level fit does."""

    min_observed: int = 3             # 2D points a chain needs
    hit_candidates: int = 48          # depths tried when initialising a racket hit
    free_ends: bool = True            # fit the track before the first and after the last event
    free_end_seconds: float = 1.5     # longest free end
    free_end_gap: int = 8             # frames without 2D that end a free end
    trim_sigma: float = 4.0           # a free end stops where 3 frames in a row are off by more (σ units)
    rms_fail_factor: float = 4.0      # a flight with RMS above this × pixel_sigma is refitted or failed
    refit: bool = True                # try other contact hypotheses for flights that do not fit
    max_refits: int = 8               # rounds of refits per rally (each keeps at most one new plan)
    max_hypotheses: int = 16          # hypotheses screened per failing flight and round (local fits: a few frames)
    verify_hypotheses: int = 3        # the locally best hypotheses of a flight fitted over the whole rally
    max_whole_refits: int = 24        # whole-rally fits the refits may spend in all
    leave_out_share: float = 0.5      # most of a still failing flight's detections one left-out block may hold
    leave_out_min_kept: int = 4       # detections that must remain on the flight (on both sides of the block)
    sigma_inflation: float = 1.0      # extra covariance scale on top of the court YAML's `uncertainty`
    sigma_floor_m: float = 0.0        # extra isotropic m added to every frame's σ (the court's floor_m first)
    uncertainty: Uncertainty | None = None  # covariance calibration (None: the court YAML's `uncertainty`)
    max_sigma_m: float = 3.0          # a flight whose median σ exceeds this is reported failed
    max_speed_ms: float = 75.0        # a flight launched faster (270 km/h; records are ~263) is implausible
    max_spin_rads: float = 600.0      # a flight leaving a racket spinning faster (5,700 rpm; a tennis topspin
    #                                   reaches ~5,000) is implausible too
    depth_restarts: int = 6           # fits from other depths the rally's first fit may spend (:func:`_depth_restarts`)


#: how a plan whose fit diverged is reported (:func:`fit_joint` then fits the rally in two halves)
DIVERGED = "the fit diverged"


@dataclass
class ChainFit:
    """A fitted chain: the plan, the problem, its solution and the per-flight checks."""

    plan: Plan
    problem: Problem
    sol: object
    checks: list[FlightCheck]

    @property
    def cost(self) -> float:
        n = 2 * len(self.problem.frames)
        r = self.sol.r[:n]
        return float(r @ r)


# ---------------------------------------------------------------------------------------------------
# Initialisation
# ---------------------------------------------------------------------------------------------------
def _parabola_error(obs: Observations, p0: np.ndarray, p1: np.ndarray, f0: float, f1: float,
                    frames: np.ndarray) -> np.ndarray:
    """Sum of squared reprojection errors over ``frames`` of vacuum parabolas from p0 (…, 3) at time f0 to p1
    (…, 3) at f1 (frames)."""
    seen = frames[np.isfinite(obs.uv[frames]).all(axis=1)]
    if not len(seen) or f1 == f0:
        return np.zeros(np.broadcast_shapes(p0.shape, p1.shape)[:-1])
    t = (seen - f0) / obs.fps
    T = (f1 - f0) / obs.fps
    g = obs.court.ball.gravity
    ez = np.array([0.0, 0.0, 1.0])
    v = (p1 - p0) / T + 0.5 * g * T * ez
    pos = p0[..., None, :] + v[..., None, :] * t[:, None] - 0.5 * g * (t**2)[:, None] * ez
    shape = pos.shape
    pix = obs.camera.project(pos.reshape(-1, 3)).reshape(shape[:-1] + (2,))
    err = np.sum((pix - obs.uv[seen]) ** 2, axis=-1)
    err = np.where(np.isfinite(err), np.minimum(err, 1e6), 1e6)
    return err.sum(axis=-1)


def _ray_candidates(obs: Observations, frame: int, n: int, z_range=(-0.5, 6.0)) -> np.ndarray | None:
    """(n, 3) points along the line of sight of ``frame``'s 2D ball, between two heights and in front."""
    uv = obs.uv[frame]
    if not np.isfinite(uv).all():
        return None
    o, d = obs.camera.rays(uv[None])
    o, d = o[0], d[0]
    if abs(d[2]) < 1e-6:
        s = np.linspace(1.0, 60.0, n)
    else:
        a, b = sorted(((z_range[0] - o[2]) / d[2], (z_range[1] - o[2]) / d[2]))
        a, b = max(a, 0.5), min(max(b, 0.5), 80.0)
        if b <= a:
            return None
        s = np.linspace(a, b, n)
    return o + s[:, None] * d


def _init_points(obs: Observations, chain: Chain, theta: np.ndarray) -> bool:
    """Contacts without a first guess start between their neighbours (on their plane when they have one).
    False when no contact of the chain has a guess."""
    known = [c for c, ct in enumerate(chain.contacts) if np.isfinite(theta[ct.coords]).all()]
    if not known:
        return False
    for c, ct in enumerate(chain.contacts):
        if c in known:
            continue
        before = [k for k in known if k < c]
        after = [k for k in known if k > c]
        pts = [(chain.contacts[k].frame, chain.point(theta, k)) for k in (before[-1:] + after[:1])]
        if len(pts) == 2:
            (f0, p0), (f1, p1) = pts
            p = p0 + (p1 - p0) * (ct.frame - f0) / max(f1 - f0, 1)
        else:
            p = pts[0][1]
        theta[ct.coords] = np.linalg.lstsq(ct.basis, p - ct.origin, rcond=None)[0]
    return True


def _hit_span(obs: Observations, o: np.ndarray, d: np.ndarray) -> tuple[float, float] | None:
    """Distances (s_lo, s_hi) along the ray o + s·d (d a unit (3,) vector) between the court's lowest and highest
    hit heights, at least 0.5 m in front; None when the ray is level or the span is empty."""
    if abs(d[2]) < 1e-6:
        return None
    lo, hi = obs.court.hits.height
    s_lo, s_hi = sorted(((lo - o[2]) / d[2], (hi - o[2]) / d[2]))
    s_lo = max(s_lo, 0.5)
    return (s_lo, s_hi) if s_hi > s_lo else None


def _init_hits(obs: Observations, chain: Chain, theta: np.ndarray, cfg: JointConfig) -> None:
    """Place each racket hit on its line of sight at the depth whose neighbouring vacuum parabolas best
    explain the 2D track (two sweeps, so neighbouring hits settle together)."""
    hits = obs.court.hits
    K = len(chain.contacts)
    for _ in range(2):
        for c, ct in enumerate(chain.contacts):
            if ct.kind != "hit":
                continue
            uv, _f = nearest_observed(obs.uv, ct.frame)
            if uv is None:
                continue
            o, d = obs.camera.rays(uv[None])
            o, d = o[0], d[0]
            span = _hit_span(obs, o, d)
            if span is None:
                continue
            s_lo, s_hi = span
            cand = o + np.linspace(s_lo, s_hi, cfg.hit_candidates)[:, None] * d
            if ct.prior.hitter_xy is not None:
                near = np.linalg.norm(cand[:, :2] - ct.prior.hitter_xy, axis=1) <= hits.reach
                cand = cand[near] if near.any() else cand
            err = np.zeros(len(cand))
            if c > 0:
                a = chain.contacts[c - 1]
                err += _parabola_error(obs, chain.point(theta, c - 1)[None], cand, a.frame, ct.frame,
                                       np.arange(a.frame, ct.frame + 1))
            if c < K - 1:
                b = chain.contacts[c + 1]
                err += _parabola_error(obs, cand, chain.point(theta, c + 1)[None], ct.frame, b.frame,
                                       np.arange(ct.frame, b.frame + 1))
            theta[ct.coords] = cand[int(np.argmin(err))]


def _init_velocities(obs: Observations, chain: Chain, theta: np.ndarray, cfg: JointConfig) -> None:
    """Vacuum parabolas between contacts; free ends: the parabola from the contact to the point on the line of
    sight of the free end's farthest observed frame that best explains its 2D track."""
    g = obs.court.ball.gravity
    ez = np.array([0.0, 0.0, 1.0])
    for f in chain.flights:
        ct = chain.contacts[f.start]
        p0 = chain.point(theta, f.start)
        if f.end is not None:
            T = max(chain.contacts[f.end].frame - ct.frame, 1) / obs.fps
            theta[f.vel] = (chain.point(theta, f.end) - p0) / T + 0.5 * g * T * ez
            continue
        span = np.arange(min(f.last, ct.frame), max(f.last, ct.frame) + 1)
        seen = span[np.isfinite(obs.uv[span]).all(axis=1)]
        far = seen[np.argmax(np.abs(seen - ct.frame))] if len(seen) else None
        cand = _ray_candidates(obs, int(far), 60) if far is not None and far != ct.frame else None
        if cand is None:
            theta[f.vel] = 0.0
            continue
        err = _parabola_error(obs, p0[None], cand, ct.frame, far, seen)
        best = cand[int(np.argmin(err))]
        T = (far - ct.frame) / obs.fps
        theta[f.vel] = (best - p0) / T + 0.5 * g * T * ez   # velocity at the contact (arriving for a lead-in)


# ---------------------------------------------------------------------------------------------------
# Fitting a plan
# ---------------------------------------------------------------------------------------------------
def _free_end(obs: Observations, frame: int, direction: int, cfg: JointConfig, limit: int,
              min_seen: int = 3) -> int | None:
    """The farthest frame of a free end from the event at ``frame`` (None: no usable free end, fewer than
    ``min_seen`` 2D points)."""
    if not cfg.free_ends:
        return None
    longest = int(round(cfg.free_end_seconds * obs.fps))
    f, last_seen, n_seen = frame, None, 0
    while True:
        f += direction
        if f < 0 or f >= obs.n_frames or abs(f - frame) > longest or (direction < 0 and f < limit) or \
                (direction > 0 and f > limit):
            break
        if np.isfinite(obs.uv[f]).all():
            last_seen, n_seen = f, n_seen + 1
        elif last_seen is not None and abs(f - last_seen) > cfg.free_end_gap:
            break
        elif last_seen is None and abs(f - frame) > cfg.free_end_gap:
            break
    return last_seen if n_seen >= min_seen else None


def _free_end_min_seen(prior: ContactPrior) -> int:
    """2D points a free end at this contact needs: one at a floor/glass bounce (the impact model carries the
    flight on the other side through it), else three."""
    return 1 if prior.plane is not None and prior.plane.material in BOUNCE_MATERIALS else 3


def _warm(theta: np.ndarray, chain: Chain, warm: dict | None) -> None:
    """Start from a previous fit's values for contacts and flights it shares with this chain."""
    if not warm:
        return
    for ct in chain.contacts:
        v = warm.get(("c", ct.frame, ct.label))
        if v is not None and len(v) == 1 + len(ct.coords):
            theta[ct.tau] = v[0]
            theta[ct.coords] = v[1:]
    for f in chain.flights:
        v = warm.get(("f", chain.contacts[f.start].frame, f.direction, f.end is None))
        if v is not None:
            theta[f.vel] = v[:3]
            if f.spin is not None and len(v) >= 6:
                theta[f.spin] = v[3:6]


def _remember(chain: Chain, theta: np.ndarray) -> dict:
    out = {}
    for ct in chain.contacts:
        out[("c", ct.frame, ct.label)] = np.r_[theta[ct.tau], theta[ct.coords]]
    for f in chain.flights:
        v = theta[f.vel]
        if f.spin is not None:
            v = np.r_[v, theta[f.spin]]
        out[("f", chain.contacts[f.start].frame, f.direction, f.end is None)] = v
    return out


def _fit_plan(obs: Observations, plan: Plan, cfg: JointConfig, model: FlightModel, hit_prior: HitPrior,
              span: tuple[int, int] | None = None, warm: dict | None = None,
              mute: list[tuple[int, int]] | None = None) -> ChainFit | str:
    """Fit one plan; a string says why it cannot be fitted."""
    priors = [c.prior for c in plan.contacts]
    first, last = priors[0].frame, priors[-1].frame
    lead = _free_end(obs, first, -1, cfg, 0, _free_end_min_seen(priors[0]))
    tail = _free_end(obs, last, +1, cfg, obs.n_frames - 1, _free_end_min_seen(priors[-1]))
    if span is not None:  # trimmed free ends
        lead = lead if lead is None else max(lead, span[0])
        tail = tail if tail is None else min(tail, span[1])
        lead = None if lead is not None and lead >= first - 1 else lead
        tail = None if tail is not None and tail <= last + 1 else tail
    chain, theta = build_chain(obs, priors, lead if lead is not None else first, tail if tail is not None else last,
                               lead is not None, tail is not None, cfg)
    if not chain.flights:
        return "a single event with no 2D track around it"
    if not _init_points(obs, chain, theta):
        return "no contact of the rally could be placed (no 2D ball near any event)"
    _init_hits(obs, chain, theta, cfg)
    _init_velocities(obs, chain, theta, cfg)
    _warm(theta, chain, warm)
    problem = Problem(obs, chain, cfg, model, hit_prior)
    if len(problem.frames) < cfg.min_observed:
        return f"only {len(problem.frames)} 2D ball positions between frames {chain.first_frame} and {chain.last_frame}"
    if mute:
        problem.mute(mute)
    if plan.left_out:
        problem.leave_out(plan.left_out)
    try:
        sol = solve(problem, theta)
    except (ValueError, np.linalg.LinAlgError) as e:   # a wild step (NaN contact time): the plan fails
        # the library's words ("cannot convert float NaN to integer") go to the log, not to the user's reason
        log.debug("the fit of frames %d–%d diverged: %s: %s", chain.first_frame, chain.last_frame, type(e).__name__, e)
        return (f"{DIVERGED} between frames {chain.first_frame} and {chain.last_frame} (no consistent flight "
                "through these contacts: check the 2D ball and the events there)")
    checks = check_flights(problem, sol, cfg)
    return ChainFit(plan, problem, sol, checks)


def _trimmed_span(fit: ChainFit, cfg: JointConfig) -> tuple[int, int] | None:
    """Where the free ends stop fitting one flight: the first of 3 frames in a row off by more than
    ``trim_sigma`` σ, walking away from the contact; None when nothing needs trimming."""
    pb, sol = fit.problem, fit.sol
    ch = pb.chain
    taus = sol.aux["taus"]
    norm = pb.last_norm
    lo, hi = ch.first_frame, ch.last_frame
    changed = False
    for f in ch.flights:
        if f.end is not None:
            continue
        t0 = taus[f.start]
        m = (pb.frames < t0) if f.lead_in else (pb.frames > t0)
        fr, nm = pb.frames[m], norm[m]
        order = np.argsort(np.abs(fr - t0))
        fr, bad = fr[order], nm[order] > cfg.trim_sigma
        run = np.convolve(bad.astype(int), np.ones(3, int), mode="valid") if len(bad) >= 3 else np.zeros(0)
        k = np.flatnonzero(run == 3)
        if len(k):
            cut = fr[k[0]]
            changed = True
            if f.lead_in:
                lo = int(cut) + 1
            else:
                hi = int(cut) - 1
    return (lo, hi) if changed else None


def _fit_with_ends(obs, plan, cfg, model, hit_prior, warm=None, mute=None, span=None) -> ChainFit | str:
    fit = _fit_plan(obs, plan, cfg, model, hit_prior, span=span, warm=warm, mute=mute)
    if isinstance(fit, str):
        return fit
    trimmed = _trimmed_span(fit, cfg)
    if trimmed is not None:
        again = _fit_plan(obs, plan, cfg, model, hit_prior, span=trimmed,
                          warm=_remember(fit.problem.chain, fit.sol.theta), mute=mute)
        if not isinstance(again, str):
            fit = again
    if span is None:
        fit = _shorter_free_ends(obs, plan, cfg, model, hit_prior, fit, mute)
    return fit


def _free_ends_of(fit: ChainFit) -> set[bool]:
    """The free ends a fit has: True for its lead-in, False for its run-out."""
    return {bool(f.lead_in) for f in fit.problem.chain.flights if f.end is None}


def _free_end_reason(obs: Observations, seg: Segment) -> str:
    """Why a lead-in or run-out has no 3D: no 2D ball beyond its event, or a track there that is not one
    flight from the event."""
    beyond = obs.uv[:seg.end] if seg.index == -1 else obs.uv[seg.start + 1:]
    if not np.isfinite(beyond).all(axis=1).any():
        return "no 2D track beyond the event"
    return ("the 2D track beyond the event is not one flight from it (a bounce or hit the events missed, or the "
            "tracker on something else)")


#: 2D points a free end fitted again over a shorter stretch needs (a few frames right at the contact are no
#: evidence of the flight: on a real clip three such frames gave an 18 km/h "groundstroke")
MIN_RECOVERED_FREE_END = 6


def _seen_in_free_end(obs, fit: ChainFit, lead: bool, first: int, last: int) -> int:
    """2D points inside a fit's lead-in (``lead``) or run-out."""
    ch = fit.problem.chain
    a, b = (ch.first_frame, first - 1) if lead else (last + 1, ch.last_frame)
    return int(np.isfinite(obs.uv[max(a, 0):b + 1]).all(axis=1).sum()) if b >= a else 0


def _shorter_free_ends(obs, plan, cfg, model, hit_prior, fit: ChainFit, mute=None) -> ChainFit:
    """A free end trimmed away although the 2D track goes on there (the track beyond the first or last event
    is not one flight over its whole length: a missed bounce or hit in it, as in a clip with a single event)
    is fitted again over half the length, then a quarter, …, down to 6 frames; the first such fit that has
    it with at least :data:`MIN_RECOVERED_FREE_END` 2D points and no more failing flights is kept."""
    priors = [c.prior for c in plan.contacts]
    first, last = priors[0].frame, priors[-1].frame
    want = set()
    if _free_end(obs, first, -1, cfg, 0, _free_end_min_seen(priors[0])) is not None:
        want.add(True)
    if _free_end(obs, last, +1, cfg, obs.n_frames - 1, _free_end_min_seen(priors[-1])) is not None:
        want.add(False)
    lost = want - _free_ends_of(fit)
    if not lost:
        return fit
    ch = fit.problem.chain
    n_ok = sum(c.ok for c in fit.checks)
    k = int(round(cfg.free_end_seconds * obs.fps)) // 2
    while k >= 6:
        span = (first - k if True in lost else ch.first_frame, last + k if False in lost else ch.last_frame)
        trial = _fit_with_ends(obs, plan, cfg, model, hit_prior, warm=_remember(ch, fit.sol.theta), mute=mute,
                               span=span)
        if not isinstance(trial, str) and lost <= _free_ends_of(trial) and sum(c.ok for c in trial.checks) >= n_ok \
                and all(_seen_in_free_end(obs, trial, lead, first, last) >= MIN_RECOVERED_FREE_END for lead in lost):
            return trial
        k //= 2
    return fit


# ---------------------------------------------------------------------------------------------------
# Other depths along the line of sight
# ---------------------------------------------------------------------------------------------------
#: a restart is kept when it lowers the fit's cost by more than this share (and every flight passes)
RESTART_GAIN = 0.02
#: a first fit with more failing flights is not restarted: a wrong depth fails the flights at one hit or free
#: end; more is a track the refits must sort out (a broadcast rally with 10 of 15 flights failing had 3 of them
#: passing — wrong, 1–3 m off — after restarts)
MAX_FAILING_TO_RESTART = 2


def _fresh_problem(fit: ChainFit) -> Problem:
    """A new problem for the same chain, with the same frames muted and left out by the caller."""
    old = fit.problem
    pb = Problem(old.obs, old.chain, old.cfg, old.model, old.hit_prior)
    pb.muted |= old.muted
    pb.weights[pb.muted] = 0.0
    pb.leave_out(old.frames[old.forced])
    return pb


def _depth_starts(obs: Observations, fit: ChainFit, cfg: JointConfig) -> list[np.ndarray]:
    """Starts for :func:`_depth_restarts`, each the fit's θ with one thing moved along the line of sight:

    - a racket hit with no hitter position (no players.csv, no player near): moved to other depths on its
      line of sight between the court's hit heights (a quarter of that range or more away), the flights
      around it started again from vacuum parabolas;
    - a free end (lead-in, run-out) whose velocity at its contact runs mostly along the line of sight:
      that component reversed (a ball flying at the camera and one flying away from it draw nearly the same
      2D track). A run-out leaving a bounce is tried too: the impact model ties it to its incoming flight,
      but reversed it can pull that flight (a lead-in) into the other basin."""
    ch, theta = fit.problem.chain, fit.sol.theta
    starts: list[np.ndarray] = []
    for c, ct in enumerate(ch.contacts):
        if ct.kind != "hit" or ct.prior.hitter_xy is not None:
            continue
        o = obs.camera.centre
        d = ch.point(theta, c) - o
        s_now = float(np.linalg.norm(d))
        d = d / s_now
        span = _hit_span(obs, o, d)
        if span is None:
            continue
        s_lo, s_hi = span
        for s_new in np.linspace(s_lo, s_hi, 4):
            if abs(s_new - s_now) < (s_hi - s_lo) / 4:
                continue
            t = theta.copy()
            t[ct.coords] = ct.basis.T @ (o + s_new * d - ct.origin)
            fresh = t.copy()
            _init_velocities(obs, ch, fresh, cfg)
            for f in ch.flights:
                if f.start == c or f.end == c:
                    t[f.vel] = fresh[f.vel]
            starts.append(t)
    for f in ch.flights:
        if f.end is not None:
            continue
        p = ch.point(theta, f.start)
        r = p - obs.camera.centre
        r = r / np.linalg.norm(r)
        v = theta[f.vel]
        along = float(v @ r)
        if abs(along) < 1.0 or abs(along) < 0.5 * np.linalg.norm(v):
            continue
        t = theta.copy()
        t[f.vel] = v - 2.0 * along * r
        starts.append(t)
    return starts


def _depth_restarts(obs: Observations, fit: ChainFit, cfg: JointConfig) -> ChainFit:
    """The rally's first fit started again from other depths along the lines of sight (:func:`_depth_starts`), at
    most ``depth_restarts`` times, before the refits (a wrong depth fails checks — a hit on the far side — and
    the refits would change the events to explain it), and only when at most :data:`MAX_FAILING_TO_RESTART`
    flights fail. A restart replaces the fit when it ends with a lower cost (by :data:`RESTART_GAIN`), every
    flight passing and no more detections left out (a lower cost alone had moved a passing flight under the
    floor; fewer failing flights alone had written wrong flights of a broadcast rally).

    Seen from behind the play, the 2D track hardly says how far along the line of sight a racket hit or a
    free end lies, and the first guess (vacuum parabolas, no drag) picks a depth the fit then stays near:
    simulated tennis shots flying at a broadcast camera 22 m behind the baseline, hit → bounce → a few
    frames, with no players.csv, ended 1–5 m off in 14 of 60 tracks, 11 of them with a lower cost near the truth."""
    if cfg.depth_restarts <= 0 or sum(not c.ok for c in fit.checks) > MAX_FAILING_TO_RESTART:
        return fit
    best = fit
    best_cost = float(fit.sol.r @ fit.sol.r)
    for start in _depth_starts(obs, fit, cfg)[:cfg.depth_restarts]:
        pb = _fresh_problem(fit)
        try:
            sol = solve(pb, start)
        except (ValueError, np.linalg.LinAlgError):
            continue
        cost = float(sol.r @ sol.r)
        if not np.isfinite(cost) or cost > best_cost * (1.0 - RESTART_GAIN):
            continue
        checks = check_flights(pb, sol, cfg)
        if not all(c.ok for c in checks) or pb.outliers.sum() > best.problem.outliers.sum():
            continue
        best, best_cost = ChainFit(fit.plan, pb, sol, checks), cost
        log.debug("a fit started from another depth along the line of sight lowered the cost to %.1f", cost)
    return best


# ---------------------------------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------------------------------
def _camera_sees_court(obs: Observations) -> bool:
    sx, sy = obs.court.size
    corners = np.array([[0, 0, 0], [sx, 0, 0], [0, sy, 0], [sx, sy, 0], [sx / 2, sy / 2, 0]], float)
    px = obs.camera.project(corners)
    w, h = obs.camera.image_size
    inside = np.isfinite(px).all(axis=1) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    return bool(inside.any())


def output_segments(obs: Observations) -> list[Segment]:
    """The flights reported: between consecutive events (index i from event i to i + 1), plus the lead-in
    (index −1, before the first event) and the run-out (index E − 1, after the last) — frames filled in only
    where the fit covers them."""
    f, lab = obs.event_frames, obs.event_labels
    E = len(f)
    segs = [Segment(i, int(f[i]), int(f[i + 1]), lab[i], lab[i + 1]) for i in range(E - 1)]
    if E:
        segs.insert(0, Segment(-1, int(f[0]), int(f[0]), None, lab[0]))
        segs.append(Segment(E - 1, int(f[-1]), int(f[-1]), lab[-1], None))
    return segs


def fit_joint(obs: Observations, config: JointConfig | None = None, priors: list[ContactPrior] | None = None,
              model: FlightModel | None = None) -> RallyFit:
    """Reconstruct the whole rally jointly (the default method; see the module docstring)."""
    cfg = config or JointConfig()
    if obs.pixel_sigma is not None and obs.pixel_sigma > cfg.pixel_sigma:  # the clip's measured 2D noise
        cfg = replace(cfg, pixel_sigma=float(obs.pixel_sigma))
    t0, c0 = time.perf_counter(), time.process_time()
    model = model or FlightModel.from_ball(obs.court.ball)
    hit_prior = HitPrior.from_court(obs.court)
    priors = priors if priors is not None else contact_priors(obs)
    segs = output_segments(obs)
    extra: dict = {}
    error_model = None
    if not len(priors):
        fits = [SegmentFit.failed(s, "no events: nothing anchors the flight") for s in segs]
    elif not _camera_sees_court(obs):
        fits = [SegmentFit.failed(s, "the camera does not see the court (no court corner projects into the image)")
                for s in segs]
    else:
        plan = Plan([PlanContact(p, i) for i, p in enumerate(priors)])
        with threadpool_limits(1):  # small dense solves: BLAS threads only add contention
            fit = _fit_with_ends(obs, plan, cfg, model, hit_prior)
            if not isinstance(fit, str):
                fit = _depth_restarts(obs, fit, cfg)
            if not isinstance(fit, str) and cfg.refit:
                fit = _refit_bad_flights(obs, fit, cfg, model, hit_prior)
        if isinstance(fit, str) and fit.startswith(DIVERGED) and len(priors) >= 3:
            return _fit_halves(obs, cfg, model, fit, t0, c0)
        if isinstance(fit, str):
            fits = [SegmentFit.failed(s, fit) for s in segs]
        else:
            with threadpool_limits(1):  # the covariance's eigendecomposition too (threads: 10× the CPU time)
                fits, error_model = _segment_fits(obs, segs, fit, cfg)
            extra["iterations"] = [fit.sol.iterations]
            if fit.plan.notes:
                extra["refits"] = list(fit.plan.notes)
    # a single event's free ends are the whole replay: a failed one is said, not dropped
    fits = [f for f in fits if f.ok or obs.single_event or f.segment.index not in (-1, len(obs.event_frames) - 1)]
    out = RallyFit("joint", obs.fps, fits, time.perf_counter() - t0, extra=extra,
                   cpu_seconds=time.process_time() - c0, error_model=error_model)
    out.extra["plausibility"] = summary(out, obs, cfg.rms_fail_factor * cfg.pixel_sigma)
    return out


def _fit_halves(obs: Observations, cfg: JointConfig, model: FlightModel, why: str, t0: float, c0: float) -> RallyFit:
    """A rally whose whole fit diverged, fitted as two rallies sharing its middle event (each split again if it
    diverges too): one wild region no longer costs the whole clip its 3D. The first half keeps its lead-in and
    the flights up to the middle event, the second its flights from there and its run-out."""
    E = len(obs.event_frames)
    mid = E // 2
    halves = []
    for lo, hi in ((0, mid), (mid, E - 1)):
        sub = replace(obs, event_frames=obs.event_frames[lo:hi + 1], event_labels=list(obs.event_labels[lo:hi + 1]))
        halves.append((lo, fit_joint(sub, cfg, model=model)))
    fits, refits, iterations = [], [], []
    for lo, half in halves:  # the flights of the shared middle event once: the first half's run-out goes
        fits += [replace(f, segment=replace(f.segment, index=f.segment.index + lo)) for f in half.segments
                 if (f.segment.index < mid if lo == 0 else f.segment.index >= 0)]
        refits += half.extra.get("refits", [])
        iterations += half.extra.get("iterations", [])
    note = (f"{why}; fitted as two rallies split at the event at frame {int(obs.event_frames[mid])}")
    log.info(note)
    out = RallyFit("joint", obs.fps, fits, time.perf_counter() - t0, cpu_seconds=time.process_time() - c0,
                   extra={"split": note, **({"refits": refits} if refits else {}),
                          **({"iterations": iterations} if iterations else {})})
    out.extra["plausibility"] = summary(out, obs, cfg.rms_fail_factor * cfg.pixel_sigma)
    return out


def _bad_flights(fit: ChainFit) -> list[int]:
    """Flights between two contacts that fail their checks, the worst fitted first (a flight that is far off
    bends its neighbours: their hypotheses wait until it is explained)."""
    flights = fit.problem.chain.flights
    bad = [k for k, c in enumerate(fit.checks) if not c.ok and flights[k].end is not None]
    rms = [fit.checks[k].rms_px for k in bad]
    out = [k for _, k in sorted(zip([-(r if r == r else 0.0) for r in rms], bad))]
    # a failing run-out is muted, not refitted; what breaks it is often its contact, whose hypotheses belong
    # to the flight before it (a bounce just before the last hit, missed)
    for k, c in enumerate(fit.checks):
        if not c.ok and flights[k].end is None:
            j = k - 1
            if j >= 0 and flights[j].end is not None and fit.checks[j].ok and j not in out:
                out.append(j)
    return out


def _n_failing(fit: ChainFit) -> int:
    """How many of the chain's flights (lead-in and run-out included) fail their checks."""
    return sum(not c.ok for c in fit.checks)


#: refit hypotheses that leave this many 2D points (or a tenth of the rally's) unexplained more or less than
#: another are as good as it by that measure, and compete on their fit alone
UNEXPLAINED_TOLERANCE = 5


def unexplained(fit: ChainFit, span: tuple[int, int]) -> tuple[int, float]:
    """How much of the 2D track over ``span`` (first, last frame) a fit leaves unexplained: the points that no
    passing flight explains (a failing flight's, one the chain does not reach, a detection left out), and the
    squared residuals (σ units) of the others. Dropping a contact so that a failing flight disappears, with
    the track it had to explain, is no gain."""
    pb = fit.problem
    seen = np.isfinite(pb.obs.uv[span[0]:span[1] + 1]).all(axis=1)
    own = pb.owners(pb.frames, fit.sol.aux["taus"])
    passing = np.array([c.ok for c in fit.checks], bool)[own] & (pb.weights > 0)
    passing &= (pb.frames >= span[0]) & (pb.frames <= span[1])
    return int(seen.sum() - passing.sum()), float(np.sum(pb.last_norm[passing] ** 2))


def _window(fit: ChainFit, k: int) -> tuple[int, int]:
    """The frames of the contacts around chain flight ``k``: from the contact before its start to the one after
    its end (its neighbours' flights are in the window too: a contact moved or inserted there changes them)."""
    ch = fit.problem.chain
    f = ch.flights[k]
    K = len(ch.contacts)
    a = max(f.start - 1, 0)
    b = min((f.end if f.end is not None else f.start) + 1, K - 1)
    return int(ch.contacts[a].frame), int(ch.contacts[b].frame)


def _local_plan(plan: Plan, window: tuple[int, int]) -> Plan | None:
    """The contacts of ``plan`` inside ``window`` (frames), or None when fewer than two are."""
    inside = [c for c in plan.contacts if window[0] <= c.prior.frame <= window[1]]
    return Plan(inside, plan.notes, plan.left_out) if len(inside) >= 2 else None


def _local_score(obs, plan: Plan, window: tuple[int, int], cfg: JointConfig, model, hit_prior, warm
                 ) -> tuple[int, float, int] | None:
    """A plan fitted only between its contacts inside ``window`` (a few frames instead of the rally; the free
    end only where the window holds the plan's first or last contact: a hypothesis for the flight before a
    failing run-out is judged with that run-out): ``(2D points left unexplained, squared residuals, failing
    flights)`` there, or None when it cannot be fitted locally."""
    sub = _local_plan(plan, window)
    if sub is None:
        return None
    first = sub.contacts[0] is plan.contacts[0]
    last = sub.contacts[-1] is plan.contacts[-1]
    span = (0 if first else sub.contacts[0].prior.frame, obs.n_frames - 1 if last else sub.contacts[-1].prior.frame)
    fit = _fit_with_ends(obs, sub, replace(cfg, free_ends=cfg.free_ends and (first or last)), model, hit_prior,
                         warm=warm, span=span)
    if isinstance(fit, str):
        return None
    n, cost = unexplained(fit, window)
    return n, cost, _n_failing(fit)


def _improves(n: int, cost: float, failing: int, base: tuple[int, float, int], tol: int) -> bool:
    """Whether a hypothesis leaving ``n`` 2D points unexplained with squared residuals ``cost`` and ``failing``
    failing flights beats ``base``: it explains clearly more, or about as much and fits it better — by half, or
    at all when fewer flights fail (the run-out included: a hit at the floor fails the run-out, not the flight
    before it)."""
    better = cost < 0.5 * base[1] or (cost < base[1] and failing < base[2])
    return n < base[0] - tol or (n <= base[0] + tol and better)


def _tolerance(obs, span: tuple[int, int]) -> int:
    """2D points two hypotheses may differ by in what they leave unexplained and still count as equal."""
    return max(UNEXPLAINED_TOLERANCE, int(0.1 * np.isfinite(obs.uv[span[0]:span[1] + 1]).all(axis=1).sum()))


def _refit_bad_flights(obs, fit: ChainFit, cfg: JointConfig, model, hit_prior) -> ChainFit:
    """Try other contact hypotheses for each flight that does not fit; keep the best that explains the track;
    then refit with the frames of what still fails muted, so it does not pull its neighbours.

    Each hypothesis is first fitted locally — only the contacts from the one before the flight to the one after
    it, without free ends — and compared there with the current plan fitted the same way; the locally best
    ones (at most ``cfg.verify_hypotheses``) are then fitted over the whole rally and kept by the same test on
    the whole track. A rally with many missed contacts (a broadcast's glass rebounds and volleys) so gets
    ``cfg.max_hypotheses`` tries per failing flight at the price of a few whole fits."""
    tried: set[tuple] = {fit.plan.key()}
    # one yardstick for every hypothesis: the track between the first and the last event (the free ends beyond
    # are what the track alone pins; a hypothesis that explains them differently is no better for it)
    span = (int(obs.event_frames[0]), int(obs.event_frames[-1]))
    # a run of detections off the ball first: a contact inserted to explain it would cut the flight in two
    fit = leave_out_off_runs(obs, fit, cfg, model, hit_prior, span)
    whole_fits = 0
    for _ in range(cfg.max_refits):
        # hypotheses only for flights between two contacts: a free end that does not fit is muted below
        bad = _bad_flights(fit)
        if not bad:
            break
        improved = False
        current = unexplained(fit, span)
        tol = _tolerance(obs, span)
        warm = _remember(fit.problem.chain, fit.sol.theta)
        for k in bad:
            window = _window(fit, k)
            base = _local_score(obs, fit.plan, window, cfg, model, hit_prior, warm)
            local_tol = _tolerance(obs, window)
            screened, n_tried = [], 0
            for plan in hypotheses(obs, fit, k, cfg):
                if plan.key() in tried:
                    continue
                if n_tried >= cfg.max_hypotheses:
                    break
                tried.add(plan.key())
                n_tried += 1
                loc = _local_score(obs, plan, window, cfg, model, hit_prior, warm) if base is not None else None
                if loc is None:  # no local comparison possible: the whole fit decides
                    screened.append(((-1, 0.0, 0), plan))
                elif _improves(*loc, base, local_tol):
                    screened.append((loc, plan))
                else:  # locally no better: verified only when nothing better is left (the whole track decides)
                    screened.append(((loc[0] + 10**6, *loc[1:]), plan))
            # those explaining clearly more of the window first, then the best fitted
            screened.sort(key=lambda s: (s[0][0] // max(local_tol, 1), s[0][1]))
            kept = []
            for _loc, plan in screened[:cfg.verify_hypotheses]:
                if whole_fits >= cfg.max_whole_refits:
                    break
                whole_fits += 1
                cand = _fit_with_ends(obs, plan, cfg, model, hit_prior, warm=warm)
                if isinstance(cand, str):
                    continue
                n, cost = unexplained(cand, span)
                if _improves(n, cost, _n_failing(cand), (*current, _n_failing(fit)), tol):
                    kept.append((n, cost, cand))
            if kept:  # of those explaining about as much of the track as the best, the one that fits it best
                least = min(n for n, _, _ in kept)
                fit = min((c for c in kept if c[0] <= least + tol), key=lambda c: c[1])[2]
                improved = True
                break
        if not improved:
            break
    fit = leave_out_off_runs(obs, fit, cfg, model, hit_prior, span)
    failed = [c for c in fit.checks if not c.ok]
    if failed:
        mute = [(c.first, c.last) for c in failed]
        again = _fit_with_ends(obs, fit.plan, cfg, model, hit_prior, warm=_remember(fit.problem.chain, fit.sol.theta),
                               mute=mute)
        if not isinstance(again, str):
            # the muted flights stay failed (with their first reason); their neighbours are judged afresh
            reasons = {(c.first, c.last): c.reason for c in failed}
            for c in again.checks:
                for (a, b), why in reasons.items():
                    if c.first <= b and c.last >= a and c.first >= a - 1 and c.last <= b + 1:
                        c.ok, c.reason = False, why
            fit = again
    return fit


def _detection_runs(obs, first: int, last: int) -> list[np.ndarray]:
    """Frames of the runs of detections strictly between ``first`` and ``last``: consecutive ones at most 2
    frames apart whose step per frame stays under half :data:`~.shooting.JUMP_SHARE` of the width (a broadcast
    ball moves far less: a larger step is the detector moving to something else)."""
    fr = np.arange(first + 1, last)
    fr = fr[np.isfinite(obs.uv[fr]).all(axis=1)]
    return [fr[r] for r in track_runs(fr, obs.uv[fr], 0.5 * JUMP_SHARE * obs.camera.image_size[0])]


def _blocks(runs: list[np.ndarray], cfg: JointConfig) -> list[np.ndarray]:
    """Frames of each block of consecutive runs that could be left out: inside the flight (detections kept on
    both sides), at most ``leave_out_share`` of its detections, at least ``leave_out_min_kept`` left; fewest
    frames first."""
    n = sum(len(r) for r in runs)
    out = []
    for i in range(1, len(runs) - 1):
        for j in range(i, len(runs) - 1):
            block = np.concatenate(runs[i:j + 1])
            if len(block) <= cfg.leave_out_share * n and n - len(block) >= cfg.leave_out_min_kept:
                out.append(block)
    return sorted(out, key=len)


def leave_out_off_runs(obs, fit: ChainFit, cfg: JointConfig, model, hit_prior, span: tuple[int, int]) -> ChainFit:
    """For each flight that still fails after the contact hypotheses: the detector may have spent a run of
    frames on something else (a player, a racket) inside it — longer than the fit's own outlier rule leaves out
    (``outlier_run_s``, ``outlier_share``). Try leaving out each block of runs inside the flight (the fewest
    detections first), fitted locally; keep the first that makes the flight pass with the block far off it
    (every detection of it beyond ``outlier_k`` σ), verified over the whole rally by the refits' test. The
    block is reported as detections left out (``outliers_left_out``); a flight no block repairs still fails."""
    if not cfg.refit:
        return fit
    for k in _bad_flights(fit):
        ch = fit.problem.chain
        f = ch.flights[k]
        if f.end is None:
            continue
        first, last = int(ch.contacts[f.start].frame), int(ch.contacts[f.end].frame)
        window = _window(fit, k)
        warm = _remember(ch, fit.sol.theta)
        for block in _blocks(_detection_runs(obs, first, last), cfg)[:cfg.max_hypotheses]:
            note = (int(block[0]), f"{len(block)} detections (frames {block[0]}–{block[-1]}) off the flight "
                                   f"{first}–{last} left out")
            plan = replace(fit.plan, notes=[*fit.plan.notes, note],
                           left_out=tuple(sorted({*fit.plan.left_out, *map(int, block)})))
            sub = _local_plan(plan, window)
            loc = _fit_with_ends(obs, sub, replace(cfg, free_ends=False), model, hit_prior, warm=warm,
                                 span=(sub.contacts[0].prior.frame, sub.contacts[-1].prior.frame)) if sub else None
            if loc is None or isinstance(loc, str) or not _passes_without(loc, first, last, block, cfg):
                continue
            cand = _fit_with_ends(obs, plan, cfg, model, hit_prior, warm=warm)
            if isinstance(cand, str) or not _passes_without(cand, first, last, block, cfg):
                continue
            n, cost = unexplained(cand, span)
            if _n_failing(cand) < _n_failing(fit) and _improves(n, cost, _n_failing(cand),
                                                                 (*unexplained(fit, span), _n_failing(fit)),
                                                                 _tolerance(obs, span)):
                fit = cand
                break
    return fit


def _passes_without(fit: ChainFit, first: int, last: int, block: np.ndarray, cfg: JointConfig) -> bool:
    """Whether the chain flight of ``fit`` from contact frame ``first`` to ``last`` passes its checks with every
    detection of ``block`` (frames) beyond ``outlier_k`` σ of it."""
    pb = fit.problem
    ch = pb.chain
    k = next((i for i, f in enumerate(ch.flights) if f.end is not None
              and int(ch.contacts[f.start].frame) == first and int(ch.contacts[f.end].frame) == last), None)
    if k is None or not fit.checks[k].ok:
        return False
    at = np.isin(pb.frames, block)
    return bool(at.any() and np.all(pb.last_norm[at] > cfg.outlier_k))


def keeps_flight(failing: np.ndarray) -> bool:
    """Whether a reported flight whose frames ``(n,)`` are flagged where a failing chain flight owns them is
    kept without those frames: a failing neighbour that reaches a few frames into it (its contact fitted off
    the event's frame) costs those frames only; the flight fails when they are most of it or leave < 2."""
    failing = np.asarray(failing, bool)
    return not failing.any() or (failing.mean() <= 0.5 and int((~failing).sum()) >= 2)


def _segment_fits(obs: Observations, segs: list[Segment], fit: ChainFit, cfg: JointConfig
                  ) -> tuple[list[SegmentFit], FrameErrorModel | None]:
    """The reported flights from the fitted chain (frames, positions, covariances, contacts, checks), and the
    chain's per-frame error model."""
    pb, sol = fit.problem, fit.sol
    ch = pb.chain
    em = frame_error_model(pb, sol, cfg.sigma_inflation, cfg.sigma_floor_m,
                           cfg.uncertainty or Uncertainty.from_court(obs.court))
    if em is None:
        fl, taus = sol.aux["flights"], sol.aux["taus"]
        frames, own, j = pb.frame_positions(fl, taus)
        xyz, cov = fl.P[own, 0, j], np.full((len(frames), 3, 3), np.nan)
    else:
        frames, xyz, own, cov = em.frames, em.xyz, em.own, em.covariances()
    theta = sol.theta
    checks = fit.checks
    by_event = {c.event: k for k, c in enumerate(fit.plan.contacts) if c.event is not None}
    E = len(obs.event_frames)
    out = []
    for seg in segs:
        if seg.index == -1:
            lo, hi = ch.first_frame, seg.end
        elif seg.index == E - 1:
            lo, hi = seg.start, ch.last_frame
        else:
            lo, hi = seg.start, seg.end
        m = (frames >= lo) & (frames <= hi)
        if not m.any() or (seg.index in (-1, E - 1) and m.sum() < 2):
            out.append(SegmentFit.failed(seg, _free_end_reason(obs, seg) if seg.index in (-1, E - 1)
                                         else "outside the fitted rally"))
            continue
        failing = np.array([not checks[s].ok for s in own[m]])
        why = checks[int(own[m][failing][0])].reason if failing.any() else ""
        if not keeps_flight(failing):
            seg_frames = frames[m]
            seg = replace(seg, start=int(seg_frames[0]), end=int(seg_frames[-1]))
            out.append(SegmentFit.failed(seg, why))
            continue
        dropped = frames[m][failing]
        m[np.flatnonzero(m)[failing]] = False
        seg_frames = frames[m]
        seg = replace(seg, start=int(seg_frames[0]), end=int(seg_frames[-1]))
        sig = np.sqrt(np.maximum(np.trace(cov[m], axis1=1, axis2=2), 0.0))
        if np.nanmedian(sig) > cfg.max_sigma_m:
            out.append(SegmentFit.failed(seg, f"too uncertain: median σ {np.nanmedian(sig):.1f} m (the track does "
                                              "not pin the depth)"))
            continue
        seen = np.isfinite(obs.uv[seg_frames]).all(axis=1)
        left_out = np.isin(seg_frames, pb.frames[pb.outliers]) & seen  # detections the fit left out (short runs)
        seen &= ~left_out
        err = np.linalg.norm(obs.camera.project(xyz[m][seen]) - obs.uv[seg_frames[seen]], axis=1)
        short = _too_short(seg_frames, int(seen.sum()), hi - lo + 1 if 0 <= seg.index < E - 1 else 0)
        if short:
            out.append(SegmentFit.failed(seg, short))
            continue
        rms = float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")
        if rms > cfg.rms_fail_factor * cfg.pixel_sigma:  # never written as reconstructed, whatever the chain said
            out.append(SegmentFit.failed(seg, f"reprojection RMS {rms:.1f} px over its frames > "
                                              f"{cfg.rms_fail_factor:g} × the 2D noise ({cfg.pixel_sigma:.2g} px)"))
            continue
        a = by_event.get(seg.index) if seg.index >= 0 else None
        b = by_event.get(seg.index + 1) if seg.index + 1 < E else None

        def contact_point(k, frame):
            return ch.point(theta, k) if k is not None else xyz[m][np.argmin(np.abs(seg_frames - frame))]

        def plane_name(k):
            return ch.contacts[k].plane.name if k is not None and ch.contacts[k].plane is not None else None

        start_flight = next((f for f in ch.flights if a is not None and f.start == a and not f.lead_in), None)
        if start_flight is None:
            start_flight = ch.flights[int(own[m][0])]
        flags = [f"{ch.contacts[k].label} at frame {ch.contacts[k].frame}: beyond the surface's extent "
                 "(fitted on the unbounded plane)" for k in (a, b) if k is not None and ch.contacts[k].prior.outside]
        notes = [c.note for c in fit.plan.contacts if c.note and lo <= c.prior.frame <= hi]
        sf = SegmentFit(
            seg, True, frames=seg_frames, xyz=xyz[m], sigma=sig, cov=cov[m],
            start=contact_point(a, seg.start) if seg.start_event is not None else None,
            end=contact_point(b, seg.end) if seg.end_event is not None else None,
            start_plane=plane_name(a), end_plane=plane_name(b),
            velocity=theta[start_flight.vel].copy(),
            spin=theta[start_flight.spin].copy() if start_flight.spin is not None else np.zeros(3),
            drag_k=pb.model.drag_k * (theta[start_flight.drag] if start_flight.drag is not None else 1.0),
            reproj_rms_px=rms, n_observed=int(seen.sum()))
        if em is not None:
            k_main = int(np.bincount(own[m]).argmax())                  # the chain flight with most of its frames
            ratios = em.depth_cues.get(k_main, {})
            sf.figures["depth_from"] = depth_report(ratios)
            sf.figures["depth_cues"] = {g: (round(r, 2) if np.isfinite(r) else None) for g, r in ratios.items()}
        if flags:
            sf.figures["flags"] = flags
        if notes:
            sf.figures["refit"] = notes
        if left_out.any():
            off = np.linalg.norm(obs.camera.project(xyz[m][left_out]) - obs.uv[seg_frames[left_out]], axis=1)
            fr = seg_frames[left_out]
            sf.figures["outliers_left_out"] = (f"{len(fr)} detection{'s' if len(fr) > 1 else ''} (frames {fr[0]}–{fr[-1]}) "
                                               f"up to {off.max():.0f} px off the flight, left out")
        if len(dropped):
            span = f"frame {dropped[0]}" if len(dropped) == 1 else f"{len(dropped)} frames ({dropped[0]}–{dropped[-1]})"
            sf.figures["dropped_frames"] = f"{span} of a failing neighbour left out ({why})"
        out.append(sf)
    return out, em


def _too_short(frames: np.ndarray, n_seen: int, span: int) -> str:
    """Why a reported flight covering ``frames`` (with ``n_seen`` 2D points) is too little to report ("" when
    it is not): fewer than 2 frames (a zero-length flight), or, for a flight between two events ``span``
    frames apart, a fit covering less than half of it with fewer than 2 points (the rest cut off by a refit)."""
    if len(frames) < 2:
        return f"covers {len(frames)} frame{'' if len(frames) == 1 else 's'} only (nothing to reconstruct)"
    if n_seen < 2 and span and len(frames) < 0.5 * span:
        return f"the fit covers frames {frames[0]}–{frames[-1]} only, with {n_seen} 2D point(s)"
    return ""


def is_hit(label: str | None) -> bool:
    return label in PLAYER_EVENTS
