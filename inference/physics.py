"""Ball flight dynamics: gravity, quadratic drag, Magnus lift and slowly decaying spin, with a fixed-step
RK4 integrator vectorised over a batch of balls.

Model (court frame, SI units, z up)::

    dp/dt = v
    dv/dt = g + a_drag + a_magnus,   g = (0, 0, -gravity)
    a_drag   = -k |v| v                                   k = BallConstants.drag_k  (1/m)
    a_magnus = k_L C_L(S) |v|² (ω × v) / |ω × v|          k_L = ρ A / (2 m)         (1/m)
    dω/dt = -ω / τ                                         τ = spin_decay_time (s)

The lift coefficient saturates with the spin parameter ``S = r |ω⊥| / |v|`` (ω⊥: the spin component
perpendicular to v, the only one that lifts)::

    C_L(S) = C_L,max · S / (S + S_half)

``C_L,max`` is the court YAML's ``lift_coefficient`` and ``S_half`` (default 0.1) the spin parameter at
which half of it is reached: a slowly spinning ball gets the classic linear Magnus force
``k_L C_L,max r / S_half · (ω × v)``, a fast-spinning one the constant-C_L force. ``S_half = 0`` gives the
constant-C_L model for any non-zero spin. Since ``S |v|² / |ω × v| = r``, the Magnus acceleration is
``k_L C_L,max r / (S + S_half) · (ω × v)``, which has no singularity at ω ∥ v or ω = 0.

The spin decays with a time constant of 25 s by default (about 4 % per second, as measured for tennis
balls in flight); over one shot it barely changes.

Every function accepts batches: arrays shaped (B, 3). The same component-wise code also runs on plain
Python floats, which is what a single ball (B = 1) uses: it is ~20× faster than NumPy on size-1 arrays,
and it is the same arithmetic, so a batch equals its balls integrated one at a time. The kernels use
arithmetic only, so :func:`rk4_step` also runs on torch tensors (gradients through a flight).

Example:
    >>> model = FlightModel.from_ball(load_court("padel").ball)
    >>> flight = integrate(p0, v0, w0, duration=1.0, model=model)      # (B, 3) each
    >>> flight.pos.shape                                                # (601, B, 3) at 1/600 s
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from inference.court import BallConstants

#: Default integration substep (s): at least 10 samples per frame up to 60 fps.
DEFAULT_DT = 1.0 / 600.0
#: Guard against 0/0 in the Magnus term (ω = 0 or ω ∥ v).
_TINY = 1e-300


@dataclass(frozen=True)
class FlightModel:
    """Constants of the flight model (see the module docstring).

    Attributes:
        gravity: m/s².
        drag_k: k of ``a_drag = -k |v| v`` (1/m).
        lift_k: ``k_L C_L,max`` = ρ A C_L,max / (2 m) (1/m); 0 disables Magnus.
        radius: ball radius (m), for the spin parameter.
        lift_half_spin: S_half of ``C_L(S) = C_L,max S / (S + S_half)``; 0 = constant C_L.
        spin_decay_time: τ of ``dω/dt = -ω/τ`` (s); ``inf`` = no decay.
    """

    gravity: float = 9.81
    drag_k: float = 0.0
    lift_k: float = 0.0
    radius: float = 0.033
    lift_half_spin: float = 0.1
    spin_decay_time: float = 25.0

    @classmethod
    def from_ball(cls, ball: BallConstants, **overrides: float) -> FlightModel:
        """The model of a court's ball; ``overrides`` replace any attribute (e.g. ``drag_k=0``)."""
        lift_k = 0.5 * ball.air_density * ball.area * ball.lift_coefficient / ball.mass
        model = cls(gravity=ball.gravity, drag_k=ball.drag_k, lift_k=lift_k, radius=ball.radius)
        return replace(model, **overrides)

    def vacuum(self) -> FlightModel:
        """The same model without air: gravity only."""
        return replace(self, drag_k=0.0, lift_k=0.0)

    @property
    def spin_rate(self) -> float:
        """λ = 1/τ (1/s)."""
        return 0.0 if np.isinf(self.spin_decay_time) else 1.0 / self.spin_decay_time

    def kernel(self) -> tuple[float, ...]:
        """The constants as plain floats for the component kernels (compute once, pass to rk4_step):
        (gravity, drag_k, k_L C_L,max r, S_half, r, λ)."""
        return (
            float(self.gravity),
            float(self.drag_k),
            float(self.lift_k * self.radius),
            float(self.lift_half_spin),
            float(self.radius),
            self.spin_rate,
        )

    def acceleration(self, vel: np.ndarray, spin: np.ndarray) -> np.ndarray:
        """(B, 3) velocities (m/s) and spins (rad/s) → (B, 3) accelerations (m/s²)."""
        v = np.atleast_2d(np.asarray(vel, dtype=float))
        w = np.atleast_2d(np.asarray(spin, dtype=float))
        return np.stack(_acceleration(*v.T, *w.T, self.kernel()), axis=-1)


