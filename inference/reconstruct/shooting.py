"""Multiple shooting over a chain of flights: the layout of the unknowns, the batched flights, the residuals
with a sparse Jacobian, Levenberg-Marquardt and the per-frame covariance. :mod:`.joint` builds chains and
decides what to fit; this module only fits one.

A chain is a run of contacts ``0..K-1`` (floor/wall/net contacts on their surface, racket hits as free 3D
points near their hitter) and the flights between them, optionally with a *lead-in* (the flight arriving at
contact 0, integrated backwards from it over the frames before it) and a *run-out* (the flight leaving the
last contact, up to the last frames of the track). Unknowns θ: each contact's sub-frame time τ and point,
each flight's velocity and spin at its contact (the lead-in's: arriving), optionally a drag multiplier.

Residuals (each divided by its σ):

* reprojection of every observed frame from the flight that owns it (Huber weights, reweighted),
* continuity: a flight ends at the next contact at its τ,
* bounce: at a floor/glass contact the outgoing velocity and spin follow the rigid-ball impact model
  (:func:`inference.physics.bounce`: the material's restitution and friction) from the incoming ones, so the
  frames after a bounce constrain the flight before it,
* the court: no frame below the floor or through a wall or glass (hinge on penetration), the net cleared
  unless a net event says otherwise,
* racket hits: a Student-t pull towards the hitter's court position (tighter along the court's length than
  across), within the court's hit-height range, near the hand height when poses give it,
* weak priors: τ near its event frame, spin towards 0, drag multiplier towards 1.

Jacobian by forward differences of the flights' 11 inputs, all flights and perturbations integrated in one
vectorised batch (RK4 steps spanning several frames at 30+ fps, Hermite between), assembled as a sparse
matrix (each row touches at most a few dozen unknowns) only for accepted LM trials; the trials of an LM
iteration are integrated together; the normal equations are small and solved densely.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from inference.court import Court, Material, Plane
from inference.physics import FlightModel, bounce, rk4_path, rk4_step, spin_factors

from .observations import ContactPrior, Observations

N_IN = 11  # flight inputs: C (3), v (3), ω (3), τ (1), drag scale (1)
EPS = np.array([1e-4] * 3 + [1e-4] * 3 + [1e-2] * 3 + [1e-4] + [1e-3])
#: materials whose rebound follows the impact model (net and mesh rebounds are irregular: left free)
BOUNCE_MATERIALS = ("floor", "glass", "table")


@dataclass(frozen=True)
class HitPrior:
    """The joint method's pull of a racket hit towards its hitter (court YAML ``hits.prior``).

    Attributes:
        forward: mean offset (m) of the hit point from the hitter's court position towards the net.
        sigma_forward, sigma_lateral: spreads along the court's length and across it (m).
        dof: Student-t degrees of freedom (small = heavy tails: a wrong hitter position costs little).
        height, sigma_height: typical hit height and spread (m), used when no hand height is known.
        hand_sigma: spread (m) of the hit height around the hand (wrist) height from a pose.
        raised_above_hand: height (m) of the hit above a hand raised over the shoulders (a serve, a smash:
            the racket points up), about the wrist-to-sweet-spot length.
        raised_forward: ``forward`` for such a hit (None: ``forward``): a serve's or a smash's ball is met
            in front of the body, not beside it.
        reach: hard limit (m) on the horizontal distance from the hitter.
    """

    forward: float = 0.2
    sigma_forward: float = 0.35
    sigma_lateral: float = 0.7
    dof: float = 4.0
    height: float = 1.1
    sigma_height: float = 0.7
    hand_sigma: float = 0.45
    raised_above_hand: float = 0.0
    raised_forward: float | None = None
    reach: float = 1.6

    @classmethod
    def from_court(cls, court: Court) -> HitPrior:
        extra = {k: float(v) for k, v in (court.extra.get("hit_prior") or {}).items()}
        unknown = sorted(set(extra) - {f for f in cls.__dataclass_fields__ if f != "reach"})
        if unknown:
            raise ValueError(f"{court.source}: unknown hit_prior keys {unknown}")
        return cls(**extra, reach=court.hits.reach)


@dataclass(frozen=True)
class Uncertainty:
    """How the joint method's per-frame covariance is calibrated (court YAML ``uncertainty``).

    covariance = ``scale``² × S (the Gauss-Newton covariance) S + (``model_m_per_s`` × t)² along the line of
    sight + ``floor_m``² I, with S = I + (``along_scale`` − 1) r rᵀ (r the unit line of sight: the Gauss-Newton
    part's width along the ray scaled apart from across it) and t the time (s) from the frame to the nearest
    contact; on a free end (the lead-in
    before the first contact, the run-out after the last: one end pinned, not two) the along-ray term grows
    by ``free_end_m_per_s`` instead (None: ``model_m_per_s``). A flight whose reprojection residuals say the
    model is off (mean squared normalised residual χ² > 1) has its covariance (both parts) multiplied by
    χ²^``residual_power``. The Gauss-Newton part holds
    the 2D noise, the contact times and the priors as the fit states them; ``scale`` corrects their stated
    widths, the along-ray term stands for what the flight model leaves out (drag, spin, the bounce), which the
    2D track cannot see across the line of sight; ``along_scale`` corrects the Gauss-Newton width along the
    ray apart from across it (on simulated rallies it states the depth 1.1–1.3× wider, relative to across,
    than the errors are). Fitted per sport on synthetic clips of seeds that
    the accuracy benchmark never uses, by the coverage of the 1-σ / 2-σ ellipsoids and along / across the ray
    (``bench/bench_joint.py --calibrate``).
    """

    scale: float = 1.0
    model_m_per_s: float = 0.0
    floor_m: float = 0.003
    free_end_m_per_s: float | None = None
    residual_power: float = 0.0
    along_scale: float = 1.0

    def shape(self, ray: np.ndarray) -> np.ndarray:
        """(M, 3, 3) S = I + (``along_scale`` − 1) r rᵀ per unit line of sight ``ray`` (M, 3)."""
        return np.eye(3)[None] + (self.along_scale - 1.0) * np.einsum("mi,mj->mij", ray, ray)

    def flight_factor(self, chi2: np.ndarray) -> np.ndarray:
        """Covariance factor per flight from its mean squared normalised residual (NaN: no 2D points → 1)."""
        return np.maximum(np.nan_to_num(chi2, nan=1.0), 1.0) ** self.residual_power

    def along_ray_rate(self, free: np.ndarray) -> np.ndarray:
        """(M,) m/s of the along-ray model error of frames on a free end (``free`` True) or between contacts."""
        f = self.model_m_per_s if self.free_end_m_per_s is None else self.free_end_m_per_s
        return np.where(free, f, self.model_m_per_s)

    @classmethod
    def from_court(cls, court: Court) -> Uncertainty:
        extra = court.extra.get("uncertainty") or {}
        unknown = sorted(set(extra) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"{court.source}: unknown uncertainty keys {unknown}")
        out = cls(**{k: float(v) for k, v in extra.items()})
        if min(out.scale, out.model_m_per_s, out.floor_m, out.free_end_m_per_s or 0.0, out.residual_power) < 0 \
                or out.along_scale <= 0:
            raise ValueError(f"{court.source}: uncertainty values must be ≥ 0 (along_scale > 0), got {extra}")
        return out


@dataclass(frozen=True)
class ShootingConfig:
    """Weights and limits of one chain fit (σ's are the scale of each residual)."""

    pixel_sigma: float = 2.0          # px, 2D measurement noise
    huber_k: float = 3.0              # reprojection residuals beyond k σ are down-weighted
    outlier_k: float = 8.0            # ... and beyond this, in short runs, left out (a detector stuck elsewhere)
    outlier_run_s: float = 0.25       # longest run of such detections left out (s)
    outlier_share: float = 0.25       # most of a flight's 2D points left out (more: the flight fails instead)
    continuity_sigma: float = 0.005   # m
    tau_sigma: float = 1.5            # frames, prior on the contact time around the event frame
    tau_window: float = 2.5           # frames, the contact time stays within the event frame ± this
    spin_sigma: float = 250.0         # rad/s, weak prior pulling spin to 0 (tennis topspin reaches ~300)
    bounce_sigma_normal: float = 0.08  # relative σ of the normal rebound speed (restitution ± this)
    bounce_sigma_tangent: float = 0.12  # relative σ of the tangential rebound velocity (of the impact speed)
    bounce_sigma_floor: float = 0.3   # m/s added to both
    bounce_spin_sigma: float = 150.0  # rad/s, outgoing spin around the impact model's
    court_sigma: float = 0.01         # m, hinge on a frame below the floor or through a wall
    net_sigma: float = 0.02           # m
    limit_sigma: float = 0.05         # m, hinge of the hit-height range
    speed_cap: float = 1000.0          # m/s, a guard on LM trials against runaway flights (not physics: the checks flag > 75)
    reseed_sigmas: float = 5.0         # a run-out leaving its bounce backwards this many σ off the rebound restarts from it
    free_end_speed_sigma: float = 8.0  # m/s, Student-t pull towards rest of a free end's velocity or of a
    #                                    flight leaving the net/a mesh (its motion along the ray is unseen)
    lead_in_back_sigma: float = 2.0    # m/s, hinge on a lead-in reaching a racket hit from behind its hitter
    lead_in_back_allow: float = 1.0    # m/s of that motion allowed free (a serve's toss drifts), courts without walls
    fit_spin: bool = True
    fit_drag: bool = False
    drag_sigma: float = 0.2
    max_iter: int = 60
    irls_passes: int = 3
    reweighted_iter: int = 6
    tolerance: float = 1e-4            # stop when the cost falls by less than this fraction; at 1e-3 a long lob
    #                                    dominating the cost stopped the fit before its neighbours converged (the
    #                                    padel sample's far flights 0.41 → 0.07 m off; ~25 % more CPU there)
    steps_per_second: float = 15.0    # RK4 steps per second at least; at 30+ fps one step spans several frames
    #                                   (Hermite between): ≤ 0.2 mm from one step per frame up to 70 m/s


# ---------------------------------------------------------------------------------------------------
# Layout
# ---------------------------------------------------------------------------------------------------
@dataclass
class Contact:
    """One contact of a chain.

    Attributes:
        frame: its event frame; label: the event label; kind: ``plane``, ``hit`` or ``free`` (a surface the
            court does not have: a 3D point with no prior).
        tau: index of τ in θ; coords: indices of the point's coordinates (2 on a plane, 3 for a hit).
        origin, basis: point = origin + basis @ θ[coords]; normal: the plane's normal on the ball's side.
        material: the surface's material when its rebound follows the impact model, else None.
        prior: what was known before fitting.
    """

    frame: int
    label: str
    kind: str
    tau: int
    coords: list[int]
    origin: np.ndarray
    basis: np.ndarray
    normal: np.ndarray | None
    material: Material | None
    prior: ContactPrior
    plane: Plane | None = None


@dataclass
class Flight:
    """One flight: from contact ``start`` (forwards to ``end``, or to ``last`` when ``end`` is None), or the
    lead-in (``direction`` −1: backwards from contact ``start`` to frame ``last``).

    ``vel``/``spin``/``drag``: θ indices of its velocity and spin at the contact, and its drag multiplier.
    """

    start: int
    end: int | None
    direction: int
    last: int
    vel: list[int]
    spin: list[int] | None
    drag: int | None

    @property
    def lead_in(self) -> bool:
        return self.direction < 0


@dataclass
class Chain:
    """Contacts and flights fitted together, in time order (the lead-in first when there is one)."""

    contacts: list[Contact] = field(default_factory=list)
    flights: list[Flight] = field(default_factory=list)
    n: int = 0
    first_frame: int = 0
    last_frame: int = 0

    def point(self, theta: np.ndarray, c: int) -> np.ndarray:
        ct = self.contacts[c]
        return ct.origin + ct.basis @ theta[ct.coords]

    @property
    def has_lead_in(self) -> bool:
        return bool(self.flights) and self.flights[0].lead_in


def plane_frame(plane: Plane, radius: float, camera_centre: np.ndarray) -> tuple:
    """(origin, basis (3, 2), normal) of a plane moved one ball radius towards the ball's side."""
    n = plane.normal
    if plane.two_sided and (camera_centre - plane.origin) @ n < 0:
        n = -n
    return plane.origin + radius * n, np.stack([plane.u, plane.v], axis=1), n


def build_chain(obs: Observations, priors: list[ContactPrior], first_frame: int, last_frame: int,
                lead_in: bool, run_out: bool, cfg: ShootingConfig) -> tuple[Chain, np.ndarray]:
    """Lay out θ for the contacts ``priors`` (in time order) and their flights; θ holds the priors' points
    (NaN where unknown) and zero velocities and spins."""
    chain = Chain(first_frame=first_frame, last_frame=last_frame)
    theta: list[float] = []
    court = obs.court
    for prior in priors:
        tau = len(theta)
        theta.append(float(prior.frame))
        if prior.kind == "plane" and prior.plane is not None:
            origin, basis, normal = plane_frame(prior.plane, court.ball.radius, obs.camera.centre)
            coords0 = basis.T @ (prior.point - origin)
            mat = court.materials.get(prior.plane.material)
            material = mat if prior.plane.material in BOUNCE_MATERIALS else None
            kind = "plane"
        else:  # a racket hit, or a contact with a surface the court does not have: a free 3D point
            origin, basis, normal, coords0, material = np.zeros(3), np.eye(3), None, prior.point, None
            kind = "hit" if prior.kind == "hit" else "free"
        idx = list(range(len(theta), len(theta) + len(coords0)))
        theta.extend(np.asarray(coords0, float).tolist())
        chain.contacts.append(Contact(prior.frame, prior.label, kind, tau, idx, origin, basis, normal, material,
                                      prior, prior.plane if kind == "plane" else None))

    def flight(start: int, end: int | None, direction: int, last: int) -> None:
        vel = list(range(len(theta), len(theta) + 3))
        theta.extend([0.0] * 3)
        spin = None
        if cfg.fit_spin:
            spin = list(range(len(theta), len(theta) + 3))
            theta.extend([0.0] * 3)
        drag = None
        if cfg.fit_drag:
            drag = len(theta)
            theta.append(1.0)
        chain.flights.append(Flight(start, end, direction, last, vel, spin, drag))

    K = len(priors)
    if lead_in:
        flight(0, None, -1, first_frame)
    for c in range(K - 1):
        flight(c, c + 1, 1, priors[c + 1].frame)
    if run_out:
        flight(K - 1, None, 1, last_frame)
    chain.n = len(theta)
    return chain, np.array(theta)


# ---------------------------------------------------------------------------------------------------
# Batched flights with finite-difference perturbations
# ---------------------------------------------------------------------------------------------------
@dataclass
class Flights:
    """Positions/velocities at integer frames ``F0[s] + direction[s] · j`` of each flight (base and perturbed).

    P, V: (S, 1 + N_IN, L, 3); end, vend: (S, 1 + N_IN, 3) at the end contact's τ (forward flights with an
    end contact; zeros otherwise).
    """

    F0: np.ndarray
    direction: np.ndarray
    P: np.ndarray
    V: np.ndarray
    end: np.ndarray
    vend: np.ndarray


def hermite(p0, v0, p1, v1, u, dt):
    """Cubic Hermite position and velocity at fraction u of a step of dt seconds (broadcasting)."""
    u2, u3 = u * u, u * u * u
    pos = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * dt * v0 + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * dt * v1
    vel = ((6 * u2 - 6 * u) * p0 / dt + (3 * u2 - 4 * u + 1) * v0 + (-6 * u2 + 6 * u) * p1 / dt
           + (3 * u2 - 2 * u) * v1)
    return pos, vel


#: input columns whose perturbation is a translation: a flight does not depend on where it starts
TRANSLATION = (0, 1, 2)


def integrate(inputs: np.ndarray, F0: np.ndarray, direction: np.ndarray, L: int, tau_end: np.ndarray,
              fps: float, model: FlightModel, substeps: int, perturb: bool = True, stride: int = 1,
              integrated: tuple[int, ...] | None = None) -> Flights:
    """Integrate S flights, each with its N_IN forward-difference perturbations, in one batch.

    Args:
        inputs: (S, N_IN) [C | v | ω | τ | drag scale] at τ_s (frames).
        F0: (S,) the grid's first frame; direction: (S,) +1 forwards, −1 backwards; L: frames on the grid.
        tau_end: (S,) τ of the end contact (NaN: none).
        substeps: RK4 steps per frame; stride: frames per RK4 step (used when ``substeps`` is 1: at high
            frame rates one step spans ``stride`` frames and the frames between are cubic Hermite
            interpolations of its ends).
        perturb: also the N_IN perturbations of each flight (else only the base).
        integrated: the input columns whose perturbations are integrated (default: all); the position
            columns (:data:`TRANSLATION`) are otherwise the base moved by their step, any other column left
            out is taken to have no effect (e.g. the drag scale when it is not fitted).
    """
    S = len(inputs)
    V_ = 1 + N_IN if perturb else 1
    cols = np.arange(N_IN) if integrated is None else np.asarray(integrated, int)
    Vi = 1 + len(cols) if perturb else 1                                # variants integrated
    inp = np.repeat(inputs[:, None, :], Vi, axis=1)                     # (S, Vi, N_IN)
    if perturb:
        inp[:, 1:, :] += np.diag(EPS)[cols][None]
    inp = inp.reshape(-1, N_IN)
    f0 = np.repeat(F0, Vi).astype(float)
    sgn = np.repeat(direction, Vi).astype(float)
    c = list(model.kernel())
    c[1] = c[1] * inp[:, 10]                                            # per-flight drag
    state = tuple(np.ascontiguousarray(inp[:, k]) for k in range(9))
    state = rk4_step(state, (f0 - inp[:, 9]) / fps, c)                  # from τ to the grid's first frame
    k = stride if substeps == 1 and stride > 1 else 1
    h = sgn * k / (fps * substeps)
    factors = spin_factors(h, c[5])
    nodes = -(-(L - 1) // k) + 1                                        # steps cover frames 0 … L − 1
    P, Vv, _ = rk4_path(state, h, c, factors, nodes, substeps)
    if k > 1:                                                           # frames between the steps
        Pf, Vf = np.empty((L, 3, len(inp))), np.empty((L, 3, len(inp)))
        m = len(range(0, L, k))
        Pf[0::k], Vf[0::k] = P[:m], Vv[:m]
        for q in range(1, k):                                           # frames q, q + k, … between nodes
            m = len(range(q, L, k))
            if m:
                u = (np.arange(q, L, k) / k - np.arange(m))[:, None, None]
                Pf[q::k], Vf[q::k] = hermite(P[:m], Vv[:m], P[1:m + 1], Vv[1:m + 1], u, h[None, None, :])
        P, Vv = Pf, Vf
    P = P.transpose(2, 0, 1).reshape(S, Vi, L, 3)
    Vv = Vv.transpose(2, 0, 1).reshape(S, Vi, L, 3)
    if Vi < V_:                                                         # the variants not integrated
        P_, V2 = np.repeat(P[:, :1], V_, axis=1), np.repeat(Vv[:, :1], V_, axis=1)
        P_[:, 1 + cols], V2[:, 1 + cols] = P[:, 1:], Vv[:, 1:]
        for q in TRANSLATION:
            if q not in cols:
                P_[:, 1 + q, :, q] += EPS[q]
        P, Vv = P_, V2
    end = np.zeros((S, V_, 3))
    vend = np.zeros((S, V_, 3))
    has = np.isfinite(tau_end)
    if has.any():
        rows = np.flatnonzero(has)
        te = tau_end[rows]
        ja = np.clip(np.floor(te).astype(int) - F0[rows], 0, L - 2)
        u = (te - (F0[rows] + ja))[:, None, None]
        end[rows], vend[rows] = hermite(P[rows, :, ja], Vv[rows, :, ja], P[rows, :, ja + 1], Vv[rows, :, ja + 1],
                                        u, 1.0 / fps)
    return Flights(F0, direction, P, Vv, end, vend)


# ---------------------------------------------------------------------------------------------------
# Residuals with a sparse Jacobian
# ---------------------------------------------------------------------------------------------------
class _Rows:
    """Accumulates residual blocks and, lazily, their sparse Jacobian entries: the blocks are only evaluated
    when :meth:`jacobian` is called (a rejected LM trial never pays for its Jacobian)."""

    def __init__(self, n: int, jac: bool):
        self.n, self.jac = n, jac
        self.r: list[np.ndarray] = []
        self.pending: list[tuple[int, int, object]] = []
        self.m = 0
        self.group = ""                                   # what the rows added next stand for (DEPTH_CUES)
        self.groups: list[tuple[int, int, str]] = []      # (first row, rows, group) of every block

    def add(self, r: np.ndarray, blocks=None) -> None:
        """r: (R,) residuals; blocks(): [(cols (R, k) or (k,), values (R, k))] (called only with a Jacobian)."""
        r = np.asarray(r, float).reshape(-1)
        R = len(r)
        if not R:
            return
        if self.jac and blocks is not None:
            self.pending.append((self.m, R, blocks))
        self.groups.append((self.m, R, self.group))
        self.r.append(r)
        self.m += R

    def residuals(self) -> np.ndarray:
        return np.concatenate(self.r) if self.r else np.zeros(0)

    @np.errstate(over="ignore", invalid="ignore", divide="ignore")
    def jacobian(self) -> sparse.csr_matrix:
        """(m, n) sparse Jacobian of every block added with ``blocks``."""
        I, Jc, Jv = [], [], []
        for m0, R, blocks in self.pending:
            rows = np.arange(m0, m0 + R)
            for cols, vals in blocks():
                vals = np.asarray(vals, float).reshape(R, -1)
                full = np.empty(vals.shape, np.int64)
                full[...] = cols                                        # broadcast the column indices
                I.append(np.repeat(rows, vals.shape[1]))
                Jc.append(full.reshape(-1))
                Jv.append(vals.reshape(-1))
        if not I:
            return sparse.csr_matrix((self.m, self.n))
        return sparse.csr_matrix((np.concatenate(Jv), (np.concatenate(I), np.concatenate(Jc))), shape=(self.m, self.n))

    def result(self) -> tuple[np.ndarray, sparse.csr_matrix | None]:
        return self.residuals(), (self.jacobian() if self.jac else None)


def student_t(u: np.ndarray, dof: float) -> tuple[np.ndarray, np.ndarray]:
    """Residual ρ(u) = sign(u) √(ν log(1 + u²/ν)) whose square is the Student-t negative log-likelihood, and
    dρ/du (→ 1 at u = 0)."""
    q = np.log1p(u * u / dof) * dof
    rho = np.sign(u) * np.sqrt(q)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(np.abs(u) > 1e-8, u / (rho * (1.0 + u * u / dof)), 1.0)
    return rho, d


class Problem:
    """Residuals and Jacobian of one chain."""

    def __init__(self, obs: Observations, chain: Chain, cfg: ShootingConfig, model: FlightModel,
                 hit_prior: HitPrior):
        self.obs, self.chain, self.cfg, self.model, self.hit_prior = obs, chain, cfg, model, hit_prior
        self.fps = obs.fps
        self.substeps = max(1, int(np.ceil(cfg.steps_per_second / obs.fps)))
        self.stride = max(1, int(obs.fps // cfg.steps_per_second))     # frames per RK4 step at high frame rates
        #: perturbations integrated: velocity, spin, τ and the drag scale when fitted (positions: translations)
        self.integrated = tuple(range(3, 10)) + ((10,) if cfg.fit_drag else ())
        frames = np.arange(chain.first_frame, chain.last_frame + 1)
        seen = np.isfinite(obs.uv[frames]).all(axis=1)
        self.frames = frames[seen]
        self.uv = obs.uv[self.frames]
        self.weights = np.ones(len(self.frames))
        self.muted = np.zeros(len(self.frames), bool)   # frames left out by the caller (a failing flight's)
        #: short runs of detections the track jumps to and away from (:func:`jump_runs`): left out from the start
        self.jumps = jump_runs(self.frames, self.uv, obs.camera.image_size, obs.fps)
        self.forced = np.zeros(len(self.frames), bool)  # detections the caller leaves out (:meth:`leave_out`)
        self.outliers = self.jumps.copy()  # detections the fit leaves out (:meth:`find_outliers`)
        self.weights[self.jumps] = 0.0
        self.event_frames = np.array([ct.frame for ct in chain.contacts])
        beyond = {f: e for f, e in obs.beyond_edges().items() if chain.first_frame <= f <= chain.last_frame}
        self.beyond_frames = np.array(sorted(beyond), np.int64)
        self.beyond_edge = np.array([beyond[f] for f in self.beyond_frames], np.int64)
        nets = [p for p in obs.court.planes if p.event == "net"]
        self.net = nets[0] if nets else None
        self._walls = [p for p in obs.court.planes if not p.two_sided and p.event != "ground"
                       and p.material in ("glass", "mesh")]
        r_ball = obs.court.ball.radius
        self._wall_frames = [(w, w.normal, w.origin + r_ball * w.normal) for w in self._walls]
        self._layout_inputs()
        self.last_norm = np.zeros(len(self.frames))
        self.norm_at: np.ndarray | None = None        # the θ of last_norm
        #: the impact model and the court's walls take part (off in the first pass: their hinges and the
        #: impact of a flight that is still far off send LM into poor minima)
        self.physics = True

    # --- which θ entries feed each flight's inputs ------------------------------------------------
    def _layout_inputs(self) -> None:
        """Per flight: the θ columns (S, 11) and d(inputs)/d(those columns) (S, N_IN, 11)."""
        ch = self.chain
        S = len(ch.flights)
        cols = np.zeros((S, 11), np.int64)
        M = np.zeros((S, N_IN, 11))
        for s, fl in enumerate(ch.flights):
            ct = ch.contacts[fl.start]
            entries: list[tuple[int, int, float]] = []
            for k in range(3):
                for q, idx in enumerate(ct.coords):
                    entries.append((k, idx, ct.basis[k, q]))
            entries += [(3 + k, fl.vel[k], 1.0) for k in range(3)]
            if fl.spin is not None:
                entries += [(6 + k, fl.spin[k], 1.0) for k in range(3)]
            entries.append((9, ct.tau, 1.0))
            if fl.drag is not None:
                entries.append((10, fl.drag, 1.0))
            uniq = sorted({e[1] for e in entries})
            pos = {c: i for i, c in enumerate(uniq)}
            cols[s, :len(uniq)] = uniq
            for k, idx, coef in entries:
                M[s, k, pos[idx]] += coef
        self.cols, self.M = cols, M
        # the constant part of the inputs: the start contact's plane origin, drag scale 1 when not fitted
        offset = np.zeros((S, N_IN))
        for s, fl in enumerate(ch.flights):
            offset[s, :3] = ch.contacts[fl.start].origin
            if fl.drag is None:
                offset[s, 10] = 1.0
        self.offset = offset

    def inputs(self, theta: np.ndarray) -> np.ndarray:
        """(S, N_IN) flight inputs at θ."""
        return np.einsum("skm,sm->sk", self.M, theta[self.cols]) + self.offset

    def taus(self, theta: np.ndarray) -> np.ndarray:
        return theta[[ct.tau for ct in self.chain.contacts]]

    def owners(self, frames: np.ndarray, taus: np.ndarray) -> np.ndarray:
        """(M,) the flight that owns each frame (by the contact times)."""
        k = np.searchsorted(taus, frames, side="right")               # contacts at or before the frame
        if not self.chain.has_lead_in:
            k = k - 1
        return np.clip(k, 0, len(self.chain.flights) - 1)

    def grid(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """First grid frame (S,), direction (S,), τ of the end contact (S, NaN none), grid length."""
        ch = self.chain
        taus = self.taus(theta)
        S = len(ch.flights)
        F0 = np.zeros(S, np.int64)
        dirn = np.array([fl.direction for fl in ch.flights], np.int64)
        tau_end = np.full(S, np.nan)
        need = np.zeros(S, np.int64)
        for s, fl in enumerate(ch.flights):
            t0, ev0 = taus[fl.start], ch.contacts[fl.start].frame
            if fl.lead_in:
                F0[s] = max(int(np.ceil(t0)), ev0)
                need[s] = F0[s] - fl.last + 1
            else:
                F0[s] = min(int(np.floor(t0)), ev0)
                if fl.end is not None:
                    te = taus[fl.end]
                    tau_end[s] = te
                    need[s] = max(int(np.ceil(te)), ch.contacts[fl.end].frame) + 1 - F0[s] + 1
                else:
                    need[s] = fl.last - F0[s] + 1
        return F0, dirn, tau_end, int(max(need.max(), 2))

    def flights(self, theta: np.ndarray, perturb: bool) -> Flights:
        return self.flights_batch([theta], perturb)[0]

    @np.errstate(over="ignore", invalid="ignore", divide="ignore")  # a wild LM trial: rejected by its cost
    def flights_batch(self, thetas: list[np.ndarray], perturb: bool) -> list[Flights]:
        """The flights of several θ integrated in one batch (e.g. LM trials with different damping): each
        θ's flights are the same as integrated alone, on a grid as long as the longest."""
        grids = [self.grid(t) for t in thetas]
        L = max(g[3] for g in grids)
        F0, dirn, tau_end = (np.concatenate([g[i] for g in grids]) for i in range(3))
        inputs = np.concatenate([self.inputs(t) for t in thetas])
        fl = integrate(inputs, F0, dirn, L, tau_end, self.fps, self.model, self.substeps, perturb, self.stride,
                       self.integrated)
        S = len(self.chain.flights)
        return [Flights(*(a[b * S:(b + 1) * S] for a in (fl.F0, fl.direction, fl.P, fl.V, fl.end, fl.vend)))
                for b in range(len(thetas))]

    def index(self, fl: Flights, s: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """Grid index of ``frames`` in flights ``s``."""
        return np.clip((frames - fl.F0[s]) * fl.direction[s], 0, fl.P.shape[2] - 1)

    # --- residuals -------------------------------------------------------------------------------
    def evaluate(self, theta: np.ndarray, jac: bool = True) -> tuple[np.ndarray, sparse.csr_matrix | None, dict]:
        """Residuals (m,), the sparse Jacobian (m, n) with ``jac``, and what the outputs need."""
        rows, aux = self.assemble(theta, jac)
        return (*rows.result(), aux)

    @np.errstate(over="ignore", invalid="ignore", divide="ignore")  # a wild LM trial: rejected by its cost
    def assemble(self, theta: np.ndarray, jac: bool = True, fl: Flights | None = None) -> tuple[_Rows, dict]:
        """The residual rows at θ (their Jacobian is evaluated on demand, :meth:`_Rows.jacobian`) and what the
        outputs need; sets ``last_norm``. ``fl``: θ's flights when already integrated (with perturbations
        when ``jac``)."""
        ch, cfg = self.chain, self.cfg
        fl = fl if fl is not None else self.flights(theta, perturb=jac)
        taus = self.taus(theta)
        rows = _Rows(ch.n, jac)
        cols, M = self.cols, self.M

        def through(s: np.ndarray, d_in: np.ndarray) -> list:
            """d(rows)/d(inputs of flight s) (R, N_IN) → sparse blocks over θ."""
            return [(cols[s], np.einsum("rk,rkm->rm", d_in, M[s]))]

        # reprojection
        own = self.owners(self.frames, taus)
        j = self.index(fl, own, self.frames)
        pts = fl.P[own, :, j]                                               # (R, V, 3)
        pix = self.obs.camera.project(pts.reshape(-1, 3)).reshape(len(j), pts.shape[1], 2)
        r = (pix[:, 0] - self.uv) / cfg.pixel_sigma
        r = np.where(np.isfinite(r), r, 1e3)                                # behind the camera: far off
        self.last_norm, self.norm_at = np.linalg.norm(r, axis=1), theta
        w = self.weights

        def reproj_blocks():
            d = (pix[:, 1:] - pix[:, :1]) / EPS[None, :, None] / cfg.pixel_sigma   # (R, N_IN, 2)
            d = np.where(np.isfinite(d), d, 0.0) * w[:, None, None]
            d = d.transpose(0, 2, 1).reshape(-1, N_IN)
            return through(np.repeat(own, 2), d)

        rows.group = "track"
        rows.add((r * w[:, None]).reshape(-1), reproj_blocks)

        # continuity: a flight ends at its end contact
        rows.group = "continuity"
        for s, f in enumerate(ch.flights):
            if f.end is None:
                continue
            ct = ch.contacts[f.end]

            def cont_blocks(s=s, ct=ct):
                d_end = (fl.end[s, 1:] - fl.end[s, :1]) / EPS[:, None]           # (N_IN, 3)
                b = through(np.full(3, s), d_end.T)
                b.append((np.array([ct.tau]), (fl.vend[s, 0] / self.fps)[:, None]))
                b.append((np.array(ct.coords), -ct.basis))
                return [(c, v / cfg.continuity_sigma) for c, v in b]

            rows.add((fl.end[s, 0] - ch.point(theta, f.end)) / cfg.continuity_sigma, cont_blocks)

        if self.physics:
            rows.group = "bounce"
            self._bounces(theta, fl, taus, rows, through)
            rows.group = "court"
            self._court(fl, taus, rows, through)
            rows.group = "picture edge"
            self._beyond(fl, taus, rows, through)
        rows.group = "net"
        self._net(fl, taus, rows, through)
        rows.group = "hitter"
        self._hits(theta, rows)
        rows.group = "free end"
        self._free_ends(theta, rows)

        # contact-time prior, spin and drag priors
        tau_idx = np.array([ct.tau for ct in ch.contacts])
        ev = self.event_frames
        rows.group = "timing"
        rows.add((theta[tau_idx] - ev) / cfg.tau_sigma,
                 lambda: [(tau_idx[:, None], np.full((len(ev), 1), 1.0 / cfg.tau_sigma))])
        spin = np.array([f.spin for f in ch.flights if f.spin is not None], np.int64).reshape(-1)
        rows.group = "spin"
        if len(spin):
            rows.add(theta[spin] / cfg.spin_sigma,
                     lambda: [(spin[:, None], np.full((len(spin), 1), 1.0 / cfg.spin_sigma))])
        drag = np.array([f.drag for f in ch.flights if f.drag is not None], np.int64)
        rows.group = "drag"
        if len(drag):
            rows.add((theta[drag] - 1.0) / cfg.drag_sigma,
                     lambda: [(drag[:, None], np.full((len(drag), 1), 1.0 / cfg.drag_sigma))])
        return rows, {"flights": fl, "owners": own, "taus": taus, "groups": rows.groups}

    def incoming(self, theta: np.ndarray, fl: Flights, taus: np.ndarray, c: int):
        """The flight arriving at contact c: (flight index, v_in (3,), ω_in (3,), dv_in/dinputs (N_IN, 3) or
        None when v_in is the lead-in's own velocity parameter)."""
        ch = self.chain
        for s, f in enumerate(ch.flights):
            if f.end == c:
                w = theta[f.spin] if f.spin is not None else np.zeros(3)
                decay = np.exp(-self.model.spin_rate * (taus[c] - taus[f.start]) / self.fps)
                dv = (fl.vend[s, 1:] - fl.vend[s, :1]) / EPS[:, None] if fl.vend.shape[1] > 1 else np.zeros((N_IN, 3))
                return s, fl.vend[s, 0], w * decay, dv, decay
            if f.lead_in and f.start == c:
                w = theta[f.spin] if f.spin is not None else np.zeros(3)
                return s, theta[f.vel], w, None, 1.0
        return None

    def bounce_sigmas(self, v_in: np.ndarray, normal: np.ndarray) -> tuple[float, float]:
        """σ (m/s) of the outgoing velocity around the impact model's, along the normal and along the surface,
        for an incoming velocity ``v_in`` (3,)."""
        cfg = self.cfg
        vn = abs(float(v_in @ normal))
        return (cfg.bounce_sigma_normal * vn + cfg.bounce_sigma_floor,
                cfg.bounce_sigma_tangent * float(np.linalg.norm(v_in)) + cfg.bounce_sigma_floor)

    def _bounces(self, theta, fl, taus, rows: _Rows, through) -> None:
        """The impact model at floor/glass contacts with flights on both sides."""
        ch, cfg = self.chain, self.cfg
        r_ball = self.obs.court.ball.radius
        todo = []
        for c, ct in enumerate(ch.contacts):
            if ct.material is None or ct.normal is None:
                continue
            out = [s for s, f in enumerate(ch.flights) if f.start == c and not f.lead_in]
            inc = self.incoming(theta, fl, taus, c)
            if not out or inc is None:
                continue
            if inc[1] @ ct.normal > -0.3:      # not moving into the surface: nothing to model
                continue
            todo.append((ct, out[0], inc))
        if not todo:
            return
        # the impact model of every contact and its 6 perturbations (v_in, ω_in) in one call
        X = np.repeat(np.stack([np.concatenate([inc[1], inc[2]]) for _, _, inc in todo]), 7, axis=0)
        X = X.reshape(len(todo), 7, 6)
        X[:, 1:4, :3] += np.eye(3) * 1e-4
        X[:, 4:7, 3:] += np.eye(3) * 1e-2
        X = X.reshape(-1, 6)
        rep = np.repeat(np.arange(len(todo)), 7)
        VO, WO = bounce(X[:, :3], X[:, 3:], np.stack([ct.normal for ct, _, _ in todo])[rep],
                        np.array([ct.material.restitution for ct, _, _ in todo])[rep],
                        np.array([ct.material.friction for ct, _, _ in todo])[rep], r_ball)
        for q, (ct, so, (si, vin, win, dvin, decay)) in enumerate(todo):
            n = ct.normal
            vo, wo = VO[7 * q:7 * q + 7], WO[7 * q:7 * q + 7]
            s_n, s_t = self.bounce_sigmas(vin, n)
            # residual in (normal, tangential) components
            Pn = np.outer(n, n)
            scale = (Pn / s_n + (np.eye(3) - Pn) / s_t)                         # (3, 3) symmetric
            fo = ch.flights[so]
            v_out = theta[fo.vel]
            rv = scale @ (v_out - vo[0])
            dvo = np.concatenate([(vo[1:4] - vo[0]) / 1e-4, (vo[4:7] - vo[0]) / 1e-2], axis=0)  # (6, 3)
            has_w = fo.spin is not None
            fi = ch.flights[si]

            def blocks(fo=fo, fi=fi, si=si, dvin=dvin, dvo=dvo, scale=scale, decay=decay):
                b = [(np.array(fo.vel), scale)]
                d_vin = -(scale @ dvo[:3].T)                                    # (3, 3) d r / d v_in
                d_win = -(scale @ dvo[3:].T) * decay
                if dvin is None:
                    b.append((np.array(fi.vel), d_vin))
                else:
                    b += through(np.full(3, si), d_vin @ dvin.T)
                if fi.spin is not None:
                    b.append((np.array(fi.spin), d_win))
                return b

            rows.add(rv, blocks)
            if has_w and fi.spin is not None:
                dwo = np.concatenate([(wo[1:4] - wo[0]) / 1e-4, (wo[4:7] - wo[0]) / 1e-2], axis=0)  # (6, 3)
                rw = (theta[fo.spin] - wo[0]) / cfg.bounce_spin_sigma

                def wblocks(fo=fo, fi=fi, si=si, dvin=dvin, dwo=dwo, decay=decay):
                    k = 1.0 / cfg.bounce_spin_sigma
                    b = [(np.array(fo.spin), np.eye(3) * k)]
                    d_vin = -dwo[:3].T * k
                    if dvin is None:
                        b.append((np.array(fi.vel), d_vin))
                    else:
                        b += through(np.full(3, si), d_vin @ dvin.T)
                    b.append((np.array(fi.spin), -dwo[3:].T * k * decay))
                    return b

                rows.add(rw, wblocks)

    def frame_positions(self, fl: Flights, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every frame of the chain: frames (M,), owning flights (M,), grid indices (M,)."""
        frames = np.arange(self.chain.first_frame, self.chain.last_frame + 1)
        own = self.owners(frames, taus)
        return frames, own, self.index(fl, own, frames)

    def _court(self, fl: Flights, taus: np.ndarray, rows: _Rows, through) -> None:
        """Hinges on frames below the floor or behind a wall/glass patch (penetration deeper than 1 cm)."""
        cfg = self.cfg
        frames, own, j = self.frame_positions(fl, taus)
        P = fl.P[own, 0, j]                                                    # (M, 3)
        r_ball = self.obs.court.ball.radius
        tol = 0.01
        # frames outside every flight's time span (before the first contact without a lead-in, after the last
        # without a run-out) are extrapolations: not judged
        live = np.ones(len(P), bool)
        if not self.chain.has_lead_in:
            live &= frames >= taus[0]
        if self.chain.flights[-1].end is not None:
            live &= frames <= taus[-1]
        for wall, n, o in [(None, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, r_ball]))] + self._wall_frames:
            d = (P - o) @ n
            bad = np.flatnonzero(live & (d < -tol))
            if len(bad) and wall is not None:           # behind the wall's plane: within its extent?
                bad = bad[wall.contains(P[bad], tol=0.05)]
            if not len(bad):
                continue

            def blocks(bad=bad, n=n):
                dP = (fl.P[own[bad], 1:, j[bad]] - fl.P[own[bad], :1, j[bad]]) / EPS[None, :, None]  # (R, N_IN, 3)
                return through(own[bad], (dP @ n) / cfg.court_sigma)

            rows.add((d[bad] + tol) / cfg.court_sigma, blocks)

    def _beyond(self, fl: Flights, taus: np.ndarray, rows: _Rows, through) -> None:
        """Hinges keeping the ball beyond the image edge it left through where the track says so
        (:meth:`~.observations.Observations.beyond_edges`: a lob above the top of the picture): a frame
        projected inside the picture by more than 2 σ costs its distance past that line (σ units)."""
        if not len(self.beyond_frames):
            return
        cfg = self.cfg
        own = self.owners(self.beyond_frames, taus)
        j = self.index(fl, own, self.beyond_frames)
        pts = fl.P[own, :, j]                                                   # (R, V, 3)
        pix = self.obs.camera.project(pts.reshape(-1, 3)).reshape(len(j), pts.shape[1], 2)
        w, h = (float(v) for v in self.obs.camera.image_size)
        e = self.beyond_edge
        axis = np.where(e < 2, 1, 0)
        sign = np.where(e % 2 == 0, 1.0, -1.0)                                   # top/left: inside is +
        bound = np.where(e == 1, h, np.where(e == 3, w, 0.0))
        tol = 2.0 * cfg.pixel_sigma
        coord = pix[np.arange(len(j)), :, axis]                                  # (R, V)
        inside = sign[:, None] * (coord - bound[:, None]) - tol                   # > 0: inside the picture
        bad = np.flatnonzero(np.isfinite(inside[:, 0]) & (inside[:, 0] > 0))
        if not len(bad):
            return

        def blocks(bad=bad):
            d = (inside[bad, 1:] - inside[bad, :1]) / EPS[None, :] / cfg.pixel_sigma  # (B, N_IN)
            return through(own[bad], np.where(np.isfinite(d), d, 0.0))

        rows.add(inside[bad, 0] / cfg.pixel_sigma, blocks)

    def _net(self, fl: Flights, taus: np.ndarray, rows: _Rows, through) -> None:
        """Hinge on the ball's height where a flight without a net event crosses the net plane."""
        if self.net is None:
            return
        net = self.net
        ch = self.chain
        need_r = self.obs.court.ball.radius
        for s, f in enumerate(ch.flights):
            labels = [ch.contacts[f.start].label] + ([ch.contacts[f.end].label] if f.end is not None else [])
            if "net" in labels:
                continue
            P = fl.P[s, 0]
            d = (P - net.origin) @ net.normal
            if f.lead_in:
                j1 = int(fl.F0[s] - f.last)
            elif f.end is not None:
                j1 = int(np.floor(taus[f.end])) - fl.F0[s]
            else:
                j1 = f.last - fl.F0[s]
            j1 = min(j1, len(P) - 1)
            if j1 < 1:
                continue
            cross = np.flatnonzero(np.sign(d[:j1]) * np.sign(d[1:j1 + 1]) < 0)
            if not len(cross):
                continue
            k = int(cross[0])
            fr = d[k] / (d[k] - d[k + 1])
            p = P[k] + fr * (P[k + 1] - P[k])
            need = net_height(net, p) + need_r
            if p[2] >= need:
                continue

            def blocks(s=s, k=k, fr=fr, P=P):
                dz = ((1 - fr) * (fl.P[s, 1:, k, 2] - P[k, 2]) + fr * (fl.P[s, 1:, k + 1, 2] - fl.P[s, 0, k + 1, 2])) / EPS
                return through(np.array([s]), -dz[None, :] / self.cfg.net_sigma)

            rows.add(np.array([(need - p[2]) / self.cfg.net_sigma]), blocks)

    def _hits(self, theta: np.ndarray, rows: _Rows) -> None:
        """Racket hits: Student-t pull towards the hitter (forward, lateral), height range and height prior."""
        hp, cfg = self.hit_prior, self.cfg
        lo, hi = self.obs.court.hits.height
        lo = max(lo, self.obs.court.ball.radius)  # the ball's centre stays above the floor
        for ct in self.chain.contacts:
            if ct.kind != "hit":
                continue
            idx = np.array(ct.coords)
            p = theta[idx]
            h = ct.prior.hitter_xy
            if h is not None:
                fwd = 1.0 if h[1] < self.obs.court.net_y else -1.0
                ahead = hp.raised_forward if ct.prior.hand_raised and hp.raised_forward is not None else hp.forward
                u = np.array([(p[0] - h[0]) / hp.sigma_lateral, ((p[1] - h[1]) * fwd - ahead) / hp.sigma_forward])
                rho, d = student_t(u, hp.dof)
                rows.add(rho, lambda d=d, fwd=fwd, idx=idx: [
                    (idx[:2][None, :].repeat(2, 0), np.diag([d[0] / hp.sigma_lateral, d[1] * fwd / hp.sigma_forward]))])
            z0, sz = (ct.prior.hand_z + hp.raised_above_hand * ct.prior.hand_raised, hp.hand_sigma) \
                if ct.prior.hand_z is not None else (hp.height, hp.sigma_height)
            rho, d = student_t(np.array([(p[2] - z0) / sz]), hp.dof)
            rows.add(rho, lambda d=d, idx=idx, sz=sz: [(idx[2:3][None, :], np.array([[d[0] / sz]]))])
            viol = p[2] - hi if p[2] > hi else (p[2] - lo if p[2] < lo else 0.0)
            if viol:
                rows.add(np.array([viol / cfg.limit_sigma]),
                         lambda idx=idx: [(idx[2:3][None, :], np.array([[1.0 / cfg.limit_sigma]]))])

    def _free_ends(self, theta: np.ndarray, rows: _Rows) -> None:
        """Lead-ins, run-outs that do not leave a floor/glass bounce, and flights leaving the net or a mesh
        (rebounds the impact model leaves free): a heavy-tailed (Student-t) pull of the velocity at the
        contact towards rest. The 2D track pins such a flight's motion across the line of sight but hardly
        along it (a serve's toss seen from behind, a ball dropping off the net towards the camera); a fast
        flight that the track does explain costs little."""
        sig = self.cfg.free_end_speed_sigma
        if not sig:
            return
        for f in self.chain.flights:
            ct = self.chain.contacts[f.start]
            if not f.lead_in and ct.material is not None:
                continue           # leaving a floor/glass bounce: the impact model ties it to its incoming
            if f.end is not None and ct.kind == "hit":
                continue           # between a hit and the next contact: both ends pin it
            idx = np.array(f.vel)
            rho, d = student_t(theta[idx] / sig, self.hit_prior.dof)
            rows.add(rho, lambda d=d, idx=idx: [(idx[None, :].repeat(3, 0), np.diag(d / sig))])
        self._lead_in_from_behind(theta, rows)

    def _lead_in_from_behind(self, theta: np.ndarray, rows: _Rows) -> None:
        """A lead-in arriving at a racket hit comes from the other side of the net or is a toss: on a court
        without walls (nothing behind the hitter to rebound from) its velocity towards the net, beyond
        ``lead_in_back_allow``, is a hinge of σ ``lead_in_back_sigma``. Without it a serve's toss seen from
        behind fits as well as a fast ball flying at the camera from beyond the far baseline (5 m off)."""
        ch, cfg = self.chain, self.cfg
        if not cfg.lead_in_back_sigma or self._walls or not ch.has_lead_in:
            return
        f = ch.flights[0]
        if ch.contacts[f.start].kind != "hit":
            return
        side = 1.0 if ch.point(theta, f.start)[1] >= self.obs.court.net_y else -1.0
        towards_net = -side * theta[f.vel[1]]
        if towards_net > cfg.lead_in_back_allow:
            s = cfg.lead_in_back_sigma
            rows.add(np.array([(towards_net - cfg.lead_in_back_allow) / s]),
                     lambda i=f.vel[1], side=side, s=s: [(np.array([[i]]), np.array([[-side / s]]))])

    def seed_runouts(self, theta: np.ndarray, fl: Flights, theta0: np.ndarray | None = None) -> np.ndarray | None:
        """θ with each run-out that leaves a floor/glass bounce backwards (its velocity along the surface
        opposite to the incoming flight's, which no rebound does) and more than ``reseed_sigmas`` σ off the
        impact model's rebound restarted from that rebound, when that costs less with the physics on than θ as
        it is (None: no change). Without the impact model (the first pass) a run-out's depth is pinned by its
        2D track alone, and seen from behind or obliquely a ball moving away fits as well as one coming back
        towards the camera; LM does not leave that basin once the impact model joins. With ``theta0`` (the
        first pass's start) a second restart also takes the bounce (time, point) and its incoming flight back
        to where the first pass began them — the first pass can drag them along with the run-out (a ball
        dropping off the net: the bounce pulled 2.5 frames early, the run-out flying at the camera at
        67 m/s) — and the lower-cost restart is tried. A run-out that goes on
        forwards but far off the rebound is left alone: there the contact is more likely wrong (a wall the
        events missed) and a restart can turn a flight that fails its checks into a wrong one that passes."""
        ch = self.chain
        taus = self.taus(theta)
        flagged = []
        for c, ct in enumerate(ch.contacts):
            if ct.material is None or ct.normal is None:
                continue
            out = [f for f in ch.flights if f.start == c and f.end is None and not f.lead_in]
            inc = self.incoming(theta, fl, taus, c)
            if not out or inc is None or inc[1] @ ct.normal > -0.3:
                continue
            vo, _ = bounce(inc[1][None], inc[2][None], ct.normal[None], ct.material.restitution,
                           ct.material.friction, self.obs.court.ball.radius)
            dv = theta[out[0].vel] - vo[0]
            s_n, s_t = self.bounce_sigmas(inc[1], ct.normal)
            dn = float(dv @ ct.normal)
            if np.hypot(dn / s_n, np.linalg.norm(dv - dn * ct.normal) / s_t) < self.cfg.reseed_sigmas:
                continue                   # the run-out is about what the impact model says: leave it
            t_in = inc[1] - (inc[1] @ ct.normal) * ct.normal
            t_out = theta[out[0].vel] - (theta[out[0].vel] @ ct.normal) * ct.normal
            if t_in @ t_out >= 0:
                continue                   # it goes on along the surface: a wrong contact more likely than a wrong depth
            flagged.append((c, out[0], inc[0]))
        if not flagged:
            return None
        cands = [self._rebound_runouts(theta.copy(), flagged, fl)]
        if theta0 is not None:
            back = theta.copy()
            for c, _, s in flagged:
                ct, f_in = ch.contacts[c], ch.flights[s]
                idx = [ct.tau, *ct.coords, *f_in.vel, *(f_in.spin or []), *([f_in.drag] if f_in.drag is not None else [])]
                back[idx] = theta0[idx]
            cands.append(self._rebound_runouts(back, flagged))
        with np.errstate(over="ignore", invalid="ignore"):  # a wild candidate's cost is inf: never the best
            costs = [float(np.sum(self.assemble(t, jac=False)[0].residuals() ** 2)) for t in (theta, *cands)]
        best = int(np.argmin(costs))
        return cands[best - 1] if best else None

    def _rebound_runouts(self, theta: np.ndarray, flagged: list, fl: Flights | None = None) -> np.ndarray:
        """θ with the run-outs of ``flagged`` (contact, run-out flight, incoming flight index) set to the
        impact model's rebound of their incoming flight (at θ; ``fl``: θ's flights when already integrated)."""
        fl, taus = fl if fl is not None else self.flights(theta, perturb=False), self.taus(theta)
        for c, out, _ in flagged:
            ct = self.chain.contacts[c]
            inc = self.incoming(theta, fl, taus, c)
            vo, wo = bounce(inc[1][None], inc[2][None], ct.normal[None], ct.material.restitution,
                            ct.material.friction, self.obs.court.ball.radius)
            theta[out.vel] = vo[0]
            if out.spin is not None:
                theta[out.spin] = wo[0]
        return theta

    def mute(self, spans: list[tuple[int, int]]) -> None:
        """Leave the frames of ``spans`` (first, last) out of the fit (weights 0 through every reweighting)."""
        for a, b in spans:
            self.muted |= (self.frames >= a) & (self.frames <= b)
        self.weights[self.muted] = 0.0

    def leave_out(self, frames) -> None:
        """Leave the detections at ``frames`` out of the fit for good, reported as left out (not muted: the flight
        owning them is still judged on its other detections)."""
        self.forced |= np.isin(self.frames, np.asarray(list(frames), np.int64))
        self.outliers |= self.forced
        self.weights[self.forced] = 0.0

    def reweight(self) -> None:
        """Huber weights from the latest evaluation's reprojection residuals (held fixed while LM runs); muted
        frames and short runs of detections far off the fit (:meth:`find_outliers`) weigh nothing."""
        k = self.cfg.huber_k
        self.outliers = self.find_outliers() | self.jumps | self.forced
        w = np.where(self.last_norm > k, np.sqrt(k / np.maximum(self.last_norm, 1e-12)), 1.0)
        w[self.muted | self.outliers] = 0.0
        self.weights = w

    def find_outliers(self) -> np.ndarray:
        """(M,) detections to leave out: beyond ``outlier_k`` σ of the latest fit, in runs of at most
        ``outlier_run_s`` with well-fitted detections of the same flight on both sides, and at most
        ``outlier_share`` of their flight's 2D points (a flight whose track is off more than that fails its
        checks instead: nothing hides a wrong flight)."""
        cfg = self.cfg
        far = (self.last_norm > cfg.outlier_k) & ~self.muted & ~self.jumps & ~self.forced
        if not far.any() or self.norm_at is None:
            return np.zeros(len(self.frames), bool)
        own = self.owners(self.frames, self.taus(self.norm_at))
        longest = max(1, int(round(cfg.outlier_run_s * self.fps)))
        out = np.zeros(len(self.frames), bool)
        for s in np.unique(own[far]):
            mine = own == s
            cand = far & mine
            k = np.flatnonzero(cand)
            runs = np.split(k, np.flatnonzero(np.diff(self.frames[k]) > 1) + 1)
            if max(len(r) for r in runs) > longest or len(k) > cfg.outlier_share * mine.sum():
                continue
            inner = np.flatnonzero(mine & ~far)
            if not len(inner):
                continue
            for r in runs:  # inside the flight's track only: its ends are where a flight model is least sure
                if self.frames[inner[0]] < self.frames[r[0]] and self.frames[r[-1]] < self.frames[inner[-1]]:
                    out[r] = True
        return out

    def clamp(self, theta: np.ndarray) -> np.ndarray:
        """Project θ onto what is possible: contact times in their windows and in order, racket hits within
        the court's height range and the hitter's reach, every flight's speed at its contact at most
        ``speed_cap`` (a flight nothing constrains along the line of sight — a run-out without 2D points in
        the first pass — had flown off to 10⁸ m/s, and its rows swamped the normal matrix)."""
        cfg, ch = self.cfg, self.chain
        theta = theta.copy()
        prev = -np.inf
        for ct in ch.contacts:
            t = min(max(theta[ct.tau], ct.frame - cfg.tau_window), ct.frame + cfg.tau_window)
            t = max(t, prev + 0.5)
            theta[ct.tau] = t
            prev = t
        lo, hi = self.obs.court.hits.height
        r_ball = self.obs.court.ball.radius
        for ct in ch.contacts:
            if ct.kind != "hit":
                continue
            p = theta[ct.coords]
            p[2] = min(max(p[2], max(lo, r_ball)), hi)
            h = ct.prior.hitter_xy
            if h is not None:
                off = p[:2] - h
                dist = float(np.linalg.norm(off))
                if dist > self.hit_prior.reach:
                    p[:2] = h + off * (self.hit_prior.reach / dist)
            theta[ct.coords] = p
        cap = self.cfg.speed_cap
        for f in ch.flights:
            speed = float(np.linalg.norm(theta[f.vel]))
            if speed > cap:
                theta[f.vel] *= cap / speed
        return theta


#: a detection this far (share of the image width) from the one before, per frame between them, is a jump no
#: broadcast ball makes: 0.15 of 1920 px is 288 px a frame (the fastest serve seen from 20 m: ~100)
JUMP_SHARE = 0.15
#: the longest run of detections (s) that a jump to and away from marks as a detection of something else
JUMP_RUN_S = 0.2


def jump_runs(frames: np.ndarray, uv: np.ndarray, image_size, fps: float) -> np.ndarray:
    """(M,) the detections of short runs (≤ :data:`JUMP_RUN_S`) that the track jumps to and away from (or to,
    then loses): a tracker stuck for a few frames on something far from the ball. ``frames`` (M,) sorted, ``uv``
    (M, 2) pixels; a jump is :data:`JUMP_SHARE` × the image width per frame or more, and the run must be
    shorter than the runs around it."""
    M = len(frames)
    out = np.zeros(M, bool)
    if M < 3:
        return out
    limit = JUMP_SHARE * float(image_size[0])
    step = np.linalg.norm(np.diff(uv, axis=0), axis=1) / np.maximum(np.diff(frames), 1)
    near = np.diff(frames) <= 2                       # consecutive detections (a 1-frame miss between at most)
    cut = np.flatnonzero(~near | (step > limit)) + 1   # where runs start
    starts, stops = np.r_[0, cut], np.r_[cut, M]
    jumped = np.r_[False, near & (step > limit)]       # the run starting here was jumped to
    longest = max(1, int(round(JUMP_RUN_S * fps)))
    for i, (a, b) in enumerate(zip(starts, stops)):
        if b - a > longest or not jumped[a]:
            continue
        after_jump = b < M and near[b - 1] and step[b - 1] > limit
        lost_after = b == M or not near[b - 1]
        before = stops[i - 1] - starts[i - 1] if i > 0 else 0
        after = stops[i + 1] - starts[i + 1] if i + 1 < len(starts) else 0
        if (after_jump or lost_after) and b - a < max(before, after if after_jump else 0):
            out[a:b] = True
    return out


def net_height(net, point: np.ndarray) -> float:
    """Height of the net's top edge at ``point``'s position along the net (from the net polygon)."""
    poly = net.polygon
    top = poly[poly[:, 1] > 1e-6]
    order = np.argsort(top[:, 0])
    u = (point - net.origin) @ net.u
    return float(np.interp(u, top[order, 0], top[order, 1]))


# ---------------------------------------------------------------------------------------------------
# Levenberg-Marquardt
# ---------------------------------------------------------------------------------------------------
#: Levenberg-Marquardt damping: start nearly Gauss-Newton and change it tenfold.
LM_LAMBDA0 = 1e-4
LM_FACTOR = 10.0


@dataclass
class Solution:
    theta: np.ndarray
    r: np.ndarray
    J: sparse.csr_matrix
    aux: dict
    iterations: int


def solve(problem: Problem, theta: np.ndarray, max_iter: int | None = None) -> Solution:
    """Iteratively reweighted LM: a pass with unit weights, then short passes with Huber weights while some
    2D points lie beyond ``huber_k`` σ (outliers are down-weighted, not dropped)."""
    cfg = problem.cfg
    problem.physics = False
    theta0 = problem.clamp(theta)
    sol = lm(problem, theta0, max_iter or cfg.max_iter)
    problem.physics = True
    n = sol.iterations
    seeded = problem.seed_runouts(sol.theta, sol.aux["flights"], theta0)
    plain = lm(problem, sol.theta, max_iter or cfg.max_iter, sol.aux["flights"])
    if seeded is not None:   # both starts: the restarted run-outs only where they end lower
        other = lm(problem, seeded, max_iter or cfg.max_iter)
        plain = other if float(other.r @ other.r) < float(plain.r @ plain.r) else plain
    sol = plain
    sol.iterations += n
    for _ in range(cfg.irls_passes - 1):
        problem.reweight()
        if np.all(problem.weights == 1.0) or np.all(problem.weights[~problem.muted] == 1.0):
            break
        n = sol.iterations
        sol = lm(problem, sol.theta, cfg.reweighted_iter, sol.aux["flights"])
        sol.iterations += n
    for _ in range(2):  # detections far off the converged fit (a stuck tracker): left out, then refit
        before = problem.outliers.copy()
        problem.reweight()
        if not problem.outliers.any() or np.array_equal(problem.outliers, before):
            break
        n = sol.iterations
        sol = lm(problem, sol.theta, cfg.reweighted_iter, sol.aux["flights"])
        sol.iterations += n
    return sol


#: LM trials integrated together: the first batch (the usual damping and the next one up), then the rest
LM_BATCHES = (2, 3, 3)


def lm(problem: Problem, theta: np.ndarray, max_iter: int, flights: Flights | None = None) -> Solution:
    """Levenberg-Marquardt from θ (``flights``: θ's flights when a previous pass integrated them). Up to 8
    trials per iteration, the damping ×10 after each rejected one; trials are integrated in batches
    (:data:`LM_BATCHES`, one pass of the integrator each) but judged in order, so the path is that of trying
    them one at a time. A trial's Jacobian is assembled only when it is accepted; ``problem.last_norm`` is
    left at the returned θ."""
    cfg = problem.cfg
    rows, aux = problem.assemble(theta, fl=flights)
    r, J = rows.result()
    norm = problem.last_norm
    with np.errstate(over="ignore"):  # a wild start (a hypothesis far off) costs inf: every trial improves on it
        cost = float(r @ r)
    lam = LM_LAMBDA0
    it = 0
    rel = 1.0
    for it in range(max_iter):  # noqa: B007
        A = (J.T @ J).toarray()
        g = J.T @ r
        D = np.maximum(np.diag(A), 1e-9)
        improved = False
        for size in LM_BATCHES:
            trials = []                                   # (damping, θ) of the next ``size`` attempts
            for _ in range(size):
                try:
                    step = -np.linalg.solve(A + lam * np.diag(D), g)
                    trials.append((lam, problem.clamp(theta + step)))
                except np.linalg.LinAlgError:
                    pass
                lam *= LM_FACTOR
            flights = problem.flights_batch([c for _, c in trials], perturb=True) if trials else []
            for (lam_c, cand), fl in zip(trials, flights):
                rows, aux2 = problem.assemble(cand, fl=fl)
                r2 = rows.residuals()
                with np.errstate(over="ignore", invalid="ignore"):  # a wild trial step: its cost is inf, refused
                    cost2 = float(r2 @ r2)
                if np.isfinite(cost2) and cost2 < cost:
                    rel = (cost - cost2) / max(cost, 1e-12)
                    theta, cost, r, J, aux, norm = cand, cost2, r2, rows.jacobian(), aux2, problem.last_norm
                    lam = max(lam_c / LM_FACTOR, 1e-9)
                    improved = True
                    break
            if improved:
                break
        if not improved or rel < cfg.tolerance:
            break
    problem.last_norm, problem.norm_at = norm, theta
    return Solution(theta, r, J, aux, it + 1)


# ---------------------------------------------------------------------------------------------------
# Covariance
# ---------------------------------------------------------------------------------------------------
@dataclass
class FrameErrorModel:
    """The reported per-frame error model of a fitted chain: frame positions' Jacobians (M, 3, 11) on their
    columns (M, 11) of θ, θ's covariance (n, n), the isotropic variance (m²), the along-ray model-error
    vectors (M, 3: σ × unit line of sight) and each frame's flight factor k (M,); with a calibrated camera's
    pose covariance Σc (7, 7), the frames' response to the camera's pose T (M, 3, 7). The covariance of frame
    m is k (Jp Σ Jpᵀ + a aᵀ) + T Σc Tᵀ + iso I."""

    frames: np.ndarray
    xyz: np.ndarray
    own: np.ndarray
    jac: np.ndarray
    cols: np.ndarray
    theta_cov: np.ndarray
    iso_var: float
    along: np.ndarray
    free: np.ndarray        # (M,) frame on a free end (lead-in / run-out)
    dt: np.ndarray          # (M,) s from the nearest contact
    ray: np.ndarray         # (M, 3) unit line of sight
    flight_chi2: np.ndarray  # (flights,) mean squared normalised reprojection residual per 2D coordinate
    factor: np.ndarray       # (M,) covariance factor of the frame's flight (Uncertainty.flight_factor)
    camera_jac: np.ndarray | None = None   # (M, 3, 7) d(frame position)/d(camera pose) after the refit
    camera_cov: np.ndarray | None = None   # (7, 7) the camera's pose covariance (Camera.pose_covariance)
    depth_cues: dict = field(default_factory=dict)   # chain flight → {cue: σ ratio without it} (depth_cues)

    def camera_part(self) -> np.ndarray:
        """(M, 3, 3) the covariance the camera's own uncertainty adds (zeros without one)."""
        if self.camera_jac is None or self.camera_cov is None:
            return np.zeros((len(self.frames), 3, 3))
        return np.einsum("mdk,kl,mel->mde", self.camera_jac, self.camera_cov, self.camera_jac)

    def covariances(self) -> np.ndarray:
        """(M, 3, 3)."""
        sub = self.theta_cov[self.cols[:, :, None], self.cols[:, None, :]]                # (M, 11, 11)
        out = np.einsum("mdc,mce,mfe->mdf", self.jac, sub, self.jac) + np.einsum("mi,mj->mij", self.along, self.along)
        return self.factor[:, None, None] * out + self.camera_part() + self.iso_var * np.eye(3)[None]

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """(n, M, 3) errors drawn from this model jointly, as a perfectly calibrated fit would make them: one
        draw of θ per sample propagated to every frame (so the frames of one flight share their depth error),
        one normal draw of the along-ray model error per flight and sample, the isotropic part per frame."""
        w, V = np.linalg.eigh(self.theta_cov)
        z = rng.standard_normal((n, len(w))) * np.sqrt(np.maximum(w, 0.0))
        dtheta = z @ V.T                                                                  # (n, P)
        out = np.einsum("mdc,smc->smd", self.jac, dtheta[:, self.cols])
        flights = rng.standard_normal((n, int(self.own.max()) + 1 if len(self.own) else 0))
        out += flights[:, self.own, None] * self.along[None]
        out *= np.sqrt(self.factor)[None, :, None]
        if self.camera_jac is not None and self.camera_cov is not None:   # one camera error for every frame
            wc, Vc = np.linalg.eigh(self.camera_cov)
            zc = (rng.standard_normal((n, 7)) * np.sqrt(np.maximum(wc, 0.0))) @ Vc.T
            out += np.einsum("mdk,sk->smd", self.camera_jac, zc)
        return out + np.sqrt(self.iso_var) * rng.standard_normal(out.shape)


def frame_error_model(problem: Problem, sol: Solution, inflation: float = 1.0, floor_m: float = 0.0,
                      calibration: Uncertainty | None = None) -> FrameErrorModel | None:
    """Every frame of the chain, from the first to the last frame: the :class:`FrameErrorModel` from the
    Gauss-Newton covariance of θ (scaled by the reprojection residuals' variance when it exceeds 1, times
    ``inflation``²), calibrated by ``calibration`` (:class:`Uncertainty`; its scale, its width along the ray
    apart from across it, and its along-ray model error),
    plus ``floor_m``² I. None when θ's normal matrix cannot be inverted."""
    cal = calibration or Uncertainty(floor_m=0.0)
    fl, taus = sol.aux["flights"], sol.aux["taus"]
    frames, own, j = problem.frame_positions(fl, taus)
    xyz = fl.P[own, 0, j]
    n_obs = 2 * len(problem.frames)
    wr = sol.r[:n_obs]
    dof = max(n_obs - problem.chain.n, 1)
    s2 = max(float(wr @ wr) / dof, 1.0) * (inflation * cal.scale)**2
    A = (sol.J.T @ sol.J).toarray()
    try:
        A_inv = np.linalg.pinv(A, hermitian=True)
    except np.linalg.LinAlgError:
        return None
    cov = A_inv * s2
    dP = (fl.P[own, 1:, j] - fl.P[own, :1, j]) / EPS[None, :, None]             # (M, N_IN, 3)
    Jp = np.einsum("mkd,mkc->mdc", dP, problem.M[own])                          # (M, 3, 11)
    cam_cov = problem.obs.camera.pose_covariance()
    cam_jac = None if cam_cov is None else camera_response(problem, sol, A_inv, Jp, problem.cols[own])
    ray = xyz - problem.obs.camera.centre
    ray /= np.maximum(np.linalg.norm(ray, axis=1), 1e-9)[:, None]
    cues = depth_cues(sol, A_inv, Jp, problem.cols[own], ray, own)
    if cal.along_scale != 1.0:
        Jp = np.einsum("mij,mjc->mic", cal.shape(ray), Jp)                      # the width along the ray apart
    t = np.min(np.abs(frames[:, None] - taus[None, :]), axis=1) / problem.fps          # (M,) s
    free = np.array([f.end is None for f in problem.chain.flights], bool)[own]
    along = (cal.along_ray_rate(free) * t)[:, None] * ray
    chi2 = flight_chi2(problem, taus)
    return FrameErrorModel(frames, xyz, own, Jp, problem.cols[own], cov, floor_m**2 + cal.floor_m**2, along,
                           free, t, ray, chi2, cal.flight_factor(chi2)[own], cam_jac, cam_cov, cues)


#: the fit's evidence on a flight's depth besides its 2D track (``_Rows.group``) → words for the report
DEPTH_CUES = {"bounce": "the bounce (its impact model)", "timing": "the events' timing (the flight time)",
              "hitter": "the racket hit (the hitter's position and reach)", "court": "the court (floor and walls)",
              "picture edge": "where the ball left the picture", "net": "the net",
              "free end": "the free end's speed prior", "spin": "the spin prior", "drag": "the drag prior"}
#: frames per flight whose along-ray σ is compared (evenly spaced: the cost stays small on long flights)
DEPTH_CUE_FRAMES = 8
#: a σ ratio beyond this: without the cue the depth is not determined
UNDETERMINED_RATIO = 100.0


def depth_cues(sol: Solution, A_inv: np.ndarray, Jp: np.ndarray, cols: np.ndarray, ray: np.ndarray,
               own: np.ndarray) -> dict[int, dict[str, float]]:
    """Per chain flight (``own``: (M,) each frame's flight), how much each piece of evidence besides the 2D
    track pins its depth: the ratio of the along-ray σ without that evidence (its rows of the fit's Jacobian
    removed: (A − J_gᵀJ_g)⁻¹ by the Woodbury identity) to the σ with everything, on up to
    :data:`DEPTH_CUE_FRAMES` of its frames; ``inf`` when the depth is not determined without it. Only the
    cues of :data:`DEPTH_CUES` that the fit used. ``Jp`` (M, 3, 11) on θ columns ``cols`` (M, 11), ``ray`` (M,
    3) unit lines of sight, ``A_inv`` (JᵀJ)⁻¹."""
    rows: dict[str, list[int]] = {}
    for m0, R, g in sol.aux.get("groups", []):
        if g in DEPTH_CUES:
            rows.setdefault(g, []).extend(range(m0, m0 + R))
    # per cue, once for every flight: its rows G (R_g, n) and I − G A⁻¹ Gᵀ = V diag(w) Vᵀ (Woodbury's middle)
    groups = {}
    for g, rws in rows.items():
        G = sol.J[rws].toarray()
        w, V = np.linalg.eigh(np.eye(len(rws)) - G @ A_inv @ G.T)
        groups[g] = (G, np.maximum(w, 1e-12), V)
    out: dict[int, dict[str, float]] = {}
    n = A_inv.shape[0]
    for k in np.unique(own):
        idx = np.flatnonzero(own == k)
        idx = idx[np.unique(np.linspace(0, len(idx) - 1, min(DEPTH_CUE_FRAMES, len(idx))).round().astype(int))]
        a = np.zeros((len(idx), n))                                   # (F, n): d(depth along the ray)/dθ
        np.add.at(a, (np.arange(len(idx))[:, None], cols[idx]), np.einsum("fd,fdc->fc", ray[idx], Jp[idx]))
        Ba = A_inv @ a.T                                              # (n, F)
        base = float(np.mean(np.einsum("fn,nf->f", a, Ba)))
        if not base > 0:
            continue
        ratios = {}
        for g, (G, w, V) in groups.items():
            u = G @ Ba                                                # (R_g, F)
            if not np.any(np.abs(u) > 1e-12 * max(np.abs(a).max(), 1.0)):
                continue                                              # these rows do not touch the depth here
            extra = float(np.mean(np.sum((V.T @ u) ** 2 / w[:, None], axis=0)))
            r = float(np.sqrt((base + extra) / base))
            ratios[g] = r if r < UNDETERMINED_RATIO else float("inf")
        out[int(k)] = ratios
    return out


def depth_report(ratios: dict[str, float], threshold: float = 1.25) -> str:
    """One line on what decided a flight's depth: the cue whose absence widens the along-ray σ most (when by
    more than ``threshold``), else the 2D track and the flight's physics."""
    if not ratios or max(ratios.values()) < threshold:
        return "the 2D track and the flight's physics (no other evidence widens its depth σ by 25 % or more)"
    g, r = max(ratios.items(), key=lambda kv: kv[1])
    how = "undetermined" if not np.isfinite(r) else f"{r:.1f}× as wide"
    return f"{DEPTH_CUES[g]} (without it the depth σ would be {how})"


#: finite-difference steps of the camera pose (:data:`inference.camera.POSE_PARAMETERS`): m, rad, px
CAMERA_STEPS = np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5, 0.1])


def camera_response(problem: Problem, sol: Solution, A_inv: np.ndarray, Jp: np.ndarray,
                    cols: np.ndarray) -> np.ndarray | None:
    """(M, 3, 7) how the fitted frame positions move with the camera's pose (implicit function theorem at the
    optimum: dθ/dq = −(JᵀJ)⁻¹ Jᵀ ∂r/∂q, the 2D residuals being the only ones that see the camera; then
    the frames' Jacobians ``Jp`` (M, 3, 11) on their θ columns ``cols`` (M, 11)). ``A_inv``: (JᵀJ)⁻¹. A fitted
    point behind the camera contributes nothing; None when the result is not finite."""
    cam = problem.obs.camera
    fl, taus = sol.aux["flights"], sol.aux["taus"]
    own_o = problem.owners(problem.frames, taus)
    pts = fl.P[own_o, 0, problem.index(fl, own_o, problem.frames)]              # (F, 3) fitted, at the 2D points
    w = problem.weights / problem.cfg.pixel_sigma
    dr = np.zeros((2 * len(pts), 7))
    for k, h in enumerate(CAMERA_STEPS):
        dq = np.zeros(7)
        dq[k] = h
        d = (cam.perturbed(dq).project(pts) - cam.perturbed(-dq).project(pts)) / (2 * h)
        dr[:, k] = (np.nan_to_num(d) * w[:, None]).reshape(-1)
    n_obs = 2 * len(problem.frames)
    dtheta = -A_inv @ (sol.J[:n_obs].T @ dr)                                     # (n, 7)
    out = np.einsum("mdc,mck->mdk", Jp, dtheta[cols])
    return out if np.all(np.isfinite(out)) else None


def flight_chi2(problem: Problem, taus: np.ndarray) -> np.ndarray:
    """(flights,) each flight's mean squared normalised reprojection residual per 2D coordinate (≈ 1 when the
    flight model explains its track to the 2D noise; NaN without 2D points)."""
    nf = len(problem.chain.flights)
    own = problem.owners(problem.frames, taus)
    live = problem.weights > 0
    r2 = np.bincount(own[live], problem.last_norm[live] ** 2, minlength=nf)
    n = np.bincount(own[live], minlength=nf)
    with np.errstate(invalid="ignore", divide="ignore"):
        return r2 / (2.0 * n)
