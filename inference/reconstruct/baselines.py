"""Four published single-segment baselines: each fits one flight between two consecutive events.

1. :func:`fit_gravity` — both end points from the contact priors, the vacuum parabola through them.
2. :func:`fit_drag_shooting` — the same end points; the launch velocity whose drag flight (court YAML
   ball constants) reaches the end point at the end frame, by shooting (SLSQP from the parabola).
3. :func:`fit_reprojection` — minimises the squared reprojection errors of the drag flight at the
   segment's observed frames (SLSQP) over the launch velocity and, for a racket-hit start, the start
   point's depth along its line of sight, with its height within ``court.hits.height``. A surface start is
   fixed where its line of sight meets the surface (the contact prior; letting it slide along the line of
   sight was no better on synthetic rallies). A racket-hit end keeps the same height limits (inequality
   constraints); a flight that ends on a surface ends on that surface's plane (equality constraint).
   Initialised from method 2 (method 1 if that fails).
4. :func:`fit_players` — as 3, and a racket-hit point is also within ``court.hits.offset_y`` (along y)
   and ``court.hits.reach`` (horizontally) of the hitter's court position from players.csv. A hit without a
   hitter position is fitted as in method 3 (:func:`fit_rally` notes it in ``RallyFit.extra["notes"]``).

Segment times are ``(f - seg.start)/fps`` for the frames ``seg.frames``; no fit uses spin. Every failure
returns ``SegmentFit.failed(seg, reason)``; the fits never raise.

The optimising methods get their gradients from central finite differences computed in one batched flight
(:func:`inference.reconstruct.flight.sample_flight` costs the same for 1 or 9 balls), and work in
variables scaled by the initial Jacobian's column norms so that SLSQP's first quasi-Newton steps are
well scaled.

Example:
    >>> fit = fit_rally(Observations.from_clip(clip), "reprojection")
    >>> [s.reproj_rms_px for s in fit.segments if s.ok]
"""
from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from inference.physics import FlightModel

from .flight import gravity_launch_velocity, sample_flight, vacuum_positions
from .observations import ContactPrior, Observations, Segment, contact_priors
from .results import RallyFit, SegmentFit

#: Start depths beyond these distances from the camera (m) are not considered.
DEPTH_RANGE = (0.3, 300.0)
#: Bound on each launch velocity component (m/s).
MAX_SPEED = 100.0
#: A drag-shooting solution must reach the end point within this distance (m).
SHOOTING_TOL = 0.01
#: A constrained optimum may violate its constraints by this much (m, or m² for the reach).
CONSTRAINT_TOL = 0.01
#: Fewest observed frames the reprojection methods need (methods 1 and 2 need one: a segment without any
#: 2D ball has contact points from other frames only).
MIN_OBSERVED = 3
#: RK4 steps per frame inside the optimisers. A drag flight sampled with 2 steps per frame differs from
#: the default ``ceil(600/fps)`` by < 1e-7 m (40 m/s over 1.3 s at 30 fps), at a tenth of the cost; the
#: reported flight is always re-sampled with the default.
SEARCH_SUBSTEPS = 2


FitFn = Callable[[Observations, list[ContactPrior], Segment], SegmentFit]


def _never_raises(fit: FitFn) -> FitFn:
    """Turn an unexpected exception of a segment fit into a failed fit naming it."""

    @functools.wraps(fit)
    def wrapper(obs: Observations, priors: list[ContactPrior], seg: Segment) -> SegmentFit:
        try:
            return fit(obs, priors, seg)
        except Exception as e:  # a fit reports, it never raises
            return SegmentFit.failed(seg, f"internal error in {fit.__name__}: {type(e).__name__}: {e}")

    return wrapper


