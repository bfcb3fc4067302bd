"""Event-driven simulation of one ball flight with its contacts on the court's planes.

The flight between contacts is the RK4 drag + Magnus model of :mod:`inference.physics` (fixed substep,
1/600 s by default, i.e. at least 10 samples per frame up to 60 fps). After every chunk of steps the
signed distance of the ball centre to every plane is checked; a contact is the centre reaching one radius
from a plane, moving towards it, at a point whose projection lies within the plane's polygon. Its time is
refined by regula falsi on the length of the last RK4 step (to < 1 µs), the ball is bounced, and the
integration restarts from the contact. The free flights and launch solving for the rally planner
(:func:`free_flight`, :func:`solve_launch`, :func:`lower_to_net_height`) are at the end.

Bounce (:func:`bounce`): a rigid hollow sphere (I = 2/3 m r²) on a rigid plane. The normal velocity is
reversed and scaled by the material's restitution e; the tangential impulse is whatever makes the
contact point stop sliding (grip: the ball leaves rolling), capped by Coulomb friction μ (1 + e) |v_n|
(the ball keeps sliding), and it changes the spin accordingly.

The net (event ``net``): a ball hitting it within its extent bounces with the net material (e ≈ 0.1,
high friction: it loses most of its speed and drops on its side), except when it hits the cord — its
centre within ``net_cord_band`` of the top edge — where it trickles over: it keeps a small forward speed,
pops up, and the net is ignored while it rolls over. Mesh contacts bounce with the mesh material (the
irregular rebound of real mesh is not modelled) and carry the plane's label ``mesh``.

Far from every plane, the steps within which no contact is possible (bounded by the approach speed and
the largest possible acceleration) are integrated without checks.

A floor rebound slower than ``settle_speed`` ends the bouncing: the ball rolls on, slowing down
exponentially, with no further contacts. A ball whose centre drops below z = 0 (outside the floor's
extent: over the glass, beyond the run-off) has left the court and the flight ends.

Example:
    >>> flight = simulate_flight(court, p0, v0, w0, t0=0.0, t_end=3.0, max_ground=2)
    >>> [(round(c.t, 4), c.event) for c in flight.contacts]
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from inference.court import Court, Material, Plane
from inference.physics import DEFAULT_DT, FlightModel, rk4_step
from inference.physics import bounce as impact
from synth.types import Contact

#: Index ranges of the 9-component state rows (x, y, z, vx, vy, vz, wx, wy, wz).
POS, VEL, SPIN = slice(0, 3), slice(3, 6), slice(6, 9)


@dataclass(frozen=True)
class ContactModel:
    """Contact constants that are not properties of a court material.

    Attributes:
        inertia_factor: α of the moment of inertia I = α m r² (2/3: thin hollow sphere).
        settle_speed: a floor rebound with a normal speed below this (m/s) stops bouncing: the ball rolls.
        roll_decay_time: time constant (s) of the rolling ball's slowing down.
        net_cord_band: a net contact this close (m) below the net's top edge trickles over.
        trickle_forward: forward speed kept when trickling over, as a fraction of the normal speed.
        trickle_min_forward: at least this forward speed (m/s) when trickling over.
        trickle_pop: upward speed when trickling over = ``trickle_pop[0] |v_n| + trickle_pop[1]`` (m/s).
        trickle_keep: fraction of the tangential velocity and of the spin kept when trickling over.
        chunk_steps: RK4 steps integrated between two contact checks near a plane; far from all planes
            the steps within which no contact is possible are integrated unchecked (at most max_safe_time).
        time_tol: contact time tolerance (s).
        penetration_tol: a ball already this deep (m) behind a plane's contact distance is not re-bounced.
    """

    inertia_factor: float = 2.0 / 3.0
    settle_speed: float = 0.15
    roll_decay_time: float = 1.5
    net_cord_band: float = 0.04
    trickle_forward: float = 0.08
    trickle_min_forward: float = 0.3
    trickle_pop: tuple[float, float] = (0.15, 0.5)
    trickle_keep: float = 0.3
    chunk_steps: int = 24
    max_safe_time: float = 1.0
    time_tol: float = 1e-7
    penetration_tol: float = 1e-3


@dataclass
class Flight:
    """A simulated flight, sampled at every RK4 substep and at every contact.

    Attributes:
        t: (N,) strictly increasing times (s).
        pos, vel, spin: (N, 3) ball centre (m), velocity (m/s), angular velocity (rad/s); at a contact
            time, the velocity and spin just after the contact.
        contacts: the plane contacts, in time order.
        end: why it stopped: ``time`` (reached t_end), ``ground`` (the max_ground-th floor bounce),
            ``rest`` (rolling when t_end was reached), ``left`` (fell below z = 0 off the floor).
    """

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    spin: np.ndarray
    contacts: list[Contact] = field(default_factory=list)
    end: str = "time"

    def until(self, t_stop: float) -> Flight:
        """The samples and contacts with t ≤ t_stop (a copy)."""
        n = int(np.searchsorted(self.t, t_stop, side="right"))
        return Flight(
            self.t[:n].copy(), self.pos[:n].copy(), self.vel[:n].copy(), self.spin[:n].copy(),
            [c for c in self.contacts if c.t <= t_stop], self.end if n == len(self.t) else "time",
        )


def refine_crossing(
    row: tuple, h: float, kernel: tuple, f: Callable[[tuple], float], f0: float, f1: float, time_tol: float
) -> tuple[float, tuple]:
    """Where within an RK4 step a scalar function of the state crosses zero (Illinois regula falsi).

    Args:
        row: 9-component state at the start of the step; h: the step (s); kernel: ``FlightModel.kernel()``.
        f: the function of a state; f0 = f(row) > 0 ≥ f1 = f(state after h). If f0 ≤ 0, τ = 0.
        time_tol: stop when the bracket is shorter than this (s).
    Returns:
        (τ, state after τ).
    """
    if f0 <= 0.0:
        return 0.0, row
    a, b, fa, fb = 0.0, h, f0, f1
    tau, state, last = h, row, 0
    for _ in range(60):
        tau = (a * fb - b * fa) / (fb - fa)
        state = rk4_step(row, tau, kernel)
        g = f(state)
        if g > 0.0:
            a, fa = tau, g
            if last == 1:
                fb *= 0.5
            last = 1
        else:
            b, fb = tau, g
            if last == -1:
                fa *= 0.5
            last = -1
        if b - a < time_tol or abs(g) < 1e-10:
            break
    return tau, state


def bounce(
    vel: np.ndarray, spin: np.ndarray, normal: np.ndarray, material: Material, radius: float,
    inertia_factor: float = 2.0 / 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Rigid-sphere impact with restitution and Coulomb friction (grip or slide): one contact of
    :func:`inference.physics.bounce`, the model the reconstruction fits.

    Args:
        vel, spin: (3,) velocity (m/s) and angular velocity (rad/s) just before the contact.
        normal: (3,) unit normal of the surface, pointing towards the ball.
        material: restitution e and friction μ.
        radius: ball radius (m).
        inertia_factor: α of I = α m r².
    Returns:
        (vel, spin) (3,) just after the contact.
    """
    v, w = impact(vel, spin, normal, material.restitution, material.friction, radius, inertia_factor)
    return v[0], w[0]


