"""The default reconstruction: the whole rally fitted jointly.

Multiple shooting over the rally's flights. Unknowns: each contact's sub-frame time ``τ_c`` and point
``C_c`` (two in-plane coordinates for a floor/wall/net contact, a free 3D point with height and
player limits for a racket hit), each flight's launch velocity ``v_s`` and spin ``ω_s``. Each flight
is integrated (RK4 with drag and Magnus, :mod:`inference.physics`) from ``(C_s, v_s, ω_s)`` at
``τ_s``, all flights and their finite-difference perturbations in one vectorised batch. Residuals:

* reprojection of the flight at every observed frame (robust: Huber weights, iteratively reweighted),
* continuity: flight ``s`` ends at ``C_{s+1}`` at ``τ_{s+1}`` (consecutive flights share contacts),
* restitution bounds at floor/wall contacts (the material's normal restitution ± a margin),
* net clearance for flights with no net contact,
* weak priors on ``τ_c`` (near the event frame) and on spin (spin only where it reduces error).

Levenberg-Marquardt on the dense normal equations (a few hundred unknowns at most). The Gauss-Newton
covariance gives each frame's 1-σ position uncertainty. Segments whose contact cannot be placed (the
line of sight misses the surface) or with too few 2D points split the rally into chains that are fitted
separately; they are reported with the reason.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from inference.physics import FlightModel, rk4_step

from .observations import ContactPrior, Observations, Segment, contact_priors
from .plausibility import implausible, summary
from .results import RallyFit, SegmentFit


@dataclass(frozen=True)
class JointConfig:
    """Weights and limits of the joint fit (σ's are the scale of each residual)."""

    pixel_sigma: float = 2.0          # px, 2D measurement noise
    huber_k: float = 3.0              # reprojection residuals beyond k σ are down-weighted
    continuity_sigma: float = 0.005   # m
    tau_sigma: float = 2.0            # frames, prior on the contact time around the event frame
    tau_window: float = 2.5           # frames, the contact time stays within the event frame ± this
    spin_sigma: float = 250.0         # rad/s, weak prior pulling spin to 0 (tennis topspin reaches ~300)
    restitution_margin: float = 0.2   # allowed deviation from the material's restitution
    restitution_sigma: float = 0.05
    net_sigma: float = 0.02           # m
    limit_sigma: float = 0.05         # m, hinge penalties of the hit limits
    fit_spin: bool = True
    fit_drag: bool = False            # fit a drag multiplier per flight (prior 1 ± drag_sigma)
    drag_sigma: float = 0.2
    max_iter: int = 60               # LM iterations per pass
    irls_passes: int = 3              # robust reweighting passes (the later ones only with outliers)
    reweighted_iter: int = 6          # LM iterations of each reweighted pass
    tolerance: float = 1e-4           # stop when the cost falls by less than this fraction
    min_observed: int = 3             # 2D points (contact frames included) a flight needs
    steps_per_second: float = 20.0    # RK4 steps per second at least (one per frame is < 1 µm off at 30 fps)
    hit_candidates: int = 48          # depths tried when initialising a racket hit
    rms_fail_factor: float = 4.0      # a flight with reprojection RMS above this × pixel_sigma is failed


# ---------------------------------------------------------------------------------------------------
# Parameter layout
# ---------------------------------------------------------------------------------------------------
@dataclass
class _Contact:
    prior: ContactPrior
    tau: int                    # index of τ in θ
    coords: list[int]           # indices of the point's coordinates in θ (2 on a plane, 3 for a hit)
    origin: np.ndarray          # (3,) point = origin + basis @ coords
    basis: np.ndarray           # (3, 2|3)
    normal: np.ndarray | None   # plane normal pointing to the ball's side (None for hits)
    restitution: float | None


@dataclass
class _Chain:
    """Consecutive flights fitted together: contacts 0..K, flights 0..K-1."""

    segments: list[Segment]
    contacts: list[_Contact] = field(default_factory=list)
    vel: list[list[int]] = field(default_factory=list)
    spin: list[list[int] | None] = field(default_factory=list)
    drag: list[int | None] = field(default_factory=list)
    n: int = 0

    def point(self, theta: np.ndarray, c: int) -> np.ndarray:
        ct = self.contacts[c]
        return ct.origin + ct.basis @ theta[ct.coords]


def _plane_contact(prior: ContactPrior, radius: float, camera_centre: np.ndarray) -> tuple:
    pl = prior.plane
    n = pl.normal
    if pl.two_sided and (camera_centre - pl.origin) @ n < 0:
        n = -n
    origin = pl.origin + radius * n
    basis = np.stack([pl.u, pl.v], axis=1)
    coords0 = basis.T @ (prior.point - origin)
    return origin, basis, n, coords0


def _build_chain(obs: Observations, segs: list[Segment], priors: list[ContactPrior], cfg: JointConfig) -> tuple:
    """Lay out θ for one chain and return it with the initial θ."""
    chain = _Chain(segs)
    theta: list[float] = []
    court = obs.court
    first = segs[0].index
    for c in range(len(segs) + 1):
        prior = priors[first + c]
        tau = len(theta)
        theta.append(float(prior.frame))
        if prior.kind == "plane":
            origin, basis, normal, coords0 = _plane_contact(prior, court.ball.radius, obs.camera.centre)
            e = court.materials[prior.plane.material].restitution
        else:
            origin, basis, normal, coords0, e = np.zeros(3), np.eye(3), None, prior.point, None
        idx = list(range(len(theta), len(theta) + len(coords0)))
        theta.extend(np.asarray(coords0, float).tolist())
        chain.contacts.append(_Contact(prior, tau, idx, origin, basis, normal, e))
    for _ in segs:
        chain.vel.append(list(range(len(theta), len(theta) + 3)))
        theta.extend([0.0, 0.0, 0.0])
        if cfg.fit_spin:
            chain.spin.append(list(range(len(theta), len(theta) + 3)))
            theta.extend([0.0, 0.0, 0.0])
        else:
            chain.spin.append(None)
        if cfg.fit_drag:
            chain.drag.append(len(theta))
            theta.append(1.0)
        else:
            chain.drag.append(None)
    chain.n = len(theta)
    return chain, np.array(theta)


# ---------------------------------------------------------------------------------------------------
# Batched flights with finite-difference perturbations
# ---------------------------------------------------------------------------------------------------
N_IN = 11  # flight inputs: C (3), v (3), ω (3), τ (1), drag scale (1)
EPS = np.array([1e-4] * 3 + [1e-4] * 3 + [1e-2] * 3 + [1e-4] + [1e-3])


@dataclass
class _Flights:
    """Positions/velocities at integer frames of each flight (base and perturbed).

    P, V: (S, 1 + N_IN, L, 3) at frames F0[s] + j; end, vend: (S, 1 + N_IN, 3) at τ_{s+1}.
    """

    F0: np.ndarray
    P: np.ndarray
    V: np.ndarray
    end: np.ndarray
    vend: np.ndarray


def _hermite(p0, v0, p1, v1, u, dt):
    """Cubic Hermite position and velocity at fraction u of a step of dt seconds (broadcasting)."""
    u2, u3 = u * u, u * u * u
    pos = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * dt * v0 + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * dt * v1
    vel = ((6 * u2 - 6 * u) * p0 / dt + (3 * u2 - 4 * u + 1) * v0 + (-6 * u2 + 6 * u) * p1 / dt
           + (3 * u2 - 2 * u) * v1)
    return pos, vel


def _integrate(starts: np.ndarray, taus: np.ndarray, tau_end: np.ndarray, F0: np.ndarray, L: int, fps: float,
               model: FlightModel, substeps: int, perturb: bool = True) -> _Flights:
    """Integrate S flights, each with its N_IN forward-difference perturbations, in one batch.

    Args:
        starts: (S, 10) [C | v | ω | drag scale] at τ_s; taus: (S,) τ_s (frames); tau_end: (S,) τ_{s+1}.
        F0: (S,) first frame of each flight's grid (≤ τ_s); L: frames on the grid.
        perturb: also the N_IN forward-difference perturbations of each flight (else only the base).
    """
    S = len(starts)
    V_ = 1 + N_IN if perturb else 1
    base = np.concatenate([starts[:, :9], taus[:, None], starts[:, 9:]], axis=1)  # (S, N_IN)
    inp = np.repeat(base[:, None, :], V_, axis=1)                      # (S, V_, 10)
    if perturb:
        inp[:, 1:, :] += np.diag(EPS)[None]
    inp = inp.reshape(-1, N_IN)
    f0 = np.repeat(F0, V_)
    c = list(model.kernel())
    c[1] = c[1] * inp[:, 10]                                          # per-flight drag
    state = tuple(np.ascontiguousarray(inp[:, k]) for k in range(9))
    state = rk4_step(state, (f0 - inp[:, 9]) / fps, c)                 # to frame F0 (backwards if needed)
    h = 1.0 / (fps * substeps)
    P = np.empty((len(inp), L, 3))
    V = np.empty((len(inp), L, 3))
    for j in range(L):
        P[:, j] = np.stack(state[:3], axis=1)
        V[:, j] = np.stack(state[3:6], axis=1)
        if j < L - 1:
            for _ in range(substeps):
                state = rk4_step(state, h, c)
    P = P.reshape(S, V_, L, 3)
    V = V.reshape(S, V_, L, 3)
    ja = np.clip(np.floor(tau_end).astype(int) - F0, 0, L - 2)
    u = (tau_end - (F0 + ja))[:, None, None]
    rows = np.arange(S)
    end, vend = _hermite(P[rows, :, ja], V[rows, :, ja], P[rows, :, ja + 1], V[rows, :, ja + 1], u, 1.0 / fps)
    return _Flights(F0, P, V, end, vend)


# ---------------------------------------------------------------------------------------------------
# The problem: residuals and Jacobian
# ---------------------------------------------------------------------------------------------------
class _Problem:
    def __init__(self, obs: Observations, chain: _Chain, cfg: JointConfig, model: FlightModel):
        self.obs, self.chain, self.cfg, self.model = obs, chain, cfg, model
        self.fps = obs.fps
        self.substeps = max(1, int(np.ceil(cfg.steps_per_second / obs.fps)))
        self.event_frames = np.array([ct.prior.frame for ct in chain.contacts])
        lo, hi = self.event_frames[0], self.event_frames[-1]
        frames = np.arange(lo, hi + 1)
        seen = np.isfinite(obs.uv[frames]).all(axis=1)
        self.frames = frames[seen]
        self.uv = obs.uv[self.frames]
        self.weights = np.ones(len(self.frames))  # Huber IRLS weights of the reprojection residuals
        net = [p for p in obs.court.planes if p.event == "net"]
        self.net = net[0] if net else None
        self.net_normal = self.net.normal if self.net is not None else None
        self.input_maps = [self._input_map(s) for s in range(len(chain.segments))]

    # --- inputs of each flight and their derivatives wrt θ ------------------------------------------
    def _inputs(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ch = self.chain
        K = len(ch.segments)
        starts = np.zeros((K, 10))
        starts[:, 9] = 1.0
        for s in range(K):
            starts[s, :3] = ch.point(theta, s)
            starts[s, 3:6] = theta[ch.vel[s]]
            if ch.spin[s] is not None:
                starts[s, 6:9] = theta[ch.spin[s]]
            if ch.drag[s] is not None:
                starts[s, 9] = theta[ch.drag[s]]
        taus = np.array([theta[ct.tau] for ct in ch.contacts])
        return starts, taus[:-1], taus[1:]

    def _input_map(self, s: int) -> np.ndarray:
        """(N_IN, n) constant matrix d(flight s's inputs)/dθ."""
        M = np.zeros((N_IN, self.chain.n))
        for k, idx, coef in self._din_dtheta(s):
            M[k, idx] += coef
        return M

    def _din_dtheta(self, s: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """For flight s: (input index k, θ indices, d input_k / d θ[indices]) entries."""
        ch = self.chain
        ct = ch.contacts[s]
        out = [(k, np.array(ct.coords), ct.basis[k]) for k in range(3)]
        out += [(3 + k, np.array([ch.vel[s][k]]), np.ones(1)) for k in range(3)]
        if ch.spin[s] is not None:
            out += [(6 + k, np.array([ch.spin[s][k]]), np.ones(1)) for k in range(3)]
        out.append((9, np.array([ct.tau]), np.ones(1)))
        if ch.drag[s] is not None:
            out.append((10, np.array([ch.drag[s]]), np.ones(1)))
        return out

    def _to_theta(self, s: int, d_in: np.ndarray) -> np.ndarray:
        """(R, N_IN) derivatives wrt flight s's inputs → (R, n) wrt θ."""
        return d_in @ self.input_maps[s]

    def evaluate(self, theta: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None, dict]:
        """Residuals (m,) and, with ``jac``, the Jacobian (m, n) at θ, plus what the outputs need.

        Without ``jac`` only the base flights are integrated (11× less work): LM's trial steps need no
        Jacobian until one is accepted.
        """
        ch, cfg = self.chain, self.cfg
        K = len(ch.segments)
        starts, taus, tau_end = self._inputs(theta)
        F0 = np.minimum(np.floor(taus), self.event_frames[:-1]).astype(int)
        F1 = np.maximum(np.ceil(tau_end), self.event_frames[1:]).astype(int) + 1
        L = int((F1 - F0).max()) + 1
        fl = _integrate(starts, taus, tau_end, F0, L, self.fps, self.model, self.substeps, perturb=jac)
        rows_r: list[np.ndarray] = []
        rows_J: list[np.ndarray] = []

        def add(r: np.ndarray, J_fn) -> None:
            rows_r.append(r)
            if jac:
                rows_J.append(J_fn())

        # reprojection
        all_tau = np.array([theta[ct.tau] for ct in ch.contacts])
        seg_of = np.clip(np.searchsorted(all_tau[1:-1], self.frames, side="right"), 0, K - 1)
        j = self.frames - F0[seg_of]
        pts = fl.P[seg_of, :, j]                                       # (M, 1 | 11, 3)
        pix = self.obs.camera.project(pts.reshape(-1, 3)).reshape(len(j), pts.shape[1], 2)
        r = (pix[:, 0] - self.uv) / cfg.pixel_sigma                    # (M, 2)
        self.last_norm = np.linalg.norm(r, axis=1)
        w = self.weights
        for s in range(K):
            m = np.flatnonzero(seg_of == s)
            if len(m):
                add((r[m] * w[m, None]).reshape(-1), lambda m=m, s=s: self._reproj_jac(pix[m], w[m], s))

        # continuity: flight s ends at contact s+1
        for s in range(K):
            add((fl.end[s, 0] - ch.point(theta, s + 1)) / cfg.continuity_sigma, lambda s=s: self._cont_jac(fl, s))

        # restitution at surface contacts between two flights
        for s in range(1, K):
            ct = ch.contacts[s]
            if ct.normal is None or ct.restitution is None:
                continue
            n = ct.normal
            vin, vout = fl.vend[s - 1, 0], theta[ch.vel[s]]
            a, b = vin @ n, vout @ n
            if a > -0.5:
                continue
            e = -b / a
            lo, hi = ct.restitution - cfg.restitution_margin, ct.restitution + cfg.restitution_margin
            viol = e - hi if e > hi else (e - lo if e < lo else 0.0)
            add(np.array([viol / cfg.restitution_sigma]),
                lambda s=s, n=n, a=a, b=b, vin=vin, viol=viol: self._rest_jac(fl, s, n, a, b, vin, viol))

        # net clearance for flights that do not touch the net
        if self.net is not None:
            for s in range(K):
                if "net" in (ch.segments[s].start_event, ch.segments[s].end_event):
                    continue
                r_net, J_net = self._net_residual(fl, s, taus[s], tau_end[s], jac)
                add(r_net, lambda J_net=J_net: J_net)

        # racket-hit limits (height range, near the hitter) and the contact-time prior
        for ct in ch.contacts:
            if ct.normal is None:
                r_h, J_h = self._hit_limits(theta, ct)
                add(r_h, lambda J_h=J_h: J_h)
            add(np.array([(theta[ct.tau] - ct.prior.frame) / cfg.tau_sigma]),
                lambda ct=ct: self._unit_rows([ct.tau], 1.0 / cfg.tau_sigma))

        # spin prior, drag prior
        for idx in ch.spin:
            if idx is not None:
                add(theta[idx] / cfg.spin_sigma, lambda idx=idx: self._unit_rows(idx, 1.0 / cfg.spin_sigma))
        for idx in ch.drag:
            if idx is not None:
                add(np.array([(theta[idx] - 1.0) / cfg.drag_sigma]),
                    lambda idx=idx: self._unit_rows([idx], 1.0 / cfg.drag_sigma))
        J = np.vstack(rows_J) if jac else None
        return np.concatenate(rows_r), J, {"flights": fl, "seg_of": seg_of, "F0": F0}

    def _unit_rows(self, idx: list[int], scale: float) -> np.ndarray:
        J = np.zeros((len(idx), self.chain.n))
        J[np.arange(len(idx)), idx] = scale
        return J

    def _reproj_jac(self, pix: np.ndarray, w: np.ndarray, s: int) -> np.ndarray:
        """(2m, n) Jacobian of the weighted reprojection residuals of m frames of flight s."""
        dpix = (pix[:, 1:] - pix[:, :1]) / EPS[None, :, None] / self.cfg.pixel_sigma  # (m, N_IN, 2)
        d = dpix.transpose(0, 2, 1).reshape(-1, N_IN)
        return self._to_theta(s, d) * np.repeat(w, 2)[:, None]

    def _cont_jac(self, fl: _Flights, s: int) -> np.ndarray:
        ct = self.chain.contacts[s + 1]
        d_end = (fl.end[s, 1:] - fl.end[s, :1]) / EPS[:, None]           # (N_IN, 3)
        J = self._to_theta(s, d_end.T)
        J[:, ct.tau] += fl.vend[s, 0] / self.fps
        J[:, ct.coords] -= ct.basis
        return J / self.cfg.continuity_sigma

    def _rest_jac(self, fl: _Flights, s: int, n, a, b, vin, viol) -> np.ndarray:
        J = np.zeros((1, self.chain.n))
        if viol != 0.0:
            d_vin = (fl.vend[s - 1, 1:] - vin[None]) / EPS[:, None]       # (N_IN, 3)
            J += self._to_theta(s - 1, (d_vin @ (b / a**2 * n))[None, :])
            J[0, self.chain.vel[s]] += -n / a
        return J / self.cfg.restitution_sigma

    def reweight(self) -> None:
        """Huber weights from the latest evaluation's reprojection residuals (held fixed while LM runs)."""
        k = self.cfg.huber_k
        self.weights = np.where(self.last_norm > k, np.sqrt(k / np.maximum(self.last_norm, 1e-12)), 1.0)

    def _net_residual(self, fl: _Flights, s: int, tau0: float, tau1: float,
                      jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Hinge on the ball's height where the flight crosses the net plane (if it does)."""
        zero = (np.zeros(1), np.zeros((1, self.chain.n)))
        net = self.net
        P = fl.P[s, 0]
        j0 = int(np.ceil(tau0)) - fl.F0[s]
        j1 = int(np.floor(tau1)) - fl.F0[s]
        if j1 - j0 < 1:
            return zero
        d = (P[j0:j1 + 1] - net.origin) @ self.net_normal
        cross = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
        if not len(cross):
            return zero
        k = j0 + int(cross[0])
        f = d[k - j0] / (d[k - j0] - d[k - j0 + 1])
        p = P[k] + f * (P[k + 1] - P[k])
        top = net_height(net, p)
        need = top + self.obs.court.ball.radius
        if p[2] >= need:
            return zero
        if not jac:
            return np.array([(need - p[2]) / self.cfg.net_sigma]), None
        dz = ((1 - f) * (fl.P[s, 1:, k, 2] - P[k, 2]) + f * (fl.P[s, 1:, k + 1, 2] - P[k + 1, 2])) / EPS
        J = -self._to_theta(s, dz[None, :]) / self.cfg.net_sigma
        return np.array([(need - p[2]) / self.cfg.net_sigma]), J

    def _hit_limits(self, theta: np.ndarray, ct: _Contact) -> tuple[np.ndarray, np.ndarray]:
        """Hinges keeping a racket hit within the court's height range and near its hitter."""
        hits = self.obs.court.hits
        p = theta[ct.coords]
        sig = self.cfg.limit_sigma
        r, J = [], []

        def hinge(value, lo, hi, grad):
            viol = value - hi if value > hi else (value - lo if value < lo else 0.0)
            row = np.zeros(self.chain.n)
            if viol:
                row[ct.coords] = grad / sig
            r.append(viol / sig)
            J.append(row)

        # the ball's centre is at least one radius above the floor whatever the YAML's range says
        hinge(p[2], max(hits.height[0], self.obs.court.ball.radius), hits.height[1], np.array([0.0, 0.0, 1.0]))
        if ct.prior.hitter_xy is not None:
            h = ct.prior.hitter_xy
            hinge(p[1] - h[1], hits.offset_y[0], hits.offset_y[1], np.array([0.0, 1.0, 0.0]))
            dxy = p[:2] - h
            dist = float(np.linalg.norm(dxy))
            hinge(dist, 0.0, hits.reach, np.array([*(dxy / max(dist, 1e-9)), 0.0]))
        return np.array(r), np.array(J)


def net_height(net, point: np.ndarray) -> float:
    """Height of the net's top edge at ``point``'s position along the net (from the net polygon)."""
    poly = net.polygon
    top = poly[poly[:, 1] > 1e-6]
    order = np.argsort(top[:, 0])
    u = (point - net.origin) @ net.u
    return float(np.interp(u, top[order, 0], top[order, 1]))


# ---------------------------------------------------------------------------------------------------
# Initialisation
# ---------------------------------------------------------------------------------------------------
def _vacuum_velocity(p0, p1, T, g):
    return (p1 - p0) / T - 0.5 * np.array([0.0, 0.0, -g]) * T


def _parabola_error(obs: Observations, p0: np.ndarray, p1: np.ndarray, f0: int, f1: int) -> np.ndarray:
    """Sum of squared reprojection errors of vacuum parabolas from p0 (…, 3) to p1 (…, 3) over frames f0..f1."""
    frames = np.arange(f0, f1 + 1)
    seen = np.isfinite(obs.uv[frames]).all(axis=1)
    if not seen.any():
        return np.zeros(np.broadcast_shapes(p0.shape, p1.shape)[:-1])
    t = (frames[seen] - f0) / obs.fps
    T = (f1 - f0) / obs.fps
    g = obs.court.ball.gravity
    v = (p1 - p0) / T + 0.5 * g * T * np.array([0.0, 0.0, 1.0])
    pos = p0[..., None, :] + v[..., None, :] * t[:, None] - 0.5 * g * (t**2)[:, None] * np.array([0, 0, 1.0])
    shape = pos.shape
    pix = obs.camera.project(pos.reshape(-1, 3)).reshape(shape[:-1] + (2,))
    err = np.nansum((pix - obs.uv[frames[seen]]) ** 2, axis=-1)
    err = np.where(np.isfinite(pix).all(axis=-1), err, 1e8)
    return err.sum(axis=-1)


def _init_hits(obs: Observations, chain: _Chain, theta: np.ndarray, cfg: JointConfig) -> None:
    """Place each racket hit on its line of sight at the depth whose neighbouring vacuum parabolas best
    explain the 2D track (two sweeps, so neighbouring hits settle together)."""
    hits = obs.court.hits
    for _ in range(2):
        for c, ct in enumerate(chain.contacts):
            if ct.normal is not None:
                continue
            p = theta[ct.coords]
            o = obs.camera.centre
            d = p - o
            d /= np.linalg.norm(d)
            if abs(d[2]) < 1e-6:
                continue
            s_lo, s_hi = sorted(((hits.height[0] - o[2]) / d[2], (hits.height[1] - o[2]) / d[2]))
            s_lo = max(s_lo, 0.5)
            if s_hi <= s_lo:
                continue
            cand = o + np.linspace(s_lo, s_hi, cfg.hit_candidates)[:, None] * d
            if ct.prior.hitter_xy is not None:
                near = np.linalg.norm(cand[:, :2] - ct.prior.hitter_xy, axis=1) <= hits.reach
                cand = cand[near] if near.any() else cand
            err = np.zeros(len(cand))
            if c > 0:
                err += _parabola_error(obs, chain.point(theta, c - 1)[None], cand,
                                       chain.contacts[c - 1].prior.frame, ct.prior.frame)
            if c < len(chain.contacts) - 1:
                err += _parabola_error(obs, cand, chain.point(theta, c + 1)[None],
                                       ct.prior.frame, chain.contacts[c + 1].prior.frame)
            theta[ct.coords] = cand[int(np.argmin(err))]


def _init_velocities(obs: Observations, chain: _Chain, theta: np.ndarray) -> None:
    g = obs.court.ball.gravity
    for s, seg in enumerate(chain.segments):
        T = max(seg.duration_frames, 1) / obs.fps
        theta[chain.vel[s]] = _vacuum_velocity(chain.point(theta, s), chain.point(theta, s + 1), T, g)


def _clamp(chain: _Chain, theta: np.ndarray, cfg: JointConfig) -> np.ndarray:
    """Keep contact times inside their window and in order."""
    theta = theta.copy()
    prev = -np.inf
    for ct in chain.contacts:
        t = np.clip(theta[ct.tau], ct.prior.frame - cfg.tau_window, ct.prior.frame + cfg.tau_window)
        t = max(t, prev + 0.5)
        theta[ct.tau] = t
        prev = t
    return theta


# ---------------------------------------------------------------------------------------------------
# Levenberg-Marquardt
# ---------------------------------------------------------------------------------------------------
def _solve(problem: _Problem, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict, int]:
    """Iteratively reweighted LM: a pass with unit weights, then short passes with Huber weights while
    some 2D points lie beyond ``huber_k`` σ (outliers are down-weighted, not dropped)."""
    theta, r, J, aux, total = _lm(problem, theta, problem.cfg.max_iter)
    for _ in range(problem.cfg.irls_passes - 1):
        problem.reweight()
        if np.all(problem.weights == 1.0):
            break
        theta, r, J, aux, n = _lm(problem, theta, problem.cfg.reweighted_iter)
        total += n
    return theta, r, J, aux, total


#: Levenberg-Marquardt damping: start nearly Gauss-Newton and change it tenfold (on held-out synthetic
#: rallies this lands in better minima, in fewer iterations, than gentler schedules).
LM_LAMBDA0 = 1e-4
LM_FACTOR = 10.0


def _lm(problem: _Problem, theta: np.ndarray, max_iter: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict, int]:
    cfg, chain = problem.cfg, problem.chain
    r, J, aux = problem.evaluate(theta)
    cost = float(r @ r)
    lam = LM_LAMBDA0
    it = 0
    for it in range(max_iter):  # noqa: B007
        A = J.T @ J
        g = J.T @ r
        D = np.diag(np.maximum(np.diag(A), 1e-9))
        improved = False
        for _ in range(8):
            try:
                step = -np.linalg.solve(A + lam * D, g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            cand = _clamp(chain, theta + step, cfg)
            r2, _, _ = problem.evaluate(cand, jac=False)
            cost2 = float(r2 @ r2)
            if np.isfinite(cost2) and cost2 < cost:
                rel = (cost - cost2) / max(cost, 1e-12)
                theta, cost = cand, cost2
                r, J, aux = problem.evaluate(theta)
                lam = max(lam / LM_FACTOR, 1e-9)
                improved = True
                break
            lam *= LM_FACTOR
        if not improved or rel < cfg.tolerance:
            break
    return theta, r, J, aux, it + 1


# ---------------------------------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------------------------------
def _segment_problems(obs: Observations, priors: list[ContactPrior], cfg: JointConfig) -> tuple[dict, list]:
    """Which segments cannot be fitted (and why), and the chains of the others."""
    failed: dict[int, str] = {}
    segs = obs.segments()
    if not _camera_sees_court(obs):
        return {s.index: "the camera does not see the court (no court corner projects into the image)"
                for s in segs}, []
    for s in segs:
        a, b = priors[s.index], priors[s.index + 1]
        bad = [p for p in (a, b) if not p.ok]
        if bad:
            failed[s.index] = f"contact at frame {bad[0].frame} ({bad[0].label}): {bad[0].reason}"
            continue
        frames = s.frames
        n_seen = int(np.isfinite(obs.uv[frames]).all(axis=1).sum())
        if n_seen < cfg.min_observed:
            failed[s.index] = f"only {n_seen} 2D ball positions between frames {s.start} and {s.end}"
    chains, run = [], []
    for s in segs:
        if s.index in failed:
            if run:
                chains.append(run)
            run = []
        else:
            run.append(s)
    if run:
        chains.append(run)
    return failed, chains


def _camera_sees_court(obs: Observations) -> bool:
    sx, sy = obs.court.size
    corners = np.array([[0, 0, 0], [sx, 0, 0], [0, sy, 0], [sx, sy, 0], [sx / 2, sy / 2, 0]], float)
    px = obs.camera.project(corners)
    w, h = obs.camera.image_size
    inside = np.isfinite(px).all(axis=1) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    return bool(inside.any())


def _frame_sigma(problem: _Problem, theta: np.ndarray, J: np.ndarray, r: np.ndarray, aux: dict) -> dict:
    """1-σ position uncertainty (m) per frame from the Gauss-Newton covariance."""
    n_obs = 2 * len(problem.frames)
    dof = max(n_obs - problem.chain.n, 1)
    s2 = max(float(r[:n_obs] @ r[:n_obs]) / dof, 1.0)
    try:
        cov = np.linalg.pinv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        return {}
    fl, out = aux["flights"], {}
    for s in range(len(problem.chain.segments)):
        dP = (fl.P[s, 1:] - fl.P[s, :1]) / EPS[:, None, None]          # (N_IN, L, 3)
        Jp = np.einsum("kjd,kn->jdn", dP, problem.input_maps[s])       # (L, 3, n)
        var = np.einsum("jdn,nm,jdm->j", Jp, cov, Jp)
        for j, v in enumerate(np.sqrt(np.maximum(var, 0.0))):
            out[(s, j)] = float(v)
    return out


def fit_joint(obs: Observations, config: JointConfig | None = None, priors: list[ContactPrior] | None = None,
              model: FlightModel | None = None) -> RallyFit:
    """Reconstruct the whole rally jointly (the default method; see the module docstring)."""
    cfg = config or JointConfig()
    t0 = time.perf_counter()
    model = model or FlightModel.from_ball(obs.court.ball)
    priors = priors if priors is not None else contact_priors(obs)
    failed, chains = _segment_problems(obs, priors, cfg)
    fits: dict[int, SegmentFit] = {i: SegmentFit.failed(s, failed[i]) for i, s in
                                   ((s.index, s) for s in obs.segments()) if i in failed}
    iterations = []
    with threadpool_limits(1):  # small dense solves: BLAS threads only add contention
        fits.update(_fit_chains(obs, chains, priors, cfg, model, iterations))
    limit = cfg.rms_fail_factor * cfg.pixel_sigma
    for i, f in fits.items():
        why = implausible(f, obs.court, limit) if f.ok else ""
        if why:
            fits[i] = SegmentFit.failed(f.segment, why)
        elif f.ok:
            flags = [f"{p.label} at frame {p.frame}: beyond the surface's extent (fitted on the unbounded plane)"
                     for p in (priors[i], priors[i + 1]) if p.outside]
            if flags:
                f.figures["flags"] = flags
    out = RallyFit("joint", obs.fps, [fits[s.index] for s in obs.segments()], time.perf_counter() - t0,
                   extra={"iterations": iterations})
    out.extra["plausibility"] = summary(out, obs, limit)
    return out


def _fit_chains(obs, chains, priors, cfg, model, iterations) -> dict[int, SegmentFit]:
    fits = {}
    for segs in chains:
        chain, theta = _build_chain(obs, segs, priors, cfg)
        _init_hits(obs, chain, theta, cfg)
        _init_velocities(obs, chain, theta)
        problem = _Problem(obs, chain, cfg, model)
        theta, r, J, aux, n_it = _solve(problem, theta)
        iterations.append(n_it)
        fits.update(_chain_fits(problem, theta, r, J, aux, model))
    return fits


def _chain_fits(problem: _Problem, theta: np.ndarray, r: np.ndarray, J: np.ndarray, aux: dict,
                model: FlightModel) -> dict[int, SegmentFit]:
    chain, obs = problem.chain, problem.obs
    fl, F0 = aux["flights"], aux["F0"]
    sigma = _frame_sigma(problem, theta, J, r, aux)
    taus = np.array([theta[ct.tau] for ct in chain.contacts])
    out = {}
    for s, seg in enumerate(chain.segments):
        frames = seg.frames
        # each frame from the flight it belongs to (the contact frame goes to the later flight)
        owner = np.clip(np.searchsorted(taus[1:-1], frames, side="right"), 0, len(chain.segments) - 1)
        owner = np.clip(owner, max(s - 1, 0), min(s + 1, len(chain.segments) - 1))
        j = frames - F0[owner]
        j = np.clip(j, 0, fl.P.shape[2] - 1)
        xyz = fl.P[owner, 0, j]
        sig = np.array([sigma.get((int(o), int(jj)), np.nan) for o, jj in zip(owner, j)])
        seen = np.isfinite(obs.uv[frames]).all(axis=1)
        err = np.linalg.norm(obs.camera.project(xyz[seen]) - obs.uv[frames[seen]], axis=1)
        a, b = chain.contacts[s], chain.contacts[s + 1]
        out[seg.index] = SegmentFit(
            seg, True, frames=frames, xyz=xyz, sigma=sig, start=chain.point(theta, s), end=chain.point(theta, s + 1),
            start_plane=a.prior.plane.name if a.prior.plane else None,
            end_plane=b.prior.plane.name if b.prior.plane else None,
            velocity=theta[chain.vel[s]].copy(),
            spin=theta[chain.spin[s]].copy() if chain.spin[s] is not None else np.zeros(3),
            drag_k=model.drag_k * (theta[chain.drag[s]] if chain.drag[s] is not None else 1.0), reproj_rms_px=float(np.sqrt(np.mean(err**2))) if len(err) else float("nan"),
            n_observed=int(seen.sum()))
    return out