# ----------------------------------------------------------------------------------- shared pieces
@dataclass(frozen=True)
class _Problem:
    """One segment's data as the fits use it.

    Attributes:
        obs, seg: the rally and the flight.
        start, end: the contact priors at the segment's two events.
        model: the drag flight model (court YAML ball constants, no spin).
        observed: (M,) indices into ``seg.frames`` of frames with a finite 2D ball; uv: (M, 2) those pixels.
    """

    obs: Observations
    seg: Segment
    start: ContactPrior
    end: ContactPrior
    model: FlightModel
    observed: np.ndarray
    uv: np.ndarray

    @classmethod
    def build(cls, obs: Observations, priors: list[ContactPrior], seg: Segment) -> _Problem:
        frames = seg.frames
        inside = frames < obs.n_frames
        uv = np.full((len(frames), 2), np.nan)
        uv[inside] = obs.uv[frames[inside]]
        observed = np.flatnonzero(np.isfinite(uv).all(axis=1))
        model = FlightModel.from_ball(obs.court.ball, lift_k=0.0)
        return cls(obs, seg, priors[seg.index], priors[seg.index + 1], model, observed, uv[observed])

    @property
    def n(self) -> int:
        """Frame intervals of the flight."""
        return self.seg.duration_frames

    @property
    def duration(self) -> float:
        return self.n / self.obs.fps

    @property
    def times(self) -> np.ndarray:
        """(n + 1,) seconds since the start event."""
        return (self.seg.frames - self.seg.start) / self.obs.fps

    def observation_reason(self, need: int) -> str:
        """Why the segment has too few observed 2D ball positions ("" when it has ``need``)."""
        if len(self.observed) >= need:
            return ""
        m, seg = len(self.observed), self.seg
        return f"only {m} observed 2D ball positions in frames {seg.start}-{seg.end} (need {need})"

    def contact_reason(self) -> str:
        """Why the contact priors cannot give both end points ("" when they can)."""
        for role, p in (("start", self.start), ("end", self.end)):
            if not p.ok:
                return f"{role} contact (frame {p.frame}, {p.label}): {p.reason or 'no 3D point'}"
        return ""

    def flights(self, p0: np.ndarray, v0: np.ndarray, search: bool = False) -> np.ndarray:
        """(B, 3) launch states → (B, n + 1, 3) drag flights at the segment's frames (with
        :data:`SEARCH_SUBSTEPS` inside an optimiser, ``search=True``)."""
        k = SEARCH_SUBSTEPS if search else None
        return sample_flight(p0, v0, None, self.n, self.obs.fps, self.model, substeps=k)

    def fit(self, xyz: np.ndarray, velocity: np.ndarray, drag_k: float) -> SegmentFit:
        """A successful :class:`SegmentFit` from the (n + 1, 3) flight (a failed one if it is not finite)."""
        if not np.all(np.isfinite(xyz)) or not np.all(np.isfinite(velocity)):
            return SegmentFit.failed(self.seg, "the fitted flight is not finite")
        rms = float("nan")
        if len(self.observed):
            err = np.linalg.norm(self.obs.camera.project(xyz[self.observed]) - self.uv, axis=1)
            rms = float(np.sqrt(np.mean(err**2))) if np.all(np.isfinite(err)) else float("inf")
        return SegmentFit(
            self.seg, True, frames=self.seg.frames.copy(), xyz=xyz, start=xyz[0].copy(), end=xyz[-1].copy(),
            start_plane=_plane_name(self.start), end_plane=_plane_name(self.end),
            velocity=np.asarray(velocity, float), spin=np.zeros(3), drag_k=float(drag_k), reproj_rms_px=rms,
            n_observed=len(self.observed), sigma=None)


def _plane_name(prior: ContactPrior) -> str | None:
    return prior.plane.name if prior.kind == "plane" and prior.plane is not None else None


