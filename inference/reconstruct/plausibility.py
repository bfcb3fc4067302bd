"""What the court allows, checked on a fitted rally: per-flight checks, the contact hypotheses tried for a
flight that fails them, and the clip-level plausibility summary written to segments.json.

A flight is *plausible* when its reprojection RMS is at most ``rms_fail_factor`` × the 2D noise, no frame
of it lies more than 5 cm below the floor or behind a glass/mesh patch (padel's enclosure; the open sides
and the space above the walls are allowed), it does not pass through the net without a net event and, between
two contacts, its speed at the first is at most ``max_speed_ms`` (a short flight between two badly placed contacts can fit
the track with a ball launched at thousands of km/h).

Example:
    >>> fit = reconstruct(obs)
    >>> fit.extra["plausibility"]        # {"plausible": True, "frames_inside_court": 1.0, ...}
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from inference.court import Court

from .observations import PLAYER_EVENTS, Observations, contact_prior
from .plan import Plan, PlanContact

if TYPE_CHECKING:
    from .joint import ChainFit, JointConfig
    from .results import RallyFit
    from .shooting import Problem, Solution

#: how deep (m) a frame may sink into the floor or a wall before the flight is implausible
PENETRATION_LIMIT_M = 0.05
#: a racket hit on the other side of the net than its label says, beyond this (m), is implausible
HIT_SIDE_TOLERANCE_M = 1.0


@dataclass(frozen=True)
class HitLimits:
    """What players can do, for judging a fitted racket hit (court YAML ``plausibility``): where it can be
    struck (the players' area, :func:`inference.players.tracking.player_area`, widened by the reach), how
    high (``hits.height``) and how low (``min_hit_m``: a ball at the floor is bounced, not hit), where an
    overhead can be (``overhead_behind_m`` behind the baseline at most) and
    how fast the ball leaves (``max_speed_kmh``: overheads — serves, smashes — and other shots).

    Attributes:
        area: (K, 4) rectangles x0, x1, y0, y1 (m) where a hit may be; max_height: m; overhead_m: a hit at
        least this high is an overhead; overhead_behind_m: how far behind the baseline an overhead may be;
        max_overhead_kmh, max_other_kmh: launch speeds (None: no limit besides the fit's own); min_height: m,
        the ball centre's lowest at a racket contact (0: no check).
    """

    area: np.ndarray
    max_height: float
    overhead_m: float = 2.2
    overhead_behind_m: float | None = None
    max_overhead_kmh: float | None = None
    max_other_kmh: float | None = None
    min_height: float = 0.0

    @classmethod
    def from_court(cls, court: Court) -> HitLimits:
        from inference.players.tracking import player_area

        reach = float(court.hits.reach)
        area = player_area(court).copy()
        area[:, [0, 2]] -= reach
        area[:, [1, 3]] += reach
        d = court.extra.get("plausibility") or {}
        speed = d.get("max_speed_kmh") or {}
        num = lambda v: None if v is None else float(v)  # noqa: E731
        return cls(area, float(court.hits.height[1]), float(d.get("overhead_m", 2.2)), num(d.get("overhead_behind_m")),
                   num(speed.get("overhead")), num(speed.get("other")), float(d.get("min_hit_m", 0.0)))

    def problems(self, court: Court, point: np.ndarray, label: str, speed_ms: float | None) -> list[str]:
        """Why a racket hit at ``point`` (3,) labelled ``label`` leaving at ``speed_ms`` cannot be ([]: it can)."""
        x, y, z = (float(v) for v in point)
        out = []
        inside = ((x >= self.area[:, 0]) & (x <= self.area[:, 1]) & (y >= self.area[:, 2]) & (y <= self.area[:, 3]))
        length = float(court.size[1])
        behind = max(-y, y - length, 0.0)
        if not inside.any():
            beside = max(-x, x - float(court.size[0]), 0.0)
            where = f"{behind:.1f} m behind the baseline" if behind >= beside else f"{beside:.1f} m beside the court"
            out.append(f"a racket hit {where}, where no player stands")
        if z < self.min_height:
            out.append(f"a racket hit {z:.2f} m high, at the floor (a half-volley meets the ball at "
                       f"{self.min_height:g} m or more: a bounce?)")
        if z > self.max_height:
            out.append(f"a racket hit {z:.1f} m high, above any player's reach ({self.max_height:g} m)")
        overhead = z >= self.overhead_m
        if overhead and self.overhead_behind_m is not None and behind > self.overhead_behind_m:
            out.append(f"an overhead ({z:.1f} m high) {behind:.1f} m behind the baseline")
        side = "near" if y < court.net_y else "far"
        if label in PLAYER_EVENTS and label != f"player_{side}" and abs(y - court.net_y) > HIT_SIDE_TOLERANCE_M:
            out.append(f"a {label.removeprefix('player_')} player's hit {abs(y - court.net_y):.1f} m on the {side} side")
        limit = self.max_overhead_kmh if overhead else self.max_other_kmh
        if speed_ms is not None and limit is not None and 3.6 * speed_ms > limit:
            kind = "an overhead" if overhead else "a shot"
            out.append(f"{kind} leaving at {3.6 * speed_ms:.0f} km/h (players reach {limit:.0f})")
        return out
#: tolerance (m) of the clip-level "inside the court" figure
INSIDE_TOLERANCE_M = 0.02


def court_walls(court: Court) -> list:
    """The surfaces the ball cannot pass through besides the floor: glass and mesh patches."""
    return [p for p in court.planes if not p.two_sided and p.event != "ground" and p.material in ("glass", "mesh")]


def penetration(court: Court, xyz: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """(M,) how deep (m, ≥ 0) each ball centre sinks below the floor or behind a wall patch (the ball's
    radius included), and the name of the surface for each (empty where none)."""
    r = court.ball.radius
    depth = np.maximum(r - xyz[:, 2], 0.0)
    where = np.where(depth > 0, "floor", "").astype(object)
    for wall in court_walls(court):
        d = np.maximum(r - (xyz - wall.origin) @ wall.normal, 0.0)
        d = np.where(wall.contains(xyz, tol=0.05), d, 0.0)
        deeper = d > depth
        depth = np.where(deeper, d, depth)
        where = np.where(deeper, wall.name, where)
    return depth, [str(w) for w in where]


@dataclass
class FlightCheck:
    """One fitted flight of a chain against the court's rules.

    Attributes:
        ok: plausible; reason: why not.
        first, last: the frames it covers; rms_px: reprojection RMS over its observed frames (NaN: none);
        n_observed: its 2D points; depth_m: the deepest penetration of the floor or a wall.
    """

    ok: bool
    reason: str
    first: int
    last: int
    rms_px: float
    n_observed: int
    depth_m: float = 0.0


def check_flights(problem: Problem, sol: Solution, cfg: JointConfig) -> list[FlightCheck]:
    """One :class:`FlightCheck` per flight of the chain."""
    if problem.norm_at is not sol.theta:          # the solver leaves the residuals of its solution
        problem.evaluate(sol.theta, jac=False)
    fl, taus = sol.aux["flights"], sol.aux["taus"]
    frames, own, j = problem.frame_positions(fl, taus)
    xyz = fl.P[own, 0, j]
    court = problem.obs.court
    depth, where = penetration(court, xyz)
    obs_own = problem.owners(problem.frames, taus)
    err = problem.last_norm * cfg.pixel_sigma
    j_obs = problem.index(fl, obs_own, problem.frames)
    res = (problem.obs.camera.project(fl.P[obs_own, 0, j_obs]) - problem.uv) / cfg.pixel_sigma  # (M, 2) in σ
    live = problem.weights > 0
    limit = cfg.rms_fail_factor * cfg.pixel_sigma
    limits = HitLimits.from_court(court)
    out = []
    ch = problem.chain
    judged = _hits_by_flight(ch)
    for s, f in enumerate(ch.flights):
        m = own == s
        if not m.any():
            out.append(FlightCheck(True, "", 0, -1, float("nan"), 0))
            continue
        first, last = int(frames[m][0]), int(frames[m][-1])
        e = err[(obs_own == s) & live]
        rms = float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")
        reasons = []
        if len(e) and rms > limit:
            reasons.append(f"reprojection RMS {rms:.1f} px > {cfg.rms_fail_factor:g} × the 2D noise "
                           f"({cfg.pixel_sigma:.2g} px)")
        else:
            bent = structured_misfit(res[(obs_own == s) & live])
            if bent > STRUCTURE_LIMIT:
                reasons.append(f"the track bends where the flight does not (its residuals run {bent:.1f} σ to one "
                               "side over 5 frames: a contact missed?)")
        k = int(np.argmax(np.where(m, depth, -1.0)))
        deepest = (float(depth[k]), where[k], f"frame {frames[k]}")
        # its contacts too: a contact on an unbounded plane (the net's, a wall's) can sit below the floor
        ends = [c for c in (f.start, f.end) if c is not None]
        c_depth, c_where = penetration(court, np.array([ch.point(sol.theta, c) for c in ends]))
        for c, d, w in zip(ends, c_depth, c_where):
            if d > deepest[0]:
                deepest = (float(d), w, f"its {ch.contacts[c].label} contact (frame {ch.contacts[c].frame})")
        if deepest[0] > PENETRATION_LIMIT_M:
            d, w, at = deepest
            reasons.append(f"passes {d:.2f} m {'below the floor' if w == 'floor' else 'behind the ' + w} at {at}")
        labels = [ch.contacts[f.start].label] + ([ch.contacts[f.end].label] if f.end is not None else [])
        clearance = net_clearance(court, xyz[m])
        if "net" not in labels and clearance < -PENETRATION_LIMIT_M:
            reasons.append(f"passes through the net ({clearance:.2f} m below its top)")
        speed = float(np.linalg.norm(sol.theta[f.vel]))
        if f.end is not None and speed > cfg.max_speed_ms:     # a free end's speed is pinned by its track alone
            reasons.append(f"launched at {3.6 * speed:.0f} km/h (> {3.6 * cfg.max_speed_ms:.0f} km/h)")
        spin = float(np.linalg.norm(sol.theta[f.spin])) if f.spin is not None else 0.0
        from_racket = not f.lead_in and ch.contacts[f.start].kind == "hit"  # (a bounce may spin it faster: v / r)
        if from_racket and spin > cfg.max_spin_rads:  # the fit bending the path with spin no racket gives
            reasons.append(f"spins at {spin * 60 / (2 * np.pi):,.0f} rpm (a racket gives at most "
                           f"{cfg.max_spin_rads * 60 / (2 * np.pi):,.0f})")
        gained = bounce_gain(problem, sol, s)
        if gained is not None:
            reasons.append(gained)
        for c in judged.get(s, ()):  # its racket hits: where a player struck it, how high, how fast it left
            leaving = speed if c == f.start and f.end is not None and not f.lead_in else None
            reasons += limits.problems(court, ch.point(sol.theta, c), ch.contacts[c].label, leaving)
        if f.end is not None and ch.contacts[f.end].kind == "hit" and _left_to_a_contact(ch, f.end):
            # the hit it flies into, judged with the flight leaving it to the next contact: a flight ending where
            # no player can meet the ball is as wrong as the one leaving from there (a run-out leaving it fails
            # alone: the flight before it is then put up for refits anyway)
            reasons += [f"ends at {p}" for p in limits.problems(court, ch.point(sol.theta, f.end),
                                                                ch.contacts[f.end].label, None)]
        out.append(FlightCheck(not reasons, "; ".join(reasons), first, last, rms, len(e), deepest[0]))
    return out


#: a rebound may leave its surface at most this much faster (m/s, along the normal) than the material's
#: restitution gives for the incoming speed, beyond its 3-σ spread: a bounce does not add energy
BOUNCE_GAIN_MARGIN_MS = 1.0


def bounce_gain(problem: Problem, sol: Solution, s: int) -> str | None:
    """Why flight ``s`` cannot leave the floor/glass bounce it starts from — it leaves the surface faster than
    any rebound of its incoming flight (restitution × the incoming normal speed, + 3 σ + the margin) — or None.
    The fit's impact model leaves a grazing arrival free (it models balls moving into the surface): a refit
    may put a skimming 'bounce' where a player hit the ball; the ball then leaves it at a racket's speed."""
    ch = problem.chain
    f = ch.flights[s]
    ct = ch.contacts[f.start]
    if f.lead_in or ct.material is None or ct.normal is None:
        return None
    inc = problem.incoming(sol.theta, sol.aux["flights"], sol.aux["taus"], f.start)
    if inc is None:
        return None
    v_in = max(0.0, -float(inc[1] @ ct.normal))                  # m/s into the surface
    v_out = float(sol.theta[f.vel] @ ct.normal)                 # m/s away from it
    sigma_n, _ = problem.bounce_sigmas(inc[1], ct.normal)
    limit = ct.material.restitution * v_in + 3 * sigma_n + BOUNCE_GAIN_MARGIN_MS
    if v_out <= limit:
        return None
    return (f"leaves its {ct.label} bounce (frame {ct.frame}) at {v_out:.1f} m/s off the surface having arrived at "
            f"{v_in:.1f} m/s: a bounce cannot gain speed (a racket hit there?)")


#: a flight whose residuals, median-filtered over 5 observed frames, run this many σ to one side fits the
#: track badly even when its RMS passes: a missed contact bends the track (white noise stays below ~1.8 σ)
STRUCTURE_LIMIT = 2.5


def structured_misfit(res: np.ndarray, width: int = 5) -> float:
    """How far (σ) the residuals ``res`` (M, 2, in units of the 2D noise, frame order) of one flight run to
    one side: the largest norm of their running median over ``width`` consecutive observations (0 with
    fewer than 3 × ``width``). A flight that fits leaves white noise; one hiding a contact leaves a bend."""
    res = np.asarray(res, float)
    if len(res) < 3 * width:
        return 0.0
    res = np.where(np.isfinite(res), res, 0.0)
    win = np.lib.stride_tricks.sliding_window_view(res, width, axis=0)      # (M-w+1, 2, w)
    return float(np.max(np.linalg.norm(np.median(win, axis=2), axis=1)))


def _left_to_a_contact(ch, c: int) -> bool:
    """Whether a flight leaves contact ``c`` of chain ``ch`` for another contact (not a run-out)."""
    return any(f.start == c and f.end is not None and not f.lead_in for f in ch.flights)


def _hits_by_flight(ch) -> dict[int, list[int]]:
    """The racket-hit contacts each flight answers for: the flight leaving a hit, else the one arriving."""
    out: dict[int, list[int]] = {}
    for c, ct in enumerate(ch.contacts):
        if ct.kind != "hit":
            continue
        leaving = [s for s, f in enumerate(ch.flights) if f.start == c and not f.lead_in]
        arriving = [s for s, f in enumerate(ch.flights) if f.end == c or (f.lead_in and f.start == c)]
        owner = (leaving or arriving or [None])[0]
        if owner is not None:
            out.setdefault(owner, []).append(c)
    return out


def net_crossing(court: Court, xyz: np.ndarray):
    """Where a path (K, 3) first crosses the net's plane: ((3,) point, the net plane), or None."""
    nets = [p for p in court.planes if p.event == "net"]
    if not nets or len(xyz) < 2:
        return None
    net = nets[0]
    d = (xyz - net.origin) @ net.normal
    cross = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
    if not len(cross):
        return None
    k = int(cross[0])
    f = d[k] / (d[k] - d[k + 1])
    return xyz[k] + f * (xyz[k + 1] - xyz[k]), net


def net_clearance(court: Court, xyz: np.ndarray, beside_ok: bool = True) -> float:
    """Ball bottom above the net's top (m) where a path (K, 3) crosses the net plane; inf where it does not
    (or, with ``beside_ok``, passes beside the posts)."""
    from .shooting import net_height

    hit = net_crossing(court, xyz)
    if hit is None:
        return float("inf")
    p, net = hit
    x = (p - net.origin) @ net.u
    if beside_ok and (x < net.polygon[:, 0].min() or x > net.polygon[:, 0].max()):
        return float("inf")
    return float(p[2] - court.ball.radius - net_height(net, p))


# ---------------------------------------------------------------------------------------------------
# Hypotheses for a flight that fails
# ---------------------------------------------------------------------------------------------------
def _bounce_label(court: Court) -> str:
    """The label of an inserted surface contact: the court's group of floor-and-walls when it has one (the
    line of sight then picks the surface), else ``ground``."""
    for name, members in court.event_groups.items():
        if "ground" in members:
            return name
    return "ground"


def _kink_frames(obs: Observations, first: int, last: int, residual_frames: np.ndarray,
                 residuals: np.ndarray) -> list[int]:
    """Where a missed contact most likely is: the best break of the 2D track into two smooth pieces
    (:func:`break_frame`), its sharpest turn and the worst-fitted frame, at least 2 frames from the flight's
    ends."""
    out = []
    b = break_frame(obs.uv, first, last)
    if b is not None:
        out.append(b)
    f = np.arange(first + 2, last - 1)
    if len(f):
        acc = obs.uv[f + 1] - 2 * obs.uv[f] + obs.uv[f - 1]
        a = np.linalg.norm(acc, axis=1)
        if np.isfinite(a).any():
            out.append(int(f[int(np.nanargmax(a))]))
    m = (residual_frames >= first + 2) & (residual_frames <= last - 2)
    if m.any():
        out.append(int(residual_frames[m][int(np.argmax(residuals[m]))]))
    return list(dict.fromkeys(out))


def break_frame(uv: np.ndarray, first: int, last: int, half: int = 8, margin: int = 3) -> int | None:
    """The frame in ``[first + margin, last - margin]`` where the 2D track ``uv`` (T, 2; NaN where missing)
    most likely turns at a contact: where two quadratics in time, over the ``half`` frames before and after,
    fit it best compared with one quadratic over both (the largest drop of the squared residual; each side
    needs 4 points), or None. Local windows keep a quadratic adequate under perspective, and the fit is robust
    to the pixel noise that decides the sharpest second difference: a far player's hit turns the track by a
    few pixels per frame, as much as 2 px of noise does."""
    ok = np.isfinite(uv).all(axis=1)

    def sse(a: int, b: int) -> float:
        m = ok[a:b + 1]
        tt, yy = np.arange(a, b + 1)[m], uv[a:b + 1][m]
        if len(tt) < 4:
            return np.nan
        A = np.stack([np.ones(len(tt)), tt - tt[0], (tt - tt[0]) ** 2], axis=1)
        coef, *_ = np.linalg.lstsq(A, yy, rcond=None)
        return float(((A @ coef - yy) ** 2).sum())

    best, where = 0.0, None
    for b in range(first + margin, last - margin + 1):
        a, c = max(first, b - half), min(last, b + half)
        gain = sse(a, c) - sse(a, b) - sse(b, c)
        if np.isfinite(gain) and gain > best:
            best, where = gain, b
    return where


def turn_frames(uv: np.ndarray, first: int, last: int, half: int = 2, margin: int = 3) -> list[int]:
    """Where the ball is highest and lowest in the picture inside ``[first + margin, last - margin]`` (the track
    ``uv`` (T, 2) as its median over ``2 half + 1`` frames, :func:`inference.events.rally.running_median`), when that is not at an end: a racket hit far from the
    camera turns the ball from going away to coming back, which the picture shows as its highest point with
    hardly a kink (the change is along the line of sight); a near hit as its lowest point."""
    from inference.events.rally import running_median

    lo, hi = first + margin, last - margin
    if hi - lo < 2:
        return []
    smooth = running_median(uv[first:last + 1], half)[:, 1]
    smooth[~np.isfinite(uv[first:last + 1, 1])] = np.nan
    inner = smooth[lo - first:hi - first + 1]
    if not np.isfinite(inner).any():
        return []
    out = []
    for i in (int(np.nanargmin(inner)), int(np.nanargmax(inner))):
        if 0 < i < len(inner) - 1:
            out.append(lo + i)
    return out


def _gap_frames(obs: Observations, first: int, last: int, min_gap: int = 3) -> list[int]:
    """The middle frame of every run of at least ``min_gap`` frames without a 2D ball inside ``[first, last]``
    (a contact the tracker lost, or one out of the picture), longest run first."""
    seen = np.isfinite(obs.uv[first:last + 1]).all(axis=1)
    m = np.r_[0, (~seen).astype(int), 0]
    edges = np.flatnonzero(np.diff(m))
    runs = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_gap and a > 0 and b <= len(seen) - 1]
    return [first + (a + b) // 2 for a, b in sorted(runs, key=lambda r: r[0] - r[1])]


def _gap_beside(obs: Observations, frame: int, reach: int = 3, min_gap: int = 3) -> int | None:
    """The middle of a gap of at least ``min_gap`` frames that ends or starts within ``reach`` frames of
    ``frame`` (the contact was timed where the ball reappeared), or None."""
    from inference.events.gaps import gap_around

    seen = np.isfinite(obs.uv).all(axis=1)
    g = gap_around(seen, frame, reach)
    if g is None or g[1] - g[0] + 1 < min_gap or g[0] == 0 or g[1] == len(seen) - 1:
        return None
    return (g[0] + g[1]) // 2


def _side_label(fit: ChainFit, frame: int) -> str:
    """``player_near`` or ``player_far``: the side of the net where the fitted flight is at ``frame``."""
    pb, sol = fit.problem, fit.sol
    frames, own, j = pb.frame_positions(sol.aux["flights"], sol.aux["taus"])
    k = int(np.clip(np.searchsorted(frames, frame), 0, len(frames) - 1))
    y = float(sol.aux["flights"].P[own[k], 0, j[k]][1])
    return "player_near" if not np.isfinite(y) or y < pb.obs.court.net_y else "player_far"


#: A racket hit fitted lower than this (m) is at the floor: hypothesis 1b looks for the bounce just before it.
FLOOR_HIT_M = 0.15


def hypotheses(obs: Observations, fit: ChainFit, k: int, cfg: JointConfig):
    """Plans to try for flight ``k`` of a fitted chain that fails its checks (yielded lazily, most likely
    first): a missed bounce inside it (at the track's sharpest turn, just before a racket hit fitted at the
    floor, then in its gaps: a bounce the tracker lost or one outside the picture), a missed racket hit (a volley, a hit hidden by the player), another
    surface or event class at its contacts, no contact at all. For a flight that passes its own checks (the
    neighbour of a failing run-out) only the bounce before its end hit."""
    pb = fit.problem
    ch = pb.chain
    f = ch.flights[k]
    chk = fit.checks[k]
    contacts = list(fit.plan.contacts)
    why = chk.reason

    def plan_with(new: list, note: tuple[int, str]) -> Plan:
        return Plan(new, [*fit.plan.notes, note])

    def inserted(frame: int, label: str, what: str):
        prior = contact_prior(obs, frame, label)
        if label not in PLAYER_EVENTS and prior.plane is None:
            return None
        pos = sum(c.prior.frame < frame for c in contacts)
        if pos and pos < len(contacts) and second_bounce(obs.court, contacts[pos - 1].prior, prior,
                                                         contacts[pos].prior):
            return None
        if label in PLAYER_EVENTS and breaks_alternation([c.prior.label for c in contacts], pos, label):
            return None
        where = prior.plane.name if prior.plane is not None else what
        note = f"contact inserted at frame {frame} ({where}): the flight over frames {chk.first}–{chk.last} did " \
               f"not fit as one ({why})"
        return plan_with(contacts[:pos] + [PlanContact(prior, None, note)] + contacts[pos:], (frame, note))

    ends = [f.start] + ([f.end] if f.end is not None else [])
    label = _bounce_label(obs.court)
    floor_hit_bounces: list[int] = []
    # 1. a bounce just before a racket hit that the fit puts at the floor: the ball played off the bounce
    #     (a half-volley, a volley after a low bounce), the two contacts merged into one event
    if f.end is not None and contacts[f.end].prior.label in PLAYER_EVENTS and \
            float(ch.point(fit.sol.theta, f.end)[2]) < FLOOR_HIT_M:
        hit = contacts[f.end].prior.frame
        for frame in (hit - 2, hit - 3):
            if frame > chk.first + 1 and contact_prior(obs, frame, label).ok:
                floor_hit_bounces.append(frame)
                plan = inserted(frame, label, "a surface")
                if plan is not None:
                    yield plan
    if chk.ok:  # a passing flight before a failing run-out: only its end contact is in question
        return
    # 1b. a missed bounce inside the flight at a sharp turn of the track
    kinks = [fr for fr in _kink_frames(obs, chk.first, chk.last, pb.frames, pb.last_norm)
             if contact_prior(obs, fr, label).ok]
    gaps = [fr for fr in _gap_frames(obs, chk.first, chk.last) if fr not in kinks]
    for frame in kinks:
        if frame not in floor_hit_bounces:
            for lab in _surfaces_seen(obs, frame, label):
                plan = inserted(frame, lab, "a surface")
                if plan is not None:
                    yield plan
    # 2. another surface or event class at its contacts
    for c in ends:
        pc = contacts[c]
        old = pc.prior
        for lab in _other_labels(obs, old):
            prior = contact_prior(obs, old.frame, lab)
            if not prior.ok:
                continue
            note = f"event at frame {old.frame} fitted as {lab} instead of {old.label} ({why})"
            yield plan_with(contacts[:c] + [replace(pc, prior=prior, note=note)] + contacts[c + 1:],
                            (old.frame, note))
    # 3. a missed bounce in a gap of the track (one the tracker lost, or out of the picture: bridged)
    for frame in gaps:
        for lab in _surfaces_seen(obs, frame, label):
            plan = inserted(frame, lab, "a surface")
            if plan is not None:
                yield plan
    # 4. a missed racket hit: a volley or a hit the tracker lost (a serve in the gap after its toss), by the
    #    player on the side of the net where the fit has the ball first, then by the other
    for frame in dict.fromkeys(kinks[:1] + turn_frames(obs.uv, chk.first, chk.last) + gaps[:1]):
        side = _side_label(fit, frame)
        for lab in (side, "player_far" if side == "player_near" else "player_near"):
            plan = inserted(frame, lab, "a racket")
            if plan is not None:
                yield plan
    # 5. a contact timed at the edge of a gap of the track moved into the gap (the tracker lost the ball before a
    #    bounce far away; the model put the bounce where the ball reappeared)
    for c in ends:
        pc = contacts[c]
        g = _gap_beside(obs, pc.prior.frame)
        if g is None or pc.prior.label in PLAYER_EVENTS:
            continue
        prior = contact_prior(obs, g, pc.prior.label)
        note = f"event {pc.prior.label} at frame {pc.prior.frame} moved to frame {g}, inside the track's gap ({why})"
        yield plan_with(contacts[:c] + [replace(pc, prior=prior, note=note)] + contacts[c + 1:], (g, note))
    # 6. no contact there at all
    for c in ends:
        if len(contacts) > 1:
            old = contacts[c].prior
            note = f"event {old.label} at frame {old.frame} fitted as no contact ({why})"
            yield plan_with(contacts[:c] + contacts[c + 1:], (old.frame, note))


def second_bounce(court: Court, before, prior, after) -> bool:
    """Whether a floor contact ``prior`` inserted between the contacts ``before`` and ``after`` (their priors) is a
    second bounce that the play rules out: the one before it a floor bounce in the same half, the one after it a
    racket hit (the point is over after two bounces; a glass or the fence the camera looks through, on the same
    line of sight, is the contact then)."""
    def on_floor(p) -> bool:
        return p.plane is not None and p.plane.event == "ground" and p.ok

    if not (on_floor(prior) and on_floor(before) and after.label in PLAYER_EVENTS):
        return False
    return (float(before.point[1]) < court.net_y) == (float(prior.point[1]) < court.net_y)


def breaks_alternation(labels: list[str], pos: int, hit: str) -> bool:
    """Whether a racket hit ``hit`` inserted at position ``pos`` of the contacts ``labels`` would follow or precede a
    hit by the same side: the sides hit in turn, so a hit the events missed lies between two hits of one side (or
    before the first, after the last, of the other side), never between a near and a far hit."""
    before = next((lab for lab in reversed(labels[:pos]) if lab in PLAYER_EVENTS), None)
    after = next((lab for lab in labels[pos:] if lab in PLAYER_EVENTS), None)
    return hit in (before, after)


def _surfaces_seen(obs: Observations, frame: int, label: str) -> list[str]:
    """Surface labels for a contact inserted at ``frame``: ``label`` (the floor-and-walls group: the line of sight
    picks the surface), then any other surface the line of sight meets inside its extent — the near glass or a
    mesh, which a camera behind the near glass sees the ball through (a rebound off the glass it looks through
    lies on the same line of sight as a bounce on the floor beyond it)."""
    out = [label]
    grouped = set(obs.court.event_groups.get(label, (label,)))
    for lab in obs.court.event_labels:
        if lab in grouped or lab in PLAYER_EVENTS or lab == "net":
            continue
        if contact_prior(obs, frame, lab, unbounded_ok=False).ok:
            out.append(lab)
    return out


def _other_labels(obs: Observations, prior) -> list[str]:
    """Labels to try instead of ``prior.label``: the other surfaces the line of sight reaches, a racket hit
    for a surface contact (by side of the net) and a floor contact for a racket hit."""
    court = obs.court
    if prior.label in PLAYER_EVENTS:
        return [_bounce_label(court)]
    out = []
    current = {p.event for p in court.planes_for(prior.label)}
    for lab in court.event_labels:
        if lab in current or lab in PLAYER_EVENTS:
            continue
        if contact_prior(obs, prior.frame, lab, unbounded_ok=False).ok:
            out.append(lab)
    y = prior.point[1] if prior.ok else obs.court.net_y - 1
    out.append("player_near" if y < court.net_y else "player_far")
    return out


# ---------------------------------------------------------------------------------------------------
# The clip-level summary
# ---------------------------------------------------------------------------------------------------
#: a clip with more than this share of its flights failed is not plausible
MAX_FAILED_SHARE = 0.25
#: a clip whose reconstructed flights cover less than this share of the frames from its first to its last
#: event is not plausible (a replay of a tenth of the rally is no replay of the rally)
MIN_COVERED_SHARE = 0.5


def covered_share(fit: RallyFit, obs: Observations) -> float:
    """The share of the frames from the first to the last event that a reconstructed flight covers; with a
    single event frame, of the frames from the first to the last 2D ball (a lone event's lead-in and run-out
    are the whole replay: 3 frames of 3D beside a 180-frame track are no replay of it)."""
    ev = obs.event_frames
    if obs.single_event:
        seen = np.flatnonzero(np.isfinite(obs.uv).all(axis=1))
        if not len(seen):
            return 1.0 if any(s.ok for s in fit.segments) else 0.0
        span = np.arange(int(seen[0]), int(seen[-1]) + 1)
    else:
        span = np.arange(int(ev[0]), int(ev[-1]) + 1)
    have = np.zeros(len(span), bool)
    for s in fit.segments:
        if s.ok and len(s.frames):
            have |= (span >= s.frames[0]) & (span <= s.frames[-1])
    return float(have.mean())


def summary(fit: RallyFit, obs: Observations, rms_limit_px: float | None = None) -> dict:
    """Clip-level plausibility of a reconstruction (segments.json's ``plausibility``): flights reconstructed
    and failed (with reasons), the share of frames inside the court, contacts below the floor, the worst
    reprojection RMS, flagged contacts, and ``plausible`` when nothing is off."""
    court = obs.court
    ok = [s for s in fit.segments if s.ok]
    b = fit.ball_3d()
    inside = 1.0
    if len(b):
        depth, _ = penetration(court, b.xyz)
        inside = float(np.mean(depth <= INSIDE_TOLERANCE_M))
    r = court.ball.radius
    contacts = [p for s in ok for p in (s.start, s.end) if p is not None]
    below = int(sum(float(p[2]) < r - INSIDE_TOLERANCE_M for p in contacts))
    rms = [s.reproj_rms_px for s in ok if np.isfinite(s.reproj_rms_px)]
    over = int(sum(x > rms_limit_px for x in rms)) if rms_limit_px else 0
    flags = [f for s in ok for f in s.figures.get("flags", [])]
    reasons = Counter(s.reason for s in fit.segments if not s.ok)
    out = {
        "flights": len(fit.segments), "reconstructed": len(ok), "failed": len(fit.segments) - len(ok),
        "failure_reasons": dict(reasons), "frames": len(b), "frames_inside_court": round(inside, 4),
        "contacts_below_floor": below, "max_reprojection_rms_px": round(max(rms), 2) if rms else None,
        "flags": flags,
    }
    if rms_limit_px:
        out["flights_over_rms_limit"] = over
        out["rms_limit_px"] = round(float(rms_limit_px), 2)
    # failed flights count too: a rally of which a third could not be reconstructed is no plausible replay
    failed, n = len(fit.segments) - len(ok), len(fit.segments)
    out["failed_share"] = round(failed / n, 4) if n else 0.0
    covered = covered_share(fit, obs)
    out["covered_share"] = round(covered, 4)
    why = (["no flight reconstructed"] if not ok else []) + \
        ([f"{failed}/{n} flights failed"] if ok and failed / n > MAX_FAILED_SHARE else []) + \
        ([f"3D for {covered:.0%} of the rally only" + (
            " (a single event: the rest of the track is not one flight from it; are events missing?)"
            if obs.single_event else "")] if ok and covered < MIN_COVERED_SHARE else []) + \
        ([f"{inside:.0%} of frames inside the court"] if inside < 0.98 else []) + \
        ([f"{below} contacts below the floor"] if below else []) + \
        ([f"{over} flights over the RMS limit"] if over else [])
    out["not_plausible_because"] = why
    out["plausible"] = not why
    return out