_PLANE_SETS: dict[int, tuple[Court, _PlaneSet]] = {}


@dataclass(frozen=True)
class _PlaneSet:
    """The court's planes as arrays for the contact test: origins, normals (P, 3), two_sided (P,),
    offsets (P,) = origin · normal."""

    planes: tuple[Plane, ...]
    origins: np.ndarray
    normals: np.ndarray
    two_sided: np.ndarray
    offsets: np.ndarray

    @classmethod
    def of(cls, court: Court) -> _PlaneSet:
        """The plane arrays of a court (cached per court object)."""
        cached = _PLANE_SETS.get(id(court))
        if cached is not None and cached[0] is court:
            return cached[1]
        planes = tuple(court.planes)
        normals = np.array([p.normal for p in planes])
        origins = np.array([p.origin for p in planes])
        two_sided = np.array([p.two_sided for p in planes])
        out = cls(planes, origins, normals, two_sided, np.einsum("pk,pk->p", origins, normals))
        _PLANE_SETS[id(court)] = (court, out)
        return out

    def distances(self, pos: np.ndarray) -> np.ndarray:
        """(N, 3) centres → (N, P) signed distances along each plane's normal."""
        return pos @ self.normals.T - self.offsets[None]

    def sides(self, d: np.ndarray) -> np.ndarray:
        """(N, P) signed distances → (N, P) the side the ball is on (+1 for one-sided planes)."""
        return np.where(self.two_sided[None] & (d < 0), -1.0, 1.0)