def _acceleration(vx, vy, vz, wx, wy, wz, c):
    """Acceleration components from velocity and spin components (floats or equal-shape arrays)."""
    gravity, drag_k, magnus_k, s_half, radius, _ = c
    v2 = vx * vx + vy * vy + vz * vz
    cx = wy * vz - wz * vy
    cy = wz * vx - wx * vz
    cz = wx * vy - wy * vx
    s = radius * (cx * cx + cy * cy + cz * cz) ** 0.5 / (v2 + _TINY)  # spin parameter r|ω⊥|/|v|
    m = magnus_k / (s + s_half + _TINY)
    d = -drag_k * v2**0.5
    return d * vx + m * cx, d * vy + m * cy, d * vz + m * cz - gravity


def spin_factors(h, lam: float) -> tuple:
    """RK4 stage factors of the spin decay for a step ``h`` (a float or a (B,) array; see :func:`rk4_step`)."""
    return _spin_factors.__wrapped__(h, lam)


@lru_cache(maxsize=256)
def _spin_factors(h: float, lam: float) -> tuple[float, float, float, float]:
    """RK4 stage factors of the linear spin decay dω/dt = -λω: ω at stages 2, 3, 4 and after the step."""
    q = h * lam
    f2 = 1.0 - 0.5 * q
    f3 = 1.0 - 0.5 * q * f2
    f4 = 1.0 - q * f3
    return f2, f3, f4, 1.0 - q + q * q / 2.0 - q**3 / 6.0 + q**4 / 24.0


def rk4_step(state: tuple, h: float, c: tuple[float, ...], factors: tuple | None = None) -> tuple:
    """One RK4 step of size ``h`` (s) on a 9-component state.

    Args:
        state: (x, y, z, vx, vy, vz, wx, wy, wz), each a float or an array of one shape (B,).
        h: step (s), > 0; a float, or a (B,) array of per-ball steps.
        c: ``FlightModel.kernel()``.
        factors: ``spin_factors(h, c[5])`` when the caller repeats one ``h`` (saves recomputing them).
    Returns:
        the state after ``h``, same layout.
    """
    x, y, z, vx, vy, vz, wx, wy, wz = state
    if factors is not None:
        f2, f3, f4, fn = factors
    elif isinstance(h, np.ndarray):  # one step size per ball
        f2, f3, f4, fn = _spin_factors.__wrapped__(h, c[5])
    else:
        f2, f3, f4, fn = _spin_factors(h, c[5])
    hh = 0.5 * h
    ax1, ay1, az1 = _acceleration(vx, vy, vz, wx, wy, wz, c)
    ax2, ay2, az2 = _acceleration(vx + hh * ax1, vy + hh * ay1, vz + hh * az1, wx * f2, wy * f2, wz * f2, c)
    ax3, ay3, az3 = _acceleration(vx + hh * ax2, vy + hh * ay2, vz + hh * az2, wx * f3, wy * f3, wz * f3, c)
    ax4, ay4, az4 = _acceleration(vx + h * ax3, vy + h * ay3, vz + h * az3, wx * f4, wy * f4, wz * f4, c)
    h6 = h / 6.0
    hp = h * h6  # position: x + h v + h²/6 (a1 + a2 + a3), exact RK4 for dp/dt = v
    return (
        x + h * vx + hp * (ax1 + ax2 + ax3),
        y + h * vy + hp * (ay1 + ay2 + ay3),
        z + h * vz + hp * (az1 + az2 + az3),
        vx + h6 * (ax1 + 2.0 * (ax2 + ax3) + ax4),
        vy + h6 * (ay1 + 2.0 * (ay2 + ay3) + ay4),
        vz + h6 * (az1 + 2.0 * (az2 + az3) + az4),
        wx * fn,
        wy * fn,
        wz * fn,
    )