def _central_jacobian(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Value and Jacobian of a batched function by central differences in one call.

    Args:
        fn: (B, n) parameter vectors → (B, m) outputs.
        x: (n,) where to evaluate.
    Returns:
        (m,) value, (m, n) Jacobian.
    """
    n = len(x)
    h = 1e-5 * np.maximum(1.0, np.abs(x))
    X = np.repeat(x[None], 2 * n + 1, axis=0)
    X[1 : n + 1] += np.diag(h)
    X[n + 1 :] -= np.diag(h)
    Y = fn(X)
    return Y[0], ((Y[1 : n + 1] - Y[n + 1 :]) / (2 * h[:, None])).T


@dataclass
class _Constraint:
    """A constraint on the flight's end position e: ``g(e) = 0`` (eq) or ``g(e) >= 0`` (ineq).

    Attributes:
        kind: ``eq`` or ``ineq``; g: (3,) e → (k,) values; dg: (3,) e → (k, 3) their derivative.
        what: for messages.
    """

    kind: str
    g: Callable[[np.ndarray], np.ndarray]
    dg: Callable[[np.ndarray], np.ndarray]
    what: str

    def violation(self, e: np.ndarray) -> float:
        v = self.g(e)
        return float(np.max(np.abs(v)) if self.kind == "eq" else max(0.0, -float(np.min(v))))


@dataclass
class _LeastSquares:
    """``½ |r(x)|²`` subject to constraints on the flight's end position, solved by SLSQP.

    ``model(X)`` maps (B, n) parameters to (B, m + 3): m residuals, then the flight's end position; values
    and Jacobians come from :func:`_central_jacobian`, kept for the last x (SLSQP asks for the loss, its
    gradient and the constraints at the same x). The optimiser runs in scaled variables ``y = x / scale``
    with ``scale`` the inverse column norms of the residual Jacobian at x0.
    """

    model: Callable[[np.ndarray], np.ndarray]
    constraints: list[_Constraint] = field(default_factory=list)
    _last: tuple = (None, None)

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(m,) residuals, (m, n) their Jacobian, (3,) end position, (3, n) its Jacobian (non-finite values,
        e.g. a flight behind the camera, become large finite ones)."""
        key = x.tobytes()
        if self._last[0] != key:
            y, J = _central_jacobian(self.model, x)
            y, J = np.nan_to_num(y, nan=1e6, posinf=1e6, neginf=-1e6), np.nan_to_num(J)
            self._last = (key, (y[:-3], J[:-3], y[-3:], J[-3:]))
        return self._last[1]

    def solve(self, x0: np.ndarray, bounds: list[tuple[float, float]], ftol: float,
              maxiter: int = 60) -> tuple[np.ndarray, str]:
        """Minimise from x0 within ``bounds`` (one (lo, hi) per parameter) until the loss changes by less
        than ``ftol`` (in its units) per iteration.

        Returns:
            (n,) the solution and "" if it is acceptable, else the best x and why it is not.
        """
        x0 = np.asarray(x0, dtype=float)
        r0, J0, _, _ = self.evaluate(x0)
        norms = np.linalg.norm(J0, axis=0)
        scale = np.where(norms > 1e-12, 1.0 / np.maximum(norms, 1e-12), 1.0)

        def unscale(y):
            return y * scale

        def fun(y):
            r = self.evaluate(unscale(y))[0]
            return 0.5 * float(r @ r)

        def jac(y):
            r, J, _, _ = self.evaluate(unscale(y))
            return (J.T @ r) * scale

        def constraint(c: _Constraint) -> dict:
            def g(y):
                return c.g(self.evaluate(unscale(y))[2])

            def dg(y):
                _, _, e, Je = self.evaluate(unscale(y))
                return c.dg(e) @ Je * scale

            return {"type": c.kind, "fun": g, "jac": dg}

        ybounds = [(lo / s, hi / s) for (lo, hi), s in zip(bounds, scale)]
        y0 = np.clip(x0 / scale, [b[0] for b in ybounds], [b[1] for b in ybounds])
        cons = [constraint(c) for c in self.constraints]
        res = minimize(fun, y0, jac=jac, bounds=ybounds, constraints=cons, method="SLSQP",
                       options={"maxiter": maxiter, "ftol": ftol})
        x = unscale(np.asarray(res.x, dtype=float))
        return x, self._verdict(x, res, 0.5 * float(r0 @ r0))

    def _verdict(self, x: np.ndarray, res, f0: float) -> str:
        """Why the optimum is not acceptable ("" when it is): non-finite, constraints violated, or a
        failed optimisation that did not even improve on the start."""
        if not np.all(np.isfinite(x)):
            return f"SLSQP diverged ({res.message})"
        r, _, e, _ = self.evaluate(x)
        for c in self.constraints:
            if c.violation(e) > CONSTRAINT_TOL:
                return f"SLSQP could not satisfy {c.what} (off by {c.violation(e):.3g}; {res.message})"
        if not res.success and 0.5 * float(r @ r) > f0:
            return f"SLSQP failed ({res.message})"
        return ""


def _interval(a: float, b: float, lo: float, hi: float) -> tuple[float, float]:
    """The s with ``lo <= a + b s <= hi`` as (s_lo, s_hi); (inf, -inf) when empty, (-inf, inf) when all."""
    if abs(b) < 1e-12:
        return (-np.inf, np.inf) if lo <= a <= hi else (np.inf, -np.inf)
    s1, s2 = (lo - a) / b, (hi - a) / b
    return (min(s1, s2), max(s1, s2))


def _disc_interval(o: np.ndarray, d: np.ndarray, centre: np.ndarray, radius: float) -> tuple[float, float]:
    """The s with ``|o + s d - centre| <= radius`` (2D) as (s_lo, s_hi); (inf, -inf) when empty."""
    a = float(d @ d)
    w = o - centre
    b, c = 2.0 * float(d @ w), float(w @ w) - radius**2
    if a < 1e-12:
        return (-np.inf, np.inf) if c <= 0 else (np.inf, -np.inf)
    disc = b * b - 4 * a * c
    if disc < 0:
        return (np.inf, -np.inf)
    q = np.sqrt(disc)
    return ((-b - q) / (2 * a), (-b + q) / (2 * a))


def _intersect(*intervals: tuple[float, float]) -> tuple[float, float]:
    return max(i[0] for i in intervals), min(i[1] for i in intervals)


# ------------------------------------------------------------------------------------ methods 1, 2
@_never_raises
def fit_gravity(obs: Observations, priors: list[ContactPrior], seg: Segment) -> SegmentFit:
    """Method 1: the vacuum parabola from the start contact's point to the end contact's point."""
    pb = _Problem.build(obs, priors, seg)
    if reason := pb.observation_reason(1) or pb.contact_reason():
        return SegmentFit.failed(seg, reason)
    g = pb.model.gravity
    v0 = gravity_launch_velocity(pb.start.point, pb.end.point, pb.duration, g)
    return pb.fit(vacuum_positions(pb.start.point, v0, pb.times, g), v0, drag_k=0.0)


def shoot_velocity(pb: _Problem, p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, str]:
    """The launch velocity of the drag flight from ``p0`` that is at ``p1`` after the segment's duration.

    SLSQP on ``½ |p(T; v) - p1|²`` from the vacuum parabola's velocity. Returns (3,) v and "" on success,
    else the best v and the reason.
    """
    T = pb.duration

    def end_miss(V: np.ndarray) -> np.ndarray:
        end = pb.flights(np.broadcast_to(p0, V.shape), V, search=True)[:, -1]
        return np.hstack([end - p1, end])

    v_init = gravity_launch_velocity(p0, p1, T, pb.model.gravity)
    problem = _LeastSquares(end_miss)
    v, why = problem.solve(v_init, [(-MAX_SPEED, MAX_SPEED)] * 3, ftol=1e-10)
    miss = float(np.linalg.norm(problem.evaluate(v)[0]))
    if not why and miss > SHOOTING_TOL:
        why = f"drag shooting missed the end contact by {miss:.3f} m"
    return v, why


@_never_raises
def fit_drag_shooting(obs: Observations, priors: list[ContactPrior], seg: Segment) -> SegmentFit:
    """Method 2: the drag flight from the start contact's point that reaches the end contact's point."""
    pb = _Problem.build(obs, priors, seg)
    if reason := pb.observation_reason(1) or pb.contact_reason():
        return SegmentFit.failed(seg, reason)
    v0, why = shoot_velocity(pb, pb.start.point, pb.end.point)
    if why:
        return SegmentFit.failed(seg, why)
    return pb.fit(pb.flights(pb.start.point[None], v0[None])[0], v0, drag_k=pb.model.drag_k)


# ------------------------------------------------------------------------------------ methods 3, 4
@dataclass(frozen=True)
class _Launch:
    """The unknowns x of methods 3 and 4 and the launch state they stand for.

    A racket-hit start lies on its line of sight ``origin + s d`` (camera centre through the prior point)
    with its depth s in [lo, hi]: x = [s, vx, vy, vz]. A surface start is fixed where that line of sight
    meets the surface (the contact prior's point, ``d`` None): x = [vx, vy, vz].
    """

    point: np.ndarray
    origin: np.ndarray | None = None
    d: np.ndarray | None = None
    lo: float = 0.0
    hi: float = 0.0

    def start_points(self, X: np.ndarray) -> np.ndarray:
        """(B, n) parameters → (B, 3) start points."""
        if self.d is None:
            return np.broadcast_to(self.point, (len(X), 3))
        return self.origin + X[:, :1] * self.d

    @staticmethod
    def velocities(X: np.ndarray) -> np.ndarray:
        """(B, n) parameters → (B, 3) launch velocities."""
        return X[:, -3:]

    def x0(self, v0: np.ndarray) -> np.ndarray:
        """(n,) parameters of the allowed start point nearest the prior, launched at ``v0``."""
        if self.d is None:
            return np.asarray(v0, dtype=float)
        return np.r_[np.clip(self.d @ (self.point - self.origin), self.lo, self.hi), v0]

    def start0(self) -> np.ndarray:
        """(3,) the start point of :meth:`x0`."""
        return self.start_points(self.x0(np.zeros(3))[None])[0]

    def bounds(self) -> list[tuple[float, float]]:
        """(lo, hi) per parameter."""
        speed = [(-MAX_SPEED, MAX_SPEED)] * 3
        return speed if self.d is None else [(self.lo, self.hi), *speed]


def _hit_intervals(obs: Observations, o: np.ndarray, d: np.ndarray, prior: ContactPrior,
                   use_hitter: bool) -> list[tuple[float, float]]:
    """Depth intervals along ``o + s d`` that satisfy the court's hit limits (and the hitter's, if used)."""
    lim = obs.court.hits
    out = [_interval(o[2], d[2], *lim.height)]
    if use_hitter and prior.hitter_xy is not None:
        h = np.asarray(prior.hitter_xy, dtype=float)
        out.append(_interval(o[1] - h[1], d[1], *lim.offset_y))
        out.append(_disc_interval(o[:2], d[:2], h, lim.reach))
    return out


def _launch(pb: _Problem, use_hitter: bool) -> tuple[_Launch | None, str]:
    """The launch parametrisation of the segment's start contact, or None and why there is none."""
    p = pb.start
    if p.kind == "plane":
        return _Launch(p.point.copy()), ""
    o = pb.obs.camera.centre
    d = (p.point - o) / np.linalg.norm(p.point - o)
    lo, hi = _intersect(DEPTH_RANGE, *_hit_intervals(pb.obs, o, d, p, use_hitter))
    if not lo < hi:
        whose = "the court's and the hitter's" if use_hitter and p.hitter_xy is not None else "the court's"
        return None, (f"the line of sight at the start hit (frame {p.frame}, {p.label}) has no point within "
                      f"{whose} hit limits")
    return _Launch(p.point.copy(), o, d, lo, hi), ""


def _end_constraints(pb: _Problem, use_hitter: bool) -> list[_Constraint]:
    """The end contact's constraints on the flight's end: on its plane, or within the hit limits."""
    p = pb.end
    if p.kind == "plane":
        n, q = p.plane.normal, p.point.copy()
        return [_Constraint("eq", lambda e: np.array([n @ (e - q)]), lambda e: n[None],
                            f"the end on {p.plane.name}")]
    lo, hi = pb.obs.court.hits.height
    out = [_Constraint("ineq", lambda e: np.array([e[2] - lo, hi - e[2]]),
                       lambda e: np.array([[0.0, 0, 1], [0, 0, -1]]), "the end hit's height")]
    if use_hitter and p.hitter_xy is not None:
        h = np.asarray(p.hitter_xy, dtype=float)
        (olo, ohi), reach = pb.obs.court.hits.offset_y, pb.obs.court.hits.reach

        def g(e):
            dxy = e[:2] - h
            return np.array([dxy[1] - olo, ohi - dxy[1], reach**2 - dxy @ dxy])

        def dg(e):
            dxy = e[:2] - h
            return np.array([[0.0, 1, 0], [0, -1, 0], [-2 * dxy[0], -2 * dxy[1], 0]])

        out.append(_Constraint("ineq", g, dg, "the end hit's distance to the hitter"))
    return out


def _fit_reprojection(obs: Observations, priors: list[ContactPrior], seg: Segment,
                      use_hitter: bool) -> SegmentFit:
    """Methods 3 and 4: depth of the start along its line of sight and launch velocity, by SLSQP on the
    reprojection errors with the contact constraints."""
    pb = _Problem.build(obs, priors, seg)
    if reason := pb.observation_reason(MIN_OBSERVED) or pb.contact_reason():
        return SegmentFit.failed(seg, reason)
    launch, why = _launch(pb, use_hitter)
    if launch is None:
        return SegmentFit.failed(seg, why)
    p0 = launch.start0()
    v0, why = shoot_velocity(pb, p0, pb.end.point)
    if why:
        v0 = gravity_launch_velocity(p0, pb.end.point, pb.duration, pb.model.gravity)
    sigma = np.sqrt(len(pb.observed))
    project = pb.obs.camera.project

    def model(X: np.ndarray) -> np.ndarray:
        xyz = pb.flights(launch.start_points(X), launch.velocities(X), search=True)
        px = project(xyz[:, pb.observed].reshape(-1, 3)).reshape(len(X), -1, 2)
        return np.hstack([((px - pb.uv) / sigma).reshape(len(X), -1), xyz[:, -1]])

    problem = _LeastSquares(model, _end_constraints(pb, use_hitter))
    x, why = problem.solve(launch.x0(v0), launch.bounds(), ftol=1e-6)
    if why:
        return SegmentFit.failed(seg, why)
    X = x[None]
    return pb.fit(pb.flights(launch.start_points(X), launch.velocities(X))[0], x[-3:], drag_k=pb.model.drag_k)


@_never_raises
def fit_reprojection(obs: Observations, priors: list[ContactPrior], seg: Segment) -> SegmentFit:
    """Method 3: the drag flight that best reprojects onto the segment's 2D ball positions."""
    return _fit_reprojection(obs, priors, seg, use_hitter=False)


@_never_raises
def fit_players(obs: Observations, priors: list[ContactPrior], seg: Segment) -> SegmentFit:
    """Method 4: as method 3, with racket-hit points also near the hitter's court position."""
    return _fit_reprojection(obs, priors, seg, use_hitter=True)


# ------------------------------------------------------------------------------------------ rally
BASELINES: dict[str, FitFn] = {
    "gravity": fit_gravity,
    "drag_shooting": fit_drag_shooting,
    "reprojection": fit_reprojection,
    "players": fit_players,
}


def _hitter_notes(priors: list[ContactPrior], segments: list[Segment]) -> list[str]:
    """Segments whose racket-hit contacts had no hitter position (fitted without the player constraint)."""
    notes = []
    for seg in segments:
        ends = (priors[seg.index], priors[seg.index + 1])
        missing = [p for p in ends if p.kind == "hit" and p.hitter_xy is None]
        if missing:
            frames = " and ".join(str(p.frame) for p in missing)
            notes.append(f"segment {seg.index}: no hitter position for the hit at frame {frames} "
                         "(no players.csv row of that team); fitted without the player constraint")
    return notes


def fit_rally(obs: Observations, method: str) -> RallyFit:
    """Run one baseline over every segment of the rally (contact priors computed once)."""
    if method not in BASELINES:
        raise ValueError(f"unknown baseline {method!r}; choose one of {sorted(BASELINES)}")
    fit = BASELINES[method]
    t0 = time.perf_counter()
    priors = contact_priors(obs, unbounded_ok=False)  # the published methods as published
    segments = obs.segments()
    fits = [fit(obs, priors, seg) for seg in segments]
    extra = {}
    if method == "players":
        extra["notes"] = _hitter_notes(priors, segments)
    return RallyFit(method, obs.fps, fits, seconds=time.perf_counter() - t0, extra=extra)