def _row(*parts: np.ndarray) -> tuple:
    """Concatenate vectors into a 9-component state of plain floats (fast scalar arithmetic)."""
    return tuple(float(x) for part in parts for x in part)


def _cord_up(plane: Plane) -> np.ndarray:
    """(3,) the in-plane axis pointing up (towards the net's top edge)."""
    axis = plane.v if abs(plane.v[2]) >= abs(plane.u[2]) else plane.u
    return axis if axis[2] >= 0 else -axis


class _Simulator:
    """State of one :func:`simulate_flight` call (kept small: plain lists of 9-float rows)."""

    def __init__(self, court: Court, model: FlightModel, cm: ContactModel, dt: float):
        self.court, self.cm, self.dt = court, cm, dt
        self.kernel = model.kernel()
        self.radius = court.ball.radius
        self.planes = _PlaneSet.of(court)
        self.floor = court.planes_for("ground")
        self.ignore_until = np.full(len(self.planes.planes), -np.inf)

    def safe_time(self, row: tuple) -> float:
        """A time (s) within which the ball cannot reach any plane (nor z = 0) from ``row``: for each gap,
        the time to close it at the current approach speed plus the largest possible acceleration
        (gravity, drag and lift at 1.5× the current speed's values)."""
        pos, vel = np.asarray(row[:3]), np.asarray(row[3:6])
        d = self.planes.distances(pos[None])[0]
        side = self.planes.sides(d[None])[0]
        gaps = np.maximum(np.append(side * d - self.radius, pos[2]), 0.0)
        approach = np.maximum(np.append(-side * (self.planes.normals @ vel), -vel[2]), 0.0)
        g, drag_k, magnus_k, _, radius, _ = self.kernel
        accel = 1.5 * (g + (drag_k + magnus_k / radius) * float(vel @ vel))  # C_L(S) <= C_L,max
        # the positive root of gap = u t + a t² / 2, in a cancellation-free form
        return float(np.min(2.0 * gaps / (approach + np.sqrt(approach**2 + 2.0 * accel * gaps) + 1e-12)))

    def advance(self, rows: list, times: list, n: int, t_end: float) -> None:
        """Append up to n RK4 steps of dt to ``rows``/``times``, the last one shortened to end at t_end."""
        dt, kernel, row, t = self.dt, self.kernel, rows[-1], times[-1]
        n_full = min(n, int((t_end - t) / dt + 1e-9))
        for _ in range(n_full):
            row = rk4_step(row, dt, kernel)
            t += dt
            rows.append(row)
            times.append(t)
        if n_full < n and t_end - t > 1e-12:
            rows.append(rk4_step(row, t_end - t, kernel))
            times.append(t_end)

    def gap(self, row: tuple, p: int, side: float) -> float:
        d = float((np.asarray(row[:3]) - self.planes.origins[p]) @ self.planes.normals[p])
        return side * d - self.radius

    def refine(self, row: tuple, h: float, p: int, side: float, g0: float, g1: float) -> tuple[float, tuple]:
        """Time τ ∈ [0, h] after ``row`` where the gap to plane p is 0, and the state then."""
        return refine_crossing(row, h, self.kernel, lambda s: self.gap(s, p, side), g0, g1, self.cm.time_tol)

    def first_contact(self, rows: np.ndarray, times: np.ndarray) -> tuple | None:
        """Earliest valid contact in a chunk of (N, 9) rows at (N,) times: (step index i, τ after times[i],
        plane index, side, state at the contact), or None."""
        d = self.planes.distances(rows[:, POS])
        side = self.planes.sides(d[:-1])
        g0 = side * d[:-1] - self.radius
        g1 = side * d[1:] - self.radius
        hit = (g1 <= 0.0) & (g1 < g0) & (g0 > -self.cm.penetration_tol)
        hit &= times[:-1, None] >= self.ignore_until[None, :]
        for i in np.flatnonzero(hit.any(axis=1)):
            best = None
            row = tuple(float(x) for x in rows[i])
            h = float(times[i + 1] - times[i])
            for p in np.flatnonzero(hit[i]):
                tau, state = self.refine(row, h, int(p), float(side[i, p]), float(g0[i, p]), float(g1[i, p]))
                if best is not None and tau >= best[1]:
                    continue
                if self.planes.planes[p].contains(np.asarray(state[:3]), tol=1e-9)[0]:
                    best = (int(i), tau, int(p), float(side[i, p]), state)
            if best is not None:
                return best
        return None

    def collide(self, state: tuple, t: float, p: int, side: float) -> tuple[tuple, bool]:
        """Apply the contact with plane p; returns the new state and whether the ball now rolls."""
        plane = self.planes.planes[p]
        n = side * self.planes.normals[p]
        pos, vel, spin = np.asarray(state[:3]), np.asarray(state[3:6]), np.asarray(state[6:9])
        material = self.court.materials[plane.material]
        if plane.event == "net" and not plane.contains(pos + self.cm.net_cord_band * _cord_up(plane))[0]:
            vel, spin = self.trickle(vel, spin, n, _cord_up(plane))
            self.ignore_until[p] = t + (2 * self.radius + 0.02) / max(float(-(vel @ n)), 1e-3)
            return _row(pos, vel, spin), False
        vel, spin = bounce(vel, spin, n, material, self.radius, self.cm.inertia_factor)
        rolls = n[2] > 0.9 and float(vel @ n) < self.cm.settle_speed
        if rolls:
            vel = vel - float(vel @ n) * n
        return _row(pos, vel, spin), rolls

    def trickle(self, vel, spin, n, up) -> tuple[np.ndarray, np.ndarray]:
        """Velocity and spin of a ball rolling over the net cord (n: normal towards the ball)."""
        cm = self.cm
        vn = abs(float(vel @ n))
        vt = vel - float(vel @ n) * n
        forward = max(cm.trickle_forward * vn, cm.trickle_min_forward)
        vt = cm.trickle_keep * (vt - float(vt @ up) * up)
        return vt - forward * n + (cm.trickle_pop[0] * vn + cm.trickle_pop[1]) * up, cm.trickle_keep * spin

    def roll(self, state: tuple, t0: float, t_end: float) -> tuple[np.ndarray, np.ndarray]:
        """Rolling on the floor from ``state`` at t0 to t_end: (times (M,), rows (M, 9)), t0 excluded."""
        n_steps = int(np.ceil((t_end - t0) / self.dt - 1e-9))
        if n_steps <= 0:
            return np.zeros(0), np.zeros((0, 9))
        times = np.minimum(t0 + self.dt * np.arange(1, n_steps + 1), t_end)
        tau = self.cm.roll_decay_time
        decay = np.exp(-(times - t0) / tau)
        p0, v0 = np.asarray(state[:3]), np.asarray(state[3:6])
        pos = p0 + (tau * (1.0 - decay))[:, None] * v0
        vel = decay[:, None] * v0
        lo, hi = self.floor_box()
        clipped = (pos < lo) | (pos > hi)
        pos = np.clip(pos, lo, hi)
        vel[clipped] = 0.0
        spin = np.cross(np.array([0.0, 0.0, 1.0]), vel) / self.radius
        return times, np.concatenate([pos, vel, spin], axis=1)

    def floor_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(3,) lower and upper corners of the floor extent shrunk by the radius (centre heights = r)."""
        corners = np.concatenate([p.corners_3d() for p in self.floor])
        r = self.radius
        return corners.min(axis=0) + [r, r, r], corners.max(axis=0) + [-r, -r, r]


def simulate_flight(
    court: Court,
    pos: np.ndarray,
    vel: np.ndarray,
    spin: np.ndarray,
    t0: float,
    t_end: float,
    dt: float = DEFAULT_DT,
    model: FlightModel | None = None,
    contact_model: ContactModel = ContactModel(),
    max_ground: int | None = None,
) -> Flight:
    """Simulate one ball from a launch state until ``t_end`` (or an earlier stop), with its contacts.

    Args:
        court: the planes, materials and ball.
        pos, vel, spin: (3,) initial centre (m), velocity (m/s), angular velocity (rad/s) at ``t0``.
        t0, t_end: start and end times (s); the last step is shortened to end exactly at ``t_end``.
        dt: RK4 substep (s).
        model: flight constants (default: the court's ball).
        contact_model: bounce/net/rolling constants.
        max_ground: stop right after this many floor (``ground``) contacts.
    Returns:
        the :class:`Flight`; its samples start with the initial state at ``t0``.
    """
    sim = _Simulator(court, model or FlightModel.from_ball(court.ball), contact_model, dt)
    state = _row(pos, vel, spin)
    times, rows, contacts = [t0], [state], []
    end, n_ground = "time", 0
    while times[-1] < t_end - 1e-12:
        start = len(rows) - 1
        n_safe = int(min(sim.safe_time(rows[start]), contact_model.max_safe_time) / dt)
        sim.advance(rows, times, max(n_safe, contact_model.chunk_steps), t_end)
        if len(rows) - 1 - start <= n_safe:
            continue
        arr, tarr = np.asarray(rows[start:]), np.asarray(times[start:])
        found = sim.first_contact(arr, tarr)
        if found is None:
            below = np.flatnonzero(arr[1:, 2] < 0.0)
            if len(below):
                del times[start + int(below[0]) + 2 :], rows[start + int(below[0]) + 2 :]
                end = "left"
                break
            continue
        i, tau, p, side, cstate = found
        del times[start + i + 1 :], rows[start + i + 1 :]
        t = times[-1] + tau
        plane = sim.planes.planes[p]
        contacts.append(Contact(t=t, event=plane.event, position=np.asarray(cstate[:3]), plane=plane.name))
        state, rolls = sim.collide(cstate, t, p, side)
        if t > times[-1] + 1e-12:
            times.append(t)
            rows.append(state)
        else:
            rows[-1] = state
        n_ground += plane.event == "ground"
        if max_ground is not None and n_ground >= max_ground:
            end = "ground"
            break
        if rolls:
            r_times, r_rows = sim.roll(state, t, t_end)
            times += list(r_times)
            rows += [tuple(r) for r in r_rows]
            end = "rest"
            break
    data = np.asarray(rows, dtype=float)
    return Flight(np.asarray(times, dtype=float), data[:, POS], data[:, VEL], data[:, SPIN], contacts, end)


@dataclass(frozen=True)
class FreeFlight:
    """Where a free flight (no contacts) first comes down to the floor and crosses the net line.

    Attributes:
        landing: (2,) x, y of the ball centre when it first descends to z = r (NaN if it does not).
        t_land: flight time to the landing (s).
        net_x, net_z: ball centre x and z where it crosses y = net_y before landing (NaN if it does not).
    """

    landing: np.ndarray
    t_land: float
    net_x: float
    net_z: float


def free_flight(
    pos: np.ndarray, vel: np.ndarray, spin: np.ndarray, model: FlightModel, radius: float, net_y: float,
    dt: float = 0.025, t_max: float = 6.0,
) -> FreeFlight:
    """Integrate one ball without contacts until it comes down to z = r (for launch solving).

    Args:
        pos, vel, spin: (3,) launch state; model: flight constants; radius: ball radius (m).
        net_y: y of the net line; dt: RK4 step (s); t_max: give up after this flight time (s).
    """
    kernel, tol = model.kernel(), 1e-6
    row = _row(pos, vel, spin)
    t, net_x, net_z, crossed = 0.0, np.nan, np.nan, False
    while t < t_max:
        nxt = rk4_step(row, dt, kernel)
        dy0, dy1 = row[1] - net_y, nxt[1] - net_y
        if not crossed and dy0 * dy1 <= 0.0 and dy0 != dy1:
            sgn = 1.0 if dy0 > 0 else -1.0
            _, at = refine_crossing(row, dt, kernel, lambda s: sgn * (s[1] - net_y), sgn * dy0, sgn * dy1,
                                    tol)
            net_x, net_z, crossed = at[0], at[2], True
        if nxt[2] <= radius and nxt[5] < 0.0:
            above = row[2] - radius, nxt[2] - radius
            tau, at = refine_crossing(row, dt, kernel, lambda s: s[2] - radius, *above, tol)
            return FreeFlight(np.array([at[0], at[1]]), t + tau, net_x, net_z)
        row, t = nxt, t + dt
    return FreeFlight(np.full(2, np.nan), np.nan, net_x, net_z)


def vacuum_flight(
    pos: np.ndarray, vel: np.ndarray, gravity: float, radius: float, net_y: float
) -> FreeFlight:
    """The closed-form :func:`free_flight` of a parabola (no drag, no lift)."""
    z0 = pos[2] - radius
    disc = vel[2] ** 2 + 2.0 * gravity * z0
    t_land = (vel[2] + np.sqrt(max(disc, 0.0))) / gravity
    t_net = (net_y - pos[1]) / vel[1] if abs(vel[1]) > 1e-12 else np.nan
    ok = 0.0 <= t_net <= t_land
    return FreeFlight(
        pos[:2] + vel[:2] * t_land,
        t_land,
        pos[0] + vel[0] * t_net if ok else np.nan,
        pos[2] + vel[2] * t_net - 0.5 * gravity * t_net**2 if ok else np.nan,
    )


@dataclass(frozen=True)
class Launch:
    """A solved launch: velocity (3,) m/s, its free flight, and whether the solve converged."""

    vel: np.ndarray
    flight: FreeFlight
    ok: bool

    @property
    def speed(self) -> float:
        return float(np.linalg.norm(self.vel))


def vacuum_launch(
    pos: np.ndarray, target: np.ndarray, gravity: float, radius: float, net_y: float,
    net_height: float | None = None, speed: float | None = None,
) -> np.ndarray | None:
    """Launch velocity (3,) of a vacuum parabola from ``pos`` down to z = r at ``target`` (x, y), passing
    the net line at ``net_height`` or launched at ``speed`` (the flatter solution); None if impossible."""
    d = np.asarray(target, dtype=float) - pos[:2]
    dist = float(np.linalg.norm(d))
    u = d / dist
    dz = radius - pos[2]
    if net_height is not None:
        dn = (net_y - pos[1]) / u[1] if abs(u[1]) > 1e-9 else 0.5 * dist
        if not 0.0 < dn < dist:
            return None
        b = ((net_height - pos[2]) * dist - dz * dn) / (dn * dist * (dist - dn))  # z = z0 + a s - b s²
        if b <= 0.0:
            return None
        a = (net_height - pos[2] + b * dn * dn) / dn
        vh = np.sqrt(gravity / (2.0 * b))
        return np.array([u[0] * vh, u[1] * vh, a * vh])
    if speed is None:
        raise ValueError("give net_height or speed")
    k = gravity * dist * dist / (2.0 * speed * speed)  # k tan² - dist tan + (k - dz) = 0
    disc = dist * dist - 4.0 * k * (k - dz)
    if disc < 0.0:
        return None
    tan = (dist - np.sqrt(disc)) / (2.0 * k)
    c = 1.0 / np.sqrt(1.0 + tan * tan)
    return speed * np.array([u[0] * c, u[1] * c, tan * c])


def solve_launch(
    pos: np.ndarray,
    spin: np.ndarray,
    target: np.ndarray,
    model: FlightModel,
    radius: float,
    net_y: float,
    net_height: Callable[[float], float] | None = None,
    speed: float | None = None,
    tol: float = 0.01,
    max_iter: int = 10,
) -> Launch:
    """Launch velocity whose drag + Magnus flight first comes down at ``target`` and either crosses the
    net line at ``net_height(x)`` or has the given ``speed``.

    Broyden's quasi-Newton method on the velocity (3 unknowns, 3 residuals), started from the vacuum
    parabola aimed at a target corrected by the first flight's miss, with the vacuum Jacobian.

    Args:
        pos: (3,) ball centre at the hit; spin: (3,) rad/s, kept fixed; target: (2,) landing x, y.
        model, radius, net_y: flight constants, ball radius, net line.
        net_height: crossing height of the ball centre as a function of the crossing x; or
        speed: launch speed (m/s), the flatter of the two solutions.
        tol: residual tolerance (m, m/s).
    """
    pos, spin, target = (np.asarray(a, dtype=float) for a in (pos, spin, target))
    nan_launch = Launch(np.full(3, np.nan), FreeFlight(np.full(2, np.nan), np.nan, np.nan, np.nan), False)

    def residual(fl: FreeFlight, v: np.ndarray) -> np.ndarray:
        third = np.linalg.norm(v) - speed if net_height is None else fl.net_z - net_height(fl.net_x)
        return np.array([*(fl.landing - target), third])

    def air(v: np.ndarray) -> tuple[np.ndarray, FreeFlight]:
        fl = free_flight(pos, v, spin, model, radius, net_y)
        return residual(fl, v), fl

    def vacuum(v: np.ndarray) -> np.ndarray:
        return residual(vacuum_flight(pos, v, model.gravity, radius, net_y), v)

    def guess(aim: np.ndarray, height_shift: float) -> np.ndarray | None:
        x_net = pos[0] + (aim[0] - pos[0]) * (net_y - pos[1]) / (aim[1] - pos[1] + 1e-12)
        h = None if net_height is None else net_height(x_net) + height_shift
        return vacuum_launch(pos, aim, model.gravity, radius, net_y, net_height=h, speed=speed)

    x = guess(target, 0.0)
    if x is None:
        return nan_launch
    r, fl = air(x)
    if np.all(np.isfinite(r)):  # aim past the miss: a much better start than the vacuum parabola
        x2 = guess(target - r[:2], -r[2] if net_height is not None else 0.0)
        if x2 is not None:
            r2, fl2 = air(x2)
            if np.all(np.isfinite(r2)) and np.linalg.norm(r2) < np.linalg.norm(r):
                x, r, fl = x2, r2, fl2
    jac = np.empty((3, 3))
    eps = 1e-4
    r0 = vacuum(x)
    for k in range(3):
        jac[:, k] = (vacuum(x + eps * np.eye(3)[k]) - r0) / eps
    for _ in range(max_iter):
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))):
            break
        if np.max(np.abs(r)) < tol:
            return Launch(x, fl, True)
        try:
            dx = -np.linalg.solve(jac, r)
        except np.linalg.LinAlgError:
            break
        dx *= min(1.0, 20.0 / (np.linalg.norm(dx) + 1e-12))
        r_new, fl_new = air(x + dx)
        if not np.all(np.isfinite(r_new)):
            dx *= 0.3
            r_new, fl_new = air(x + dx)
        jac += np.outer(r_new - r - jac @ dx, dx) / float(dx @ dx)
        x, r, fl = x + dx, r_new, fl_new
    return Launch(x, fl, bool(np.all(np.isfinite(r)) and np.max(np.abs(r)) < tol))


def lower_to_net_height(
    pos: np.ndarray, vel: np.ndarray, spin: np.ndarray, model: FlightModel, radius: float, net_y: float,
    height: float, max_drop: float = 0.6, iterations: int = 30,
) -> Launch:
    """The same launch speed and direction, aimed lower so the ball crosses the net line at ``height``
    (a shot into the net). Bisection on the elevation drop in [0, max_drop] rad; a flight that comes down
    before the net counts as too low.

    Args:
        pos, vel, spin: (3,) the launch to lower; model, radius, net_y: flight constants and net line.
        height: wanted height of the ball centre at the net line (m).
    """
    pos, vel, spin = (np.asarray(a, dtype=float) for a in (pos, vel, spin))
    horizontal = np.linalg.norm(vel[:2])
    speed, azimuth = np.linalg.norm(vel), vel[:2] / horizontal
    elevation = np.arctan2(vel[2], horizontal)

    def launch(drop: float) -> np.ndarray:
        e = elevation - drop
        return speed * np.array([*(np.cos(e) * azimuth), np.sin(e)])

    def excess(drop: float) -> tuple[float, FreeFlight]:
        fl = free_flight(pos, launch(drop), spin, model, radius, net_y)
        return (fl.net_z - height if np.isfinite(fl.net_z) else -height), fl

    lo, hi = 0.0, max_drop
    f_lo, fl = excess(lo)
    if f_lo < 0.0 or excess(hi)[0] > 0.0:
        return Launch(vel, fl, False)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        f_mid, fl = excess(mid)
        if f_mid > 0.0:
            lo = mid
        else:
            hi = mid
        if abs(f_mid) < 0.005 and np.isfinite(fl.net_z):
            return Launch(launch(mid), fl, True)
    return Launch(launch(lo), fl, False)