def rk4_path(state: tuple, h: np.ndarray, c: tuple, factors: tuple, nodes: int, substeps: int
             ) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Positions and velocities of a batch at ``nodes`` grid points, ``substeps`` :func:`rk4_step` steps of ``h``
    apart: the loop a multiple shooting fit runs for every flight and every perturbation.

    Args:
        state: 9-component state of (B,) arrays at the first grid point.
        h: (B,) step per ball (s; negative integrates backwards); c: ``FlightModel.kernel()``, whose drag may be a
            (B,) array (one scale per ball); factors: ``spin_factors(h, c[5])``.
    Returns:
        ``P (nodes, 3, B)``, ``V (nodes, 3, B)`` and the state after the last node's steps (the last node's).

    With numba installed the loop is compiled (one pass over the balls, the same arithmetic as
    :func:`rk4_step`: the results agree to the last bits; ~20× faster at a 3D fit's batch sizes); without it,
    :func:`rk4_step` runs on the arrays.
    """
    B = len(state[0])
    kernel = path_kernel()
    if kernel is not None and nodes > 0:
        st = np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(v, float), (B,)) for v in state]))
        hb = np.ascontiguousarray(np.broadcast_to(np.asarray(h, float), (B,)))
        fb = np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(f, float), (B,)) for f in factors]))
        drag = np.ascontiguousarray(np.broadcast_to(np.asarray(c[1], float), (B,)))
        P, V = np.empty((nodes, 3, B)), np.empty((nodes, 3, B))
        kernel(st, hb, fb, float(c[0]), drag, float(c[2]), float(c[3]), float(c[4]), nodes, substeps, P, V)
        return P, V, tuple(st[k] for k in range(9))
    P, V = np.empty((nodes, 3, B)), np.empty((nodes, 3, B))
    for j in range(nodes):
        P[j] = state[:3]
        V[j] = state[3:6]
        if j < nodes - 1:
            for _ in range(substeps):
                state = rk4_step(state, h, c, factors)
    return P, V, state


def _compile_path_kernel():
    """The numba kernel of :func:`rk4_path` (None without numba); compiled on first use, cached on disk."""
    try:
        from numba import njit
    except ImportError:  # numba is optional: the NumPy loop gives the same figures, slower
        return None
    import math

    tiny = _TINY

    @njit(cache=True, inline="always")
    def accel(vx, vy, vz, wx, wy, wz, gravity, drag_k, magnus_k, s_half, radius):  # pragma: no cover (compiled)
        v2 = vx * vx + vy * vy + vz * vz
        cx = wy * vz - wz * vy
        cy = wz * vx - wx * vz
        cz = wx * vy - wy * vx
        s = radius * math.sqrt(cx * cx + cy * cy + cz * cz) / (v2 + tiny)
        m = magnus_k / (s + s_half + tiny)
        d = -drag_k * math.sqrt(v2)
        return d * vx + m * cx, d * vy + m * cy, d * vz + m * cz - gravity

    @njit(cache=True)
    def kernel(st, h, f, gravity, drag, magnus_k, s_half, radius, nodes, substeps, P, V):  # pragma: no cover
        for b in range(st.shape[1]):
            x, y, z, vx, vy, vz, wx, wy, wz = st[0, b], st[1, b], st[2, b], st[3, b], st[4, b], st[5, b], \
                st[6, b], st[7, b], st[8, b]
            hs, hh, h6 = h[b], 0.5 * h[b], h[b] / 6.0
            hp = hs * h6
            f2, f3, f4, fn = f[0, b], f[1, b], f[2, b], f[3, b]
            dk = drag[b]
            for j in range(nodes):
                P[j, 0, b], P[j, 1, b], P[j, 2, b] = x, y, z
                V[j, 0, b], V[j, 1, b], V[j, 2, b] = vx, vy, vz
                if j == nodes - 1:
                    break
                for _ in range(substeps):
                    ax1, ay1, az1 = accel(vx, vy, vz, wx, wy, wz, gravity, dk, magnus_k, s_half, radius)
                    ax2, ay2, az2 = accel(vx + hh * ax1, vy + hh * ay1, vz + hh * az1, wx * f2, wy * f2, wz * f2,
                                          gravity, dk, magnus_k, s_half, radius)
                    ax3, ay3, az3 = accel(vx + hh * ax2, vy + hh * ay2, vz + hh * az2, wx * f3, wy * f3, wz * f3,
                                          gravity, dk, magnus_k, s_half, radius)
                    ax4, ay4, az4 = accel(vx + hs * ax3, vy + hs * ay3, vz + hs * az3, wx * f4, wy * f4, wz * f4,
                                          gravity, dk, magnus_k, s_half, radius)
                    x, y, z = (x + hs * vx + hp * (ax1 + ax2 + ax3), y + hs * vy + hp * (ay1 + ay2 + ay3),
                               z + hs * vz + hp * (az1 + az2 + az3))
                    vx, vy, vz = (vx + h6 * (ax1 + 2.0 * (ax2 + ax3) + ax4), vy + h6 * (ay1 + 2.0 * (ay2 + ay3) + ay4),
                                  vz + h6 * (az1 + 2.0 * (az2 + az3) + az4))
                    wx, wy, wz = wx * fn, wy * fn, wz * fn
            st[0, b], st[1, b], st[2, b], st[3, b], st[4, b], st[5, b] = x, y, z, vx, vy, vz
            st[6, b], st[7, b], st[8, b] = wx, wy, wz

    return kernel


_UNSET = object()
_path_kernel = _UNSET  # numba is imported on the first flight integrated, not with this module


def path_kernel():
    """The compiled :func:`rk4_path` kernel, or None (no numba, or it could not compile: the NumPy loop runs)."""
    global _path_kernel
    if _path_kernel is _UNSET:
        try:
            _path_kernel = _compile_path_kernel()
        except Exception:  # noqa: BLE001 — a broken numba install must not stop the library
            _path_kernel = None
    return _path_kernel


def state_from_arrays(pos: np.ndarray, vel: np.ndarray, spin: np.ndarray) -> tuple:
    """(B, 3) arrays → 9-component state; a single ball (B = 1 or shape (3,)) becomes plain floats."""
    arr = np.concatenate([np.atleast_2d(np.asarray(a, dtype=float)) for a in (pos, vel, spin)], axis=1)
    if len(arr) == 1:
        return tuple(float(a) for a in arr[0])
    return tuple(np.ascontiguousarray(arr[:, k]) for k in range(9))


def state_to_array(state: tuple) -> np.ndarray:
    """9-component state → (B, 9) array [pos | vel | spin]."""
    return np.stack([np.atleast_1d(np.asarray(s, dtype=float)) for s in state], axis=-1)


@dataclass(frozen=True)
class FlightSamples:
    """A batch of integrated flights.

    Attributes:
        t: (S,) sample times (s).
        pos, vel, spin: (S, B, 3) ball centre (m), velocity (m/s), angular velocity (rad/s).
    """

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    spin: np.ndarray


def integrate(
    pos: np.ndarray,
    vel: np.ndarray,
    spin: np.ndarray,
    duration: float,
    model: FlightModel,
    dt: float = DEFAULT_DT,
    every: int = 1,
    t0: float = 0.0,
) -> FlightSamples:
    """Fixed-step RK4 of B free flights (no contacts), sampled every ``every`` steps.

    Args:
        pos, vel, spin: (B, 3) initial states (or (3,) for one ball).
        duration: seconds to integrate; the last step is shortened to end exactly there.
        model: flight constants.
        dt: RK4 step (s).
        every: keep one sample every ``every`` steps (the end is always kept).
        t0: time of the initial state.
    Returns:
        :class:`FlightSamples` with S = ceil(duration/dt)/every + 1 samples (t0 included).
    """
    if dt <= 0 or duration < 0:
        raise ValueError(f"need dt > 0 and duration >= 0, got dt={dt}, duration={duration}")
    n_full = int(np.floor(duration / dt + 1e-9))
    steps = [dt] * n_full
    rest = duration - n_full * dt
    if rest > 1e-12:
        steps.append(rest)
    c = model.kernel()
    state = state_from_arrays(pos, vel, spin)
    times, rows, t = [t0], [state], t0
    for i, h in enumerate(steps):
        state = rk4_step(state, h, c)
        t += h
        if (i + 1) % every == 0 or i == len(steps) - 1:
            times.append(t)
            rows.append(state)
    arr = np.stack([state_to_array(s) for s in rows])  # (S, B, 9)
    return FlightSamples(np.asarray(times), arr[..., 0:3], arr[..., 3:6], arr[..., 6:9])


#: I = α m r² of a thin-walled hollow ball (tennis, padel, table tennis).
HOLLOW_SPHERE = 2.0 / 3.0


def bounce(vel: np.ndarray, spin: np.ndarray, normal: np.ndarray, restitution, friction, radius: float,
           inertia_factor: float = HOLLOW_SPHERE) -> tuple[np.ndarray, np.ndarray]:
    """Rigid-ball impact on a rigid plane, vectorised: normal restitution and Coulomb friction.

    The normal velocity is reversed and scaled by ``restitution`` e. The tangential impulse is the one that
    stops the contact point sliding (the ball leaves rolling), capped by friction μ (1 + e) |v_n| (the ball
    keeps sliding); it changes the spin by the matching torque.

    Args:
        vel, spin: (B, 3) velocity (m/s) and angular velocity (rad/s) just before the contact.
        normal: (B, 3) or (3,) unit normals pointing towards the ball.
        restitution, friction: scalars or (B,) e and μ.
        radius: ball radius (m); inertia_factor: α of I = α m r².
    Returns:
        (vel, spin), each (B, 3), just after the contact.
    """
    v = np.atleast_2d(np.asarray(vel, dtype=float))
    w = np.atleast_2d(np.asarray(spin, dtype=float))
    n = np.broadcast_to(np.asarray(normal, dtype=float), v.shape)
    e = np.asarray(restitution, dtype=float).reshape(-1, 1) if np.ndim(restitution) else float(restitution)
    mu = np.asarray(friction, dtype=float).reshape(-1) if np.ndim(friction) else float(friction)
    vn = np.einsum("bi,bi->b", v, n)[:, None]
    vt = v - vn * n
    slip = vt - radius * np.cross(w, n)                     # tangential velocity of the contact point
    grip = inertia_factor / (1.0 + inertia_factor)
    limit = mu * (1.0 + np.reshape(e, -1)) * np.abs(vn[:, 0])
    speed = np.linalg.norm(slip, axis=1)
    scale = np.where(grip * speed <= limit, grip, limit / np.maximum(speed, 1e-12))
    j = -scale[:, None] * slip                              # tangential impulse / mass
    new_v = vt + j - e * vn * n
    new_w = w - np.cross(n, j) / (inertia_factor * radius)
    return new_v, new_w
