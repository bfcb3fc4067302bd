"""The rally planner: a whole padel or tennis point as a :class:`~synth.types.Rally`.

How a rally is made (all times in seconds from the clip's first frame):

1. Players take their places: padel doubles (team ``near`` on y < net, ``far`` beyond, one player per
   lane), tennis singles. The server stands behind the service line (padel) or the baseline (tennis).
2. Before the serve the ball is in the server's hand, then dropped to bounce once (padel, underhand serve
   hit below the waist near the top of the rebound) or tossed up (tennis, hit overhead at 2.7–3 m).
3. Each shot: a shot type (drive, lob, volley, ...) is drawn for the stroke, then a target in the
   opponent's half (the diagonal service box for the serve), a spin and a net clearance (or, for the
   tennis serve, a speed); the launch velocity is solved on the drag + Magnus flight
   (:func:`~synth.physics.solve_launch`) and kept if its speed is in the shot's range. The flight
   is simulated with its contacts on a coarse step and judged (in, net, out, glass before the floor).
4. The receiving team's players who can get there in time (quintic, minimum-jerk-like moves within
   their speed and acceleration limits, after a reaction time) are scored over the hittable part of the
   incoming path — after the bounce at a plausible height, also after the ball came back off the glass,
   or a volley before the bounce for padel players at the net — and the best (player, time, side) is the
   next hit. The flight is then simulated exactly (RK4 at ≤ 1/600 s) up to that hit.
5. The rally has 2–12 hits and ends with a winner (second bounce, ball out of reach or out of the
   court) or an error (net, out, padel glass before the floor). The clip runs on a little after.
6. Non-hitting players move back to a base position (padel: the team's net or back formation, shifted
   towards the ball); every player faces the ball, and the way forward around their own strokes.

Everything random comes from the ``np.random.Generator`` passed in: the same seed gives the same rally.

Example:
    >>> rally = simulate_rally(load_court("padel"), fps=30, rng=np.random.default_rng(0))
    >>> [(c.event, round(c.t, 3)) for c in rally.contacts]
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from inference.court import Court
from inference.physics import DEFAULT_DT, FlightModel
from synth.physics import (
    Flight,
    Launch,
    lower_to_net_height,
    simulate_flight,
    solve_launch,
    vacuum_launch,
)
from synth.types import BallPath, Contact, InactiveBall, PlayerPlan, Rally, Swing

Range = tuple[float, float]
TWO_PI = 2.0 * np.pi


# ----------------------------------------------------------------------------------------------------
# Configuration: every tunable number of the planner, per sport.


@dataclass(frozen=True)
class ShotSpec:
    """Ranges of one shot type.

    Attributes:
        speed: launch speed (m/s).
        spin: rev/s about the horizontal axis across the flight; + topspin, - backspin.
        sidespin: largest |rev/s| about the vertical axis (random sign).
        clearance: height of the ball centre above the net's top where it crosses (m).
        depth: target distance from the net in the opponent's half (m).
        by_speed: solve for a speed drawn from ``speed`` (tennis serve) instead of a clearance.
    """

    speed: Range
    spin: Range
    sidespin: float
    clearance: Range
    depth: Range
    by_speed: bool = False


@dataclass(frozen=True)
class ServeSpec:
    """The serve's set-up.

    Attributes:
        root_depth: server's distance from the net (m) (behind the service line / baseline).
        root_lateral: server's distance from the centre line (m).
        overhead: tennis-style toss and overhead hit; else padel drop, bounce and underhand hit.
        release_height: where the ball leaves the hand (m).
        toss_apex: top of the toss (m), overhead serves.
        contact_height: ball height at the hit (m), overhead serves (capped below the apex).
        after_apex: underhand serves are hit this long after the top of the rebound (s).
        box_margin: serve targets stay this far inside the service box lines (m).
    """

    root_depth: Range
    root_lateral: Range
    overhead: bool
    release_height: Range
    toss_apex: Range = (3.05, 3.4)
    contact_height: Range = (2.7, 3.0)
    after_apex: Range = (0.0, 0.06)
    box_margin: float = 0.3


@dataclass(frozen=True)
class PlayerSpec:
    """Players' bodies and movement.

    Attributes:
        speed: top running speed range (m/s), drawn per player; accel: top acceleration (m/s²).
        height: standing height (m); p_left_handed: share of left-handers.
        reaction: delay after a hit before a player starts moving (s).
        settle: a hitter is in place this long before the hit (s); follow: stays after it (s).
        comfort: unhurried moves use this fraction of the limits.
        wall_margin: roots stay this far from walls / the court's edge (m); net_margin: from the net.
        min_move_time: a hitter needs at least this long (s) between reacting and settling.
        base_jitter: base positions vary by ± this much in x (m).
        turn_rate: fastest turn of the heading (rad/s); stroke_facing: players face the net from this
            long (s) before to this long after their strokes, the ball otherwise.
        p_wait_forehand, wait_spread: a serve's receiver waits for a forehand with this probability,
            off the ideal spot by a normal spread of this sd (m).
    """

    speed: Range = (4.0, 6.0)
    accel: Range = (7.0, 10.0)
    height: Range = (1.65, 1.95)
    p_left_handed: float = 0.12
    reaction: Range = (0.1, 0.22)
    settle: Range = (0.06, 0.12)
    follow: Range = (0.15, 0.25)
    comfort: float = 0.8
    wall_margin: float = 0.3
    net_margin: float = 0.5
    min_move_time: float = 0.15
    base_jitter: float = 0.3
    turn_rate: float = 12.0
    stroke_facing: float = 0.5
    p_wait_forehand: float = 0.6
    wait_spread: float = 0.3


@dataclass(frozen=True)
class InactiveSpec:
    """Stationary balls lying on the floor.

    Attributes:
        count: how many (min, max), drawn uniformly; in_court: whether they may lie inside the lines.
        p_partial: share that appears or disappears mid-clip.
        feet_clearance: distance (m) from every player's root while visible; path_clearance: from the
            ball's path where it is below 1 m; edge_margin: from the floor's edge.
    """

    count: tuple[int, int] = (0, 4)
    in_court: bool = True
    p_partial: float = 0.3
    feet_clearance: float = 0.8
    path_clearance: float = 1.0
    edge_margin: float = 0.15


@dataclass(frozen=True)
class AroundPointSpec:
    """What real clips hold around the point (off by default: the default rallies are unchanged).

    Attributes:
        warmup_bounces: (min, max) bounces of the ball by the server before the serve (thrown down from
            the hand at ``bounce_height``, caught at the top of the rebound); not events of the point.
        bounce_height: hand height (m); bounce_speed: downward throw speed (m/s); pause: hand time
            between bounces (s).
        after: weights of what the ball does once the point is over: ``none`` (the clip ends ``tail``
            after), ``roll`` (it goes on bouncing and rolling), ``catch`` (a player catches it), ``side_hit``
            (a player knocks it to the side, a racket contact that is not an event); after_s: how long
            the clip runs on (s).
    """

    warmup_bounces: tuple[int, int] = (0, 0)
    bounce_height: Range = (0.8, 1.1)
    bounce_speed: Range = (1.5, 4.0)
    pause: Range = (0.15, 0.6)
    after: dict[str, float] = field(default_factory=lambda: {"none": 1.0})
    after_s: Range = (1.0, 2.5)

    @property
    def enabled(self) -> bool:
        return self.warmup_bounces[1] > 0 or set(k for k, w in self.after.items() if w > 0) != {"none"}


REAL_AROUND = AroundPointSpec(warmup_bounces=(1, 4),
                              after={"none": 0.1, "roll": 0.35, "catch": 0.3, "side_hit": 0.25})


@dataclass(frozen=True)
class ReplyScore:
    """Weights of the score that picks who returns a ball, when and how (higher is better): minus
    ``height`` × |ball height - preferred|, minus ``distance`` × the run (m), plus ``forehand`` for a
    forehand, plus ``volley_at_net`` for a volley by a player at the net, plus ``noise`` × U(0, 1)."""

    height: float = 1.5
    distance: float = 0.3
    forehand: float = 0.3
    volley_at_net: float = 0.6
    noise: float = 0.2


@dataclass(frozen=True)
class RallyConfig:
    """Everything tunable about a rally (becomes a Hydra config).

    Attributes:
        sport: rules to apply (``padel`` or ``tennis``); n_players: 4 (doubles) or 2 (singles).
        n_hits: racket hits per rally (serve included), drawn uniformly.
        p_winner: share of rallies ending with a winner; ``errors``: weights of the error endings.
        shots: shot type → ranges; ``serve`` is the serve.
        choice: stroke kind → {shot type: weight}; ``lob_vs_net``: lob weight factor when both
            opponents are at the net.
        advance: shot type → probability the hitting team then plays at the net.
        hit_height: stroke kind → allowed ball height at the hit (m); ``preferred_height`` for scoring.
        reach: stroke kind → (lateral lo, hi, forward lo, hi) of the ball from the body axis (m).
        volleys: whether players at the net volley (padel); volley_depth: "at the net" (m from it);
            volley_reach: balls are volleyed once at least this far past the net (m).
        score: how the returning stroke is chosen.
        net_depth, back_depth: formation distances from the net (m); lane_x: lane centres from the
            centre line (m, doubles); base_shift: share of the ball's x offset the base follows.
        serve: serve set-up; player: bodies and moves.
        lead, tail: clip time before the serve and after the ball is dead (s).
        inactive: stationary balls on the floor.
        around: the server's bounces before the serve and the ball after the point (off by default).
        attempts: tries per shot to find a launch that fits its ranges and can be returned.
        horizon: longest look-ahead of a flight (s); coarse_dt: its RK4 step (s), which is also the
            spacing of the candidate hit times.
        error_margin: how far beyond the lines error shots are aimed (m).
        error_net_height: crossing height of net errors as a fraction of the net's height.
        min_clearance: the ball's centre passes at least this high above the net's top (m, > ball radius).
    """

    sport: str
    n_players: int
    shots: dict[str, ShotSpec]
    choice: dict[str, dict[str, float]]
    advance: dict[str, float]
    hit_height: dict[str, Range]
    preferred_height: dict[str, float]
    reach: dict[str, tuple[float, float, float, float]]
    serve: ServeSpec
    errors: dict[str, float]
    volleys: bool
    net_depth: Range
    back_depth: Range
    lane_x: float
    base_shift: float
    n_hits: tuple[int, int] = (2, 12)
    p_winner: float = 0.5
    lob_vs_net: float = 1.5
    volley_depth: float = 4.5
    player: PlayerSpec = PlayerSpec()
    lead: Range = (0.3, 1.0)
    tail: Range = (0.3, 1.0)
    inactive: InactiveSpec = InactiveSpec()
    around: AroundPointSpec = AroundPointSpec()
    volley_reach: float = 1.0
    score: ReplyScore = ReplyScore()
    attempts: int = 8
    horizon: float = 5.0
    coarse_dt: float = 0.02
    error_margin: Range = (0.4, 2.0)
    error_net_height: Range = (0.35, 0.7)
    min_clearance: float = 0.06


_REACH = {  # (lateral lo, hi, forward lo, hi) of the ball from the body axis at contact (m)
    "forehand": (0.55, 0.9, 0.0, 0.35),
    "backhand": (0.55, 0.85, 0.0, 0.3),
    "volley": (0.45, 0.75, 0.2, 0.45),
    "overhead": (0.2, 0.4, 0.25, 0.5),
    "serve": (0.3, 0.5, 0.3, 0.5),
}

PADEL = RallyConfig(
    sport="padel",
    n_players=4,
    shots={  # speed m/s, spin rev/s (+ top), |sidespin| rev/s, net clearance m, target depth m
        "serve": ShotSpec((9.0, 17.0), (-12.0, 8.0), 6.0, (0.15, 0.7), (3.5, 6.5)),
        "drive": ShotSpec((10.0, 22.0), (-20.0, 30.0), 6.0, (0.15, 1.1), (3.0, 8.8)),
        # lobs as high as a broadcast shows them: net clearance 4.5–9.5 m, up to 23 m/s, in 30 / 35 % of the
        # forehand / backhand replies — fitted to a real broadcast, whose camera loses the ball above the
        # picture's top in 10.7 % of the frames for a median 1.06 s (bench/bench_real_track_stats.py); the
        # earlier 2–4.5 m lobs never left it
        "lob": ShotSpec((8.0, 23.0), (0.0, 20.0), 4.0, (4.5, 9.5), (6.0, 9.0)),
        "volley": ShotSpec((8.0, 20.0), (-25.0, 0.0), 5.0, (0.1, 0.8), (3.0, 8.8)),
        "overhead": ShotSpec((12.0, 25.0), (-30.0, 10.0), 8.0, (0.1, 1.2), (3.0, 8.5)),
    },
    choice={
        "forehand": {"drive": 0.7, "lob": 0.3},
        "backhand": {"drive": 0.65, "lob": 0.35},
        "volley": {"volley": 1.0},
        "overhead": {"overhead": 1.0},
    },
    advance={"serve": 1.0, "volley": 1.0, "overhead": 0.9, "lob": 0.8, "drive": 0.25},
    hit_height={
        "forehand": (0.3, 1.8), "backhand": (0.3, 1.6), "volley": (0.45, 1.9), "overhead": (1.9, 2.9),
    },
    preferred_height={"forehand": 0.95, "backhand": 0.95, "volley": 1.1, "overhead": 2.3},
    reach=_REACH,
    serve=ServeSpec(root_depth=(7.3, 8.6), root_lateral=(0.8, 2.5), overhead=False,
                    release_height=(0.9, 1.2)),
    errors={"error_net": 0.45, "error_wall": 0.55},
    volleys=True,
    net_depth=(2.5, 3.6),
    back_depth=(7.6, 8.8),
    lane_x=2.5,
    base_shift=0.35,
)

TENNIS = RallyConfig(
    sport="tennis",
    n_players=2,
    shots={  # speed m/s, spin rev/s (+ top), |sidespin| rev/s, net clearance m, target depth m
        # serve 158–230 km/h: fitted to a real men's final (serve → its bounce 0.36 / 0.41 / 0.50 s at 10 / 50 /
        # 90 %, bench/bench_real_track_stats.py); 35–55 m/s had given 0.40 / 0.48 / 0.58 s
        "serve": ShotSpec((44.0, 64.0), (0.0, 40.0), 20.0, (0.05, 1.0), (3.8, 6.1), by_speed=True),
        "topspin": ShotSpec((20.0, 35.0), (15.0, 50.0), 6.0, (0.3, 2.0), (6.0, 11.3)),
        "slice": ShotSpec((15.0, 28.0), (-30.0, -10.0), 6.0, (0.15, 0.9), (6.0, 11.3)),
        "lob": ShotSpec((12.0, 24.0), (10.0, 40.0), 4.0, (3.0, 7.0), (8.5, 11.3)),
        "smash": ShotSpec((20.0, 35.0), (-10.0, 10.0), 6.0, (0.2, 1.2), (5.0, 11.0)),
    },
    choice={
        "forehand": {"topspin": 0.88, "slice": 0.04, "lob": 0.08},
        "backhand": {"topspin": 0.7, "slice": 0.25, "lob": 0.05},
        "volley": {"slice": 1.0},
        "overhead": {"smash": 1.0},
    },
    advance={},
    hit_height={
        "forehand": (0.3, 2.0), "backhand": (0.3, 1.8), "volley": (0.45, 1.9), "overhead": (2.0, 2.9),
    },
    preferred_height={"forehand": 1.0, "backhand": 1.0, "volley": 1.1, "overhead": 2.4},
    reach=_REACH,
    serve=ServeSpec(root_depth=(12.05, 12.4), root_lateral=(0.3, 1.5), overhead=True,
                    release_height=(1.6, 1.9)),
    errors={"error_net": 0.45, "error_out": 0.55},
    volleys=False,
    net_depth=(12.2, 13.4),
    back_depth=(12.2, 13.4),
    lane_x=0.0,
    base_shift=0.45,
    inactive=InactiveSpec(count=(0, 2), in_court=False),
)

CONFIGS = {"padel": PADEL, "tennis": TENNIS}

#: Tennis at the pace of a men's tour final: groundstrokes faster, flatter and lower over the net, from deep
#: behind the baseline. Fitted to a real final's rally shots (a hit to the next bounce, not the serve): 0.64 /
#: 0.86 / 1.23 s at 10 / 50 / 90 % real, 0.41 / 0.85 / 1.14 s with these ranges, 0.88 / 1.10 / 1.30 s with the
#: default ones (bench/bench_real_track_stats.py prints them). The players' base 1–5 m behind the baseline (hits
#: 0.4 / 2.0 / 4.7 m behind at 10 / 50 / 90 %; the club pace 0.3 m median): tour players return and rally 2–6 m
#: behind it (the real broadcasts' 3D contacts: 1.8–4.5 m). The default pace stays the club player's (the sample,
#: the tests).
TENNIS_TOUR = replace(TENNIS, shots={
    **TENNIS.shots,
    "topspin": replace(TENNIS.shots["topspin"], speed=(24.0, 48.0), spin=(20.0, 55.0), clearance=(0.15, 1.0)),
    "slice": replace(TENNIS.shots["slice"], speed=(16.0, 36.0), clearance=(0.1, 0.7)),
}, back_depth=(13.0, 17.0))

#: the rally configurations by pace: ``club`` (the default) and the sports that have a ``tour`` one
PACES = {"club": CONFIGS, "tour": {"tennis": TENNIS_TOUR}}


def default_config(sport: str, pace: str = "club") -> RallyConfig:
    """The :class:`RallyConfig` of a sport at a pace (``club``: the default; ``tour``: tennis only)."""
    if pace not in PACES:
        raise KeyError(f"no rally pace {pace!r}; known: {sorted(PACES)}")
    if sport not in PACES[pace]:
        what = "" if pace == "club" else f"{pace} "
        raise KeyError(f"no {what}rally configuration for sport {sport!r}; known: {sorted(PACES[pace])}")
    return PACES[pace][sport]


# ----------------------------------------------------------------------------------------------------
# Court zones: the geometry the rules need, read from the court model.


@dataclass(frozen=True)
class Zones:
    """Rule geometry of a court.

    Attributes:
        net_y: y of the net; half: distance net → baseline (m) (the net is midway on both courts).
        x_lo, x_hi: the playing lines in x (singles for tennis, the glass for padel).
        centre_x: centre service line; service_depth: service line distance from the net.
        walls: whether the court has glass walls (padel).
        area_lo, area_hi: (2,) where players may stand (floor extent shrunk by the wall margin).
    """

    net_y: float
    half: float
    x_lo: float
    x_hi: float
    centre_x: float
    service_depth: float
    walls: bool
    area_lo: np.ndarray
    area_hi: np.ndarray

    @classmethod
    def of(cls, court: Court, margin: float) -> Zones:
        pts = court.points
        floor = np.concatenate([p.corners_3d() for p in court.planes_for("ground")])
        x_lo = float(pts["near_singles_left"][0]) if "near_singles_left" in pts else 0.0
        x_hi = float(pts["near_singles_right"][0]) if "near_singles_right" in pts else float(court.size[0])
        centre = pts["near_service_center"]
        return cls(
            net_y=float(court.net_y),
            half=float(court.net_y),
            x_lo=x_lo,
            x_hi=x_hi,
            centre_x=float(centre[0]),
            service_depth=float(court.net_y - centre[1]),
            walls=bool(court.planes_for("wall_near")),
            area_lo=floor.min(axis=0)[:2] + margin,
            area_hi=floor.max(axis=0)[:2] - margin,
        )

    @staticmethod
    def forward(team: str) -> float:
        """+1 if the team faces +y (near), -1 (far)."""
        return 1.0 if team == "near" else -1.0

    def y_at(self, team: str, depth) -> np.ndarray:
        """y of points ``depth`` metres from the net inside ``team``'s half."""
        return self.net_y - self.forward(team) * np.asarray(depth)

    def depth(self, team: str, y) -> np.ndarray:
        """Distance from the net into ``team``'s half (negative on the other side)."""
        return self.forward(team) * (self.net_y - np.asarray(y))

    def in_half(self, team: str, xy: np.ndarray, margin: float = 0.0) -> bool:
        """Whether a floor point lies inside the lines of ``team``'s half."""
        d = float(self.depth(team, xy[1]))
        return self.x_lo - margin <= xy[0] <= self.x_hi + margin and 0.0 < d <= self.half + margin

    def box_x(self, lane: str) -> Range:
        """The x range of the service box on the ``left`` (x < centre) or ``right`` side."""
        return (self.x_lo, self.centre_x) if lane == "left" else (self.centre_x, self.x_hi)

    def in_box(self, team: str, lane: str, xy: np.ndarray, margin: float = 0.0) -> bool:
        """Whether a floor point lies in ``team``'s service box on side ``lane``."""
        lo, hi = self.box_x(lane)
        d = float(self.depth(team, xy[1]))
        return lo - margin <= xy[0] <= hi + margin and 0.0 < d <= self.service_depth + margin

    def player_bounds(self, team: str, net_margin: float) -> tuple[np.ndarray, np.ndarray]:
        """(2,) lower and upper corners of where ``team``'s players may stand."""
        lo, hi = self.area_lo.copy(), self.area_hi.copy()
        if team == "near":
            hi[1] = min(hi[1], self.net_y - net_margin)
        else:
            lo[1] = max(lo[1], self.net_y + net_margin)
        return lo, hi


def net_top(court: Court) -> Callable[[float], float]:
    """The height of the net's top edge as a function of x (from the net plane's polygon)."""
    plane = court.plane("net")
    poly = plane.polygon
    a, b = poly, np.roll(poly, -1, axis=0)

    def top(x: float) -> float:
        u = float((np.array([x, 0.0, 0.0]) - plane.origin) @ plane.u)
        lo, hi = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
        span = (lo <= u) & (u <= hi) & (lo < hi)
        if not span.any():
            return float(poly[:, 1].max())
        w = (u - a[span, 0]) / (b[span, 0] - a[span, 0])
        return float(np.max(a[span, 1] + w * (b[span, 1] - a[span, 1])))

    return top


# ----------------------------------------------------------------------------------------------------
# Player motion: quintic moves that end at rest, replanned from the current state at every hit.


def _basis(s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S,) s → (S, 6) the monomials 1, s, ..., s⁵ and their first and second derivatives."""
    s = np.asarray(s, dtype=float).reshape(-1, 1)
    k = np.arange(6)
    return s**k, k * s ** np.maximum(k - 1, 0), k * (k - 1) * s ** np.maximum(k - 2, 0)


_POW, _DPOW, _DDPOW = _basis(np.linspace(0.0, 1.0, 17))  # where moves are checked against the limits


def quintic(p0, v0, a0, p1, T) -> np.ndarray:
    """Coefficients (..., 6, 2) in s = (t - t0)/T of the quintic from (p0, v0, a0) to p1 at rest.

    Args:
        p0, v0, a0: (..., 2) start position, velocity, acceleration; p1: (..., 2) end; T: (...,) duration.
    """
    T = np.asarray(T, dtype=float)[..., None]
    d = np.asarray(p1) - p0
    vt, at = v0 * T, a0 * T * T
    c3 = 10 * d - 6 * vt - 1.5 * at
    c4 = -15 * d + 8 * vt + 1.5 * at
    c5 = 6 * d - 3 * vt - 0.5 * at
    return np.stack(np.broadcast_arrays(p0, vt, 0.5 * at, c3, c4, c5), axis=-2)


def moves_ok(p0, v0, a0, p1, T, vmax: float, amax: float, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(...,) whether each quintic move stays within speed, acceleration and the area [lo, hi]."""
    T = np.maximum(np.asarray(T, dtype=float), 1e-3)
    c = quintic(p0, v0, a0, p1, T)
    pos = _POW @ c
    vel = (_DPOW @ c) / T[..., None, None]
    acc = (_DDPOW @ c) / (T * T)[..., None, None]
    inside = np.all((pos >= lo - 0.05) & (pos <= hi + 0.05), axis=(-1, -2))
    fast = np.linalg.norm(vel, axis=-1).max(axis=-1) <= vmax * (1 + 1e-6)
    strong = np.linalg.norm(acc[..., 1:, :], axis=-1).max(axis=-1) <= amax * (1 + 1e-6)
    return inside & fast & strong


def comfortable_duration(distance, vmax: float, amax: float, minimum: float = 0.35) -> np.ndarray:
    """Duration of an unhurried rest-to-rest quintic move: peak speed 1.875 D/T, peak accel 5.77 D/T²."""
    d = np.asarray(distance, dtype=float)
    return np.maximum.reduce([np.full_like(d, minimum), 1.875 * d / vmax, np.sqrt(5.774 * d / amax)])


class Motion:
    """A player's floor trajectory: a start position and quintic moves, each ending at rest."""

    def __init__(self, start: np.ndarray):
        self.start = np.asarray(start, dtype=float)
        self.moves: list[tuple[float, float, np.ndarray]] = []  # (t0, T, coefficients (6, 2))

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(2,) position, velocity, acceleration at time t."""
        active = [m for m in self.moves if m[0] <= t]
        if not active:
            return self.start.copy(), np.zeros(2), np.zeros(2)
        t0, T, c = active[-1]
        pw, dpw, ddpw = _basis(min((t - t0) / T, 1.0))
        return (pw @ c)[0], (dpw @ c)[0] / T, (ddpw @ c)[0] / T**2

    def move(self, t0: float, goal: np.ndarray, T: float) -> None:
        """Replace the plan from t0 on by a move to ``goal`` lasting T seconds."""
        p0, v0, a0 = self.state(t0)
        self.moves = [m for m in self.moves if m[0] < t0]
        self.moves.append((t0, float(T), quintic(p0, v0, a0, np.asarray(goal, dtype=float), T)))

    def sample(self, times: np.ndarray) -> np.ndarray:
        """(N,) times → (N, 2) positions."""
        times = np.asarray(times, dtype=float)
        out = np.tile(self.start, (len(times), 1))
        ends = [m[0] for m in self.moves[1:]] + [np.inf]
        for (t0, T, c), t1 in zip(self.moves, ends):
            sel = (times >= t0) & (times < t1)
            out[sel] = _basis(np.clip((times[sel] - t0) / T, 0.0, 1.0))[0] @ c
        return out


# ----------------------------------------------------------------------------------------------------
# The planner.


@dataclass
class _Player:
    """A player while planning: identity, body, limits (vmax m/s, amax m/s²), motion, formation mode."""

    pid: int
    team: str
    lane: str  # "left" (x < centre), "right" or "centre"
    handed: str
    height: float
    vmax: float
    amax: float
    motion: Motion
    mode: str = "back"  # "net" or "back": where the player's base is
    swings: list[Swing] = field(default_factory=list)

    @property
    def hand(self) -> float:
        """+1 if the forehand is on the player's right."""
        return 1.0 if self.handed == "right" else -1.0


@dataclass
class _Verdict:
    """How a shot's flight turns out: ``in`` (bounce at t_bounce, hittable until t_end) or an error."""

    kind: str
    t: float
    t_bounce: float = np.nan
    t_end: float = np.nan
    t_cross: float = np.nan


@dataclass
class _Option:
    """A way to return the ball: who, when, where the ball and the player's root are, what stroke."""

    player: _Player
    t: float
    ball: np.ndarray
    root: np.ndarray
    kind: str
    t_start: float
    duration: float
    score: float


@dataclass
class _Shot:
    """A planned shot: launch, look-ahead flight, verdict and (unless it ends the rally) the return."""

    shot_type: str
    vel: np.ndarray
    spin: np.ndarray
    flight: Flight
    verdict: _Verdict
    reply: _Option | None = None


def _uniform(rng: np.random.Generator, r: Range) -> float:
    return float(rng.uniform(r[0], r[1]))


def _other(team: str) -> str:
    return "far" if team == "near" else "near"


class _Planner:
    """One rally's planning state (see the module docstring for the steps)."""

    def __init__(self, court: Court, fps: float, rng: np.random.Generator, cfg: RallyConfig, n_players: int):
        self.court, self.fps, self.rng, self.cfg = court, float(fps), rng, cfg
        self.zones = Zones.of(court, cfg.player.wall_margin)
        self.model = FlightModel.from_ball(court.ball)
        self.radius = court.ball.radius
        self.dt = min(DEFAULT_DT, 1.0 / (10.0 * self.fps))
        self.net_top = net_top(court)
        self.players = self._make_players(n_players)
        self.receiver: _Player | None = None  # of the serve
        self.pieces: list[Flight] = []  # the ball path, in time order
        self.contacts: list[Contact] = []

    # -- set-up ---------------------------------------------------------------------------------------

    def _make_players(self, n_players: int) -> list[_Player]:
        if n_players not in (2, 4):
            raise ValueError(f"n_players must be 2 (singles) or 4 (doubles), got {n_players}")
        ps, rng = self.cfg.player, self.rng
        per_team = n_players // 2
        lanes = ["left", "right"] if per_team == 2 else ["centre"]
        players = []
        for team in ("near", "far"):
            for lane in lanes:
                players.append(
                    _Player(
                        pid=len(players),
                        team=team,
                        lane=lane,
                        handed="left" if rng.random() < ps.p_left_handed else "right",
                        height=_uniform(rng, ps.height),
                        vmax=_uniform(rng, ps.speed),
                        amax=_uniform(rng, ps.accel),
                        motion=Motion(np.zeros(2)),
                    )
                )
        return players

    def team(self, team: str) -> list[_Player]:
        return [p for p in self.players if p.team == team]

    def lane_x(self, lane: str, ball_x: float | None = None) -> float:
        """Base x of a lane, shifted towards the ball."""
        z = self.zones
        x = z.centre_x + {"left": -1.0, "right": 1.0, "centre": 0.0}[lane] * self.cfg.lane_x
        if ball_x is not None:
            x += self.cfg.base_shift * (ball_x - z.centre_x)
        return x

    def base(self, p: _Player, ball_x: float | None) -> np.ndarray:
        """Where a player goes back to, jittered."""
        depth = self.cfg.net_depth if p.mode == "net" else self.cfg.back_depth
        y = float(self.zones.y_at(p.team, _uniform(self.rng, depth)))
        jitter = self.cfg.player.base_jitter
        xy = np.array([self.lane_x(p.lane, ball_x) + self.rng.uniform(-jitter, jitter), y])
        lo, hi = self.zones.player_bounds(p.team, self.cfg.player.net_margin)
        return np.clip(xy, lo, hi)

    def frame(self, team: str) -> tuple[np.ndarray, np.ndarray]:
        """(2,) forward (towards the net) and right unit vectors of a team's players."""
        f = np.array([0.0, Zones.forward(team)])
        return f, np.array([f[1], -f[0]])

    def reach_offset(self, p: _Player, kind: str, side: float) -> np.ndarray:
        """(2,) ball minus root at contact for one stroke."""
        return self.reach_offsets(p, np.array([kind]), side)[0]

    # -- the serve ------------------------------------------------------------------------------------

    def place_for_serve(self) -> tuple[_Player, _Player, str]:
        """Put everyone in place; returns (server, receiver, receiver's box lane)."""
        cfg, z, rng = self.cfg, self.zones, self.rng
        serving = "near" if rng.random() < 0.5 else "far"
        side = "left" if rng.random() < 0.5 else "right"
        box = "right" if side == "left" else "left"  # diagonal
        servers = self.team(serving)
        server = next((p for p in servers if p.lane == side), servers[0])
        receivers = self.team(_other(serving))
        receiver = next((p for p in receivers if p.lane == box), receivers[0])
        sign = -1.0 if side == "left" else 1.0
        serve_x = z.centre_x + sign * _uniform(rng, cfg.serve.root_lateral)
        server.motion.start = np.array([serve_x, float(z.y_at(serving, _uniform(rng, cfg.serve.root_depth)))])
        box_sign = -1.0 if box == "left" else 1.0
        rx = z.centre_x + box_sign * (0.5 * (z.x_hi - z.x_lo) * rng.uniform(0.45, 0.75))
        receiver.motion.start = np.clip(
            np.array([rx, float(z.y_at(receiver.team, _uniform(rng, cfg.back_depth)))]),
            *z.player_bounds(receiver.team, cfg.player.net_margin),
        )
        for p in self.players:
            if p is server or p is receiver:
                continue
            p.mode = "net" if (p.team == serving or rng.random() < 0.6) else "back"
            p.motion.start = self.base(p, None)
        server.mode = "back"
        receiver.mode = "back"
        return server, receiver, box

    def pre_serve(self, server: _Player) -> tuple[Flight, float]:
        """The ball from the server's hand to the serve (local time 0 = release); returns it and the
        serve's local time."""
        sv, rng = self.cfg.serve, self.rng
        hand = server.motion.start + self.reach_offset(server, "serve", 1.0)
        z0 = _uniform(rng, sv.release_height)
        if sv.overhead:
            apex = _uniform(rng, sv.toss_apex)
            vz = np.sqrt(2 * self.model.gravity * (apex - z0) * 1.02)
            f, _ = self.frame(server.team)
            vel = np.array([0.0, 0.0, vz]) + 0.15 * np.append(f, 0.0)
            t_end = 2.0 * vz / self.model.gravity
            flight = simulate_flight(self.court, np.append(hand, z0), vel, np.zeros(3), 0.0, t_end, self.dt,
                                     self.model)
            top = int(np.argmax(flight.pos[:, 2]))
            z_hit = min(_uniform(rng, sv.contact_height), flight.pos[top, 2] - 0.05)
            k = top + int(np.argmax(flight.pos[top:, 2] <= z_hit))
        else:
            t_end = 2.2 * np.sqrt(2.0 * z0 / self.model.gravity) + 0.2  # past the top of the rebound
            flight = simulate_flight(self.court, np.append(hand, z0), np.zeros(3), np.zeros(3), 0.0, t_end,
                                     self.dt, self.model, max_ground=2)
            after = flight.t > flight.contacts[0].t
            top = int(np.flatnonzero(after)[np.argmax(flight.pos[after, 2])])
            k = int(np.searchsorted(flight.t, flight.t[top] + _uniform(rng, sv.after_apex)))
        return flight, float(flight.t[k])

    # -- shots ----------------------------------------------------------------------------------------

    def warmup(self, server: _Player) -> list[Flight]:
        """The server's bounces before the serve, from time 0 (thrown down, caught at the top of the
        rebound, a pause in the hand in between); their contacts are not events of the point."""
        sp, rng = self.cfg.around, self.rng
        n = int(rng.integers(sp.warmup_bounces[0], sp.warmup_bounces[1] + 1))
        hand = server.motion.start + self.reach_offset(server, "serve", 1.0) * 0.6
        out, t0 = [], 0.0
        for _ in range(n):
            t0 += _uniform(rng, sp.pause)
            z0 = _uniform(rng, sp.bounce_height)
            vel = np.array([rng.normal(0, 0.1), rng.normal(0, 0.1), -_uniform(rng, sp.bounce_speed)])
            f = simulate_flight(self.court, np.append(hand, z0), vel, np.zeros(3), t0, t0 + 2.0, self.dt,
                                self.model, max_ground=2)
            after = np.flatnonzero(f.t > f.contacts[0].t) if f.contacts else np.arange(len(f.t))
            k = int(after[np.argmax(f.vel[after, 2] <= 0)]) if len(after) else len(f.t) - 1
            f = f.until(float(f.t[k]))
            out.append(Flight(f.t, f.pos, f.vel, f.spin, [_outside(c) for c in f.contacts], f.end))
            t0 = float(f.t[-1])
        return out

    def draw_spin(self, spec: ShotSpec, direction: np.ndarray) -> np.ndarray:
        """(3,) spin (rad/s): top/backspin about ẑ × d̂ (ω × v points down for topspin) + sidespin."""
        d = np.append(direction / np.linalg.norm(direction), 0.0)
        top = np.cross([0.0, 0.0, 1.0], d) * _uniform(self.rng, spec.spin)
        side = np.array([0.0, 0.0, 1.0]) * self.rng.uniform(-spec.sidespin, spec.sidespin)
        return TWO_PI * (top + side)

    def draw_target(self, team: str, spec: ShotSpec, intent: str, box: str | None) -> np.ndarray:
        """(2,) landing point of a shot by ``team`` for an intent (normal/winner/error_*)."""
        z, rng, opp = self.zones, self.rng, _other(team)
        if box is not None:
            lo, hi = z.box_x(box)
            m = self.cfg.serve.box_margin
            x = rng.uniform(lo + m, hi - m)
            depth = rng.uniform(spec.depth[0], min(spec.depth[1], z.service_depth - m))
        else:
            x = rng.uniform(z.x_lo + 0.6, z.x_hi - 0.6)
            depth = rng.uniform(*spec.depth)
        if intent in ("error_out", "error_wall"):
            over = _uniform(rng, self.cfg.error_margin)
            if rng.random() < 0.5:
                depth = z.half + over
            else:
                x = z.x_hi + over if x > z.centre_x else z.x_lo - over
        return np.array([x, float(z.y_at(opp, depth))])

    def solve(self, pos: np.ndarray, spec: ShotSpec, intent: str, target: np.ndarray,
              spin: np.ndarray) -> Launch:
        """Solve the launch of one drawn shot (by clearance or speed); a net error is the same shot aimed
        lower, to cross the net line at a fraction of the net's height."""
        z = self.zones
        common = (pos, spin, target, self.model, self.radius, z.net_y)
        if spec.by_speed:
            launch = solve_launch(*common, speed=_uniform(self.rng, spec.speed))
        else:
            clearance = _uniform(self.rng, spec.clearance)
            launch = solve_launch(*common, net_height=lambda x: self.net_top(x) + clearance)
        if intent != "error_net" or not launch.ok:
            return launch
        height = _uniform(self.rng, self.cfg.error_net_height) * self.net_top(launch.flight.net_x)
        return lower_to_net_height(pos, launch.vel, spin, self.model, self.radius, z.net_y, height)

    def launch_fits(self, launch: Launch, spec: ShotSpec, intent: str) -> bool:
        """Converged, in the shot's speed range and (unless aimed at the net) over the net."""
        if not launch.ok or not spec.speed[0] <= launch.speed <= spec.speed[1]:
            return False
        fl = launch.flight
        if intent == "error_net" or not np.isfinite(fl.net_z):
            return intent == "error_net"
        return fl.net_z >= self.net_top(fl.net_x) + self.cfg.min_clearance

    def judge(self, flight: Flight, team: str, t_hit: float, box: str | None) -> _Verdict:
        """Apply the rules to a shot by ``team``: the first contact after the hit decides."""
        z, opp = self.zones, _other(team)
        across = z.depth(opp, flight.pos[:, 1]) > 0
        t_cross = float(flight.t[np.argmax(across)]) if across.any() else np.nan
        contacts = [c for c in flight.contacts if c.t > t_hit]
        for i, c in enumerate(contacts):
            if c.event == "net":
                return _Verdict("error_net", c.t, t_cross=t_cross)
            if c.event != "ground":
                return _Verdict("error_wall" if z.walls else "error_out", c.t, t_cross=t_cross)
            xy = c.position[:2]
            if z.depth(opp, xy[1]) <= 0:
                return _Verdict("error_net", c.t, t_cross=t_cross)
            good = z.in_box(opp, box, xy) if box is not None else z.in_half(opp, xy)
            if not good:
                return _Verdict("error_out", c.t, t_cross=t_cross)
            later = [d for d in contacts[i + 1 :] if d.event == "ground"]
            t_end = later[0].t if later else float(flight.t[-1])
            if box is not None and any(d.event == "mesh" and d.t < t_end for d in contacts[i + 1 :]):
                return _Verdict("error_out", c.t, t_cross=t_cross)  # a serve that bounces into the mesh
            return _Verdict("in", c.t, t_bounce=c.t, t_end=t_end, t_cross=t_cross)
        return _Verdict("error_out", float(flight.t[-1]), t_cross=t_cross)

    def plan_shot(self, hitter: _Player, t_hit: float, pos: np.ndarray, kind: str, intent: str,
                  box: str | None) -> _Shot:
        """Draw, solve and look ahead until the shot fits its intent (and, if normal, can be returned)."""
        cfg = self.cfg
        best: _Shot | None = None
        shot_type = "serve" if kind == "serve" else self.draw_shot_type(hitter, kind, intent)
        for attempt in range(cfg.attempts):
            if attempt == cfg.attempts // 2 and kind != "serve":  # maybe that shot cannot be played from here
                shot_type = self.draw_shot_type(hitter, kind, intent)
            spec = cfg.shots[shot_type]
            n_targets = 3 if intent == "winner" else 1  # a winner goes where the opponents are not
            targets = [self.draw_target(hitter.team, spec, intent, box) for _ in range(n_targets)]
            target = max(targets, key=lambda xy: self.distance_to_team(_other(hitter.team), xy, t_hit))
            spin = self.draw_spin(spec, target - pos[:2])
            launch = self.solve(pos, spec, intent, target, spin)
            if not self.launch_fits(launch, spec, intent):
                continue
            flight = simulate_flight(self.court, pos, launch.vel, spin, t_hit, t_hit + cfg.horizon,
                                     cfg.coarse_dt, self.model, max_ground=2)
            verdict = self.judge(flight, hitter.team, t_hit, box)
            shot = _Shot(shot_type, launch.vel, spin, flight, verdict)
            if intent == "normal":
                if verdict.kind != "in":
                    continue
                shot.reply = self.best_reply(shot, hitter, t_hit, serve_return=box is not None)
                if shot.reply is not None:
                    return shot
                best = best or shot
            elif verdict.kind == ("in" if intent == "winner" else intent):
                return shot
        if best is not None:
            return best
        return self.fallback_shot(hitter, t_hit, pos, box)

    def fallback_shot(self, hitter: _Player, t_hit: float, pos: np.ndarray, box: str | None) -> _Shot:
        """A plain vacuum-aimed lob to the middle of the opponent's half when nothing else fitted."""
        z = self.zones
        target = np.array([z.centre_x, float(z.y_at(_other(hitter.team), 0.6 * z.half))])
        vel = vacuum_launch(pos, target, self.model.gravity, self.radius, z.net_y,
                            net_height=self.net_top(z.centre_x) + 3.0)
        if vel is None:
            vel = np.array([0.0, 8.0 * Zones.forward(hitter.team), 8.0])
        flight = simulate_flight(self.court, pos, vel, np.zeros(3), t_hit, t_hit + self.cfg.horizon,
                                 self.cfg.coarse_dt, self.model, max_ground=2)
        return _Shot("lob", vel, np.zeros(3), flight, self.judge(flight, hitter.team, t_hit, box))

    def draw_shot_type(self, hitter: _Player, kind: str, intent: str) -> str:
        """A shot type for a stroke kind; lobs are likelier when both opponents are at the net and are not
        what goes into the net."""
        weights = dict(self.cfg.choice[kind])
        if intent == "error_net" and len(weights) > 1:
            weights.pop("lob", None)
        if "lob" in weights and all(p.mode == "net" for p in self.team(_other(hitter.team))):
            weights["lob"] *= self.cfg.lob_vs_net
        return _weighted(self.rng, weights)

    def distance_to_team(self, team: str, xy: np.ndarray, t: float) -> float:
        """Distance (m) from a floor point to the nearest player of ``team`` at time t."""
        return min(float(np.linalg.norm(p.motion.state(t)[0] - xy)) for p in self.team(team))

    # -- who returns it -------------------------------------------------------------------------------

    def best_reply(self, shot: _Shot, hitter: _Player, t_hit: float, serve_return: bool) -> _Option | None:
        """The best feasible (player, time, side) to return a shot, or None if nobody can."""
        cfg, z, v = self.cfg, self.zones, shot.verdict
        fl = shot.flight
        t, pos = fl.t, fl.pos
        after = (t > v.t_bounce + 0.02) & (t < v.t_end - 0.02)
        volley = np.zeros_like(after)
        if cfg.volleys and not serve_return:
            deep = z.depth(_other(hitter.team), pos[:, 1]) > cfg.volley_reach
            volley = (t > v.t_cross) & (t < v.t_bounce - 0.02) & deep
        inside = np.all((pos[:, :2] >= z.area_lo - 0.1) & (pos[:, :2] <= z.area_hi + 0.1), axis=1)
        idx = np.flatnonzero((after | volley) & inside)
        if not len(idx):
            return None
        receivers = self.team(_other(hitter.team))
        if serve_return:
            receivers = [self.receiver]
            self.anticipate(self.receiver, pos[idx], after[idx])
        options = [o for p in receivers for o in self.options_for(p, t_hit, t[idx], pos[idx], after[idx])]
        return max(options, key=lambda o: o.score) if options else None

    def anticipate(self, p: _Player, balls: np.ndarray, bounced: np.ndarray) -> None:
        """Let the receiver of a serve wait where it can be returned: near the first ball position after
        the bounce at a comfortable height within the receiving depths (a little off, at random)."""
        cfg, z = self.cfg, self.zones
        depth = z.depth(p.team, balls[:, 1])
        lo, hi = cfg.back_depth
        pref = cfg.preferred_height["forehand"]
        good = bounced & (np.abs(balls[:, 2] - pref) < 0.35) & (depth >= lo - 1.0) & (depth <= hi + 1.0)
        if not good.any():
            return
        ball = balls[np.argmax(good)]
        side = 1.0 if self.rng.random() < cfg.player.p_wait_forehand else -1.0
        spot = ball[:2] - self.reach_offset(p, "forehand" if side > 0 else "backhand", side)
        spot += self.rng.normal(0.0, cfg.player.wait_spread, 2)
        p.motion.start = np.clip(spot, *z.player_bounds(p.team, cfg.player.net_margin))

    def options_for(self, p: _Player, t_hit: float, times: np.ndarray, balls: np.ndarray,
                    bounced: np.ndarray) -> list[_Option]:
        """The best way for player p to hit the ball at one of the candidate times, per side (≤ 2).

        Args:
            times: (K,) candidate times; balls: (K, 3) ball centres then; bounced: (K,) after the bounce.
        """
        cfg, ps, rng = self.cfg, self.cfg.player, self.rng
        t_start = t_hit + _uniform(rng, ps.reaction)
        p0, v0, a0 = p.motion.state(t_start)
        at_net = float(self.zones.depth(p.team, p0[1])) <= cfg.volley_depth
        lo, hi = self.zones.player_bounds(p.team, ps.net_margin)
        settle = _uniform(rng, ps.settle)
        avail = times - settle - t_start
        out = []
        for side in (1.0, -1.0):
            ground = "forehand" if side > 0 else "backhand"
            kinds = np.where(balls[:, 2] >= cfg.hit_height["overhead"][0], "overhead",
                             np.where(bounced, ground, "volley"))
            h_lo, h_hi = np.array([cfg.hit_height[k] for k in kinds]).reshape(-1, 2).T
            pref = np.array([cfg.preferred_height[k] for k in kinds])
            ok = (balls[:, 2] >= h_lo) & (balls[:, 2] <= h_hi) & (bounced | at_net)
            ok &= avail > ps.min_move_time
            if side < 0:
                ok &= kinds != "overhead"
            if not ok.any():
                continue
            roots = balls[:, :2] - self.reach_offsets(p, kinds, side)
            dist = np.linalg.norm(roots - p0, axis=1)
            comfy = np.minimum(comfortable_duration(dist, ps.comfort * p.vmax, ps.comfort * p.amax), avail)
            ok_c = ok & moves_ok(p0, v0, a0, roots, comfy, p.vmax, p.amax, lo, hi)
            ok_a = ok & ~ok_c & moves_ok(p0, v0, a0, roots, avail, p.vmax, p.amax, lo, hi)
            feasible = ok_c | ok_a
            if not feasible.any():
                continue
            sc = cfg.score
            score = (
                -sc.height * np.abs(balls[:, 2] - pref) - sc.distance * dist + sc.forehand * (side > 0)
                + sc.volley_at_net * ((kinds == "volley") & at_net) + sc.noise * rng.random(len(times))
            )
            i = int(np.argmax(np.where(feasible, score, -np.inf)))
            out.append(_Option(p, float(times[i]), balls[i].copy(), roots[i], str(kinds[i]), t_start,
                               float(comfy[i] if ok_c[i] else avail[i]), float(score[i])))
        return out

    def reach_offsets(self, p: _Player, kinds: np.ndarray, side: float) -> np.ndarray:
        """(K, 2) ball minus root at contact for strokes of ``kinds`` on side +1 (forehand) / -1."""
        r = np.array([self.cfg.reach[k] for k in kinds]).reshape(-1, 4)
        lat = self.rng.uniform(r[:, 0], r[:, 1])
        fwd = self.rng.uniform(r[:, 2], r[:, 3])
        f, right = self.frame(p.team)
        return (side * p.hand * lat)[:, None] * right + fwd[:, None] * f

    # -- moves ----------------------------------------------------------------------------------------

    def go_to_base(self, p: _Player, t0: float, ball_x: float | None) -> None:
        """Move p towards its base from t0, unhurried; keep the current plan if no move fits."""
        ps = self.cfg.player
        goal = self.base(p, ball_x)
        p0, v0, a0 = p.motion.state(t0)
        lo, hi = self.zones.player_bounds(p.team, ps.net_margin)
        t_c = float(comfortable_duration(np.linalg.norm(goal - p0), ps.comfort * p.vmax, ps.comfort * p.amax))
        durations = t_c * np.array([1.0, 1.3, 1.7, 2.2, 3.0])
        ok = moves_ok(p0, v0, a0, np.broadcast_to(goal, (5, 2)), durations, p.vmax, p.amax, lo, hi)
        if ok.any():
            p.motion.move(t0, goal, float(durations[np.argmax(ok)]))

    def after_hit(self, hitter: _Player, shot: _Shot, t_hit: float) -> None:
        """Formation update and moves of everyone but the next hitter after a hit (bases shifted
        towards where the ball lands)."""
        cfg, rng = self.cfg, self.rng
        bounces = [c for c in shot.flight.contacts if c.event == "ground"]
        target_x = float(bounces[0].position[0] if bounces else shot.flight.pos[-1, 0])
        advance = rng.random() < cfg.advance.get(shot.shot_type, 0.0)
        for p in self.team(hitter.team):
            p.mode = "net" if advance else "back"
        nxt = shot.reply.player if shot.reply is not None else None
        for p in self.players:
            if p is nxt:
                continue
            delay = _uniform(rng, cfg.player.follow if p is hitter else cfg.player.reaction)
            self.go_to_base(p, t_hit + delay, target_x)

    # -- the rally ------------------------------------------------------------------------------------

    def run(self) -> Rally:
        """Serve, then shot after shot until the planned last one or one nobody can return."""
        cfg, rng = self.cfg, self.rng
        server, self.receiver, box = self.place_for_serve()
        pre, t_local = self.pre_serve(server)
        t_serve = _uniform(rng, cfg.lead)
        if cfg.around.enabled:  # only then: the default rallies draw exactly as before
            warm = self.warmup(server)
            if warm:  # the serve's own drop or toss starts a pause after the last catch
                t_serve = max(t_serve, float(warm[-1].t[-1]) + _uniform(rng, cfg.around.pause) + t_local)
            for f in warm:
                self.add_piece(f, last=False)
        shift = t_serve - t_local
        pre = _shifted(pre, shift).until(t_serve + 1e-9)
        self.add_piece(pre, last=False)
        n_hits = int(rng.integers(cfg.n_hits[0], cfg.n_hits[1] + 1))
        ending = "winner" if rng.random() < cfg.p_winner else _weighted(rng, cfg.errors)

        hitter, t_hit, pos, kind = server, t_serve, pre.pos[-1].copy(), "serve"
        for k in range(1, n_hits + 1):
            intent = ending if k == n_hits else "normal"
            shot = self.plan_shot(hitter, t_hit, pos, kind, intent, box if k == 1 else None)
            self.record_hit(hitter, t_hit, pos, kind, shot.shot_type)
            if shot.reply is None:
                self.after_hit(hitter, shot, t_hit)
                return self.finish(shot, hitter, t_hit, pos, box if k == 1 else None, t_serve)
            reply = shot.reply
            fine = simulate_flight(self.court, pos, shot.vel, shot.spin, t_hit, reply.t, self.dt, self.model)
            self.add_piece(fine, last=False)
            new_pos = fine.pos[-1].copy()
            root = reply.root + (new_pos[:2] - reply.ball[:2])
            reply.player.motion.move(reply.t_start, root, reply.duration)
            self.after_hit(hitter, shot, t_hit)
            hitter, t_hit, pos, kind = reply.player, reply.t, new_pos, reply.kind
        raise AssertionError("unreachable: the last hit always finishes the rally")

    def record_hit(self, p: _Player, t: float, pos: np.ndarray, kind: str, shot_type: str) -> None:
        """The player's swing and the racket contact."""
        stroke = "lob" if shot_type == "lob" and kind in ("forehand", "backhand") else kind
        p.swings.append(Swing(t_hit=t, hit_point=pos.copy(), kind=stroke))
        self.contacts.append(Contact(t=t, event=f"player_{p.team}", position=pos.copy(), player=p.pid))

    def add_piece(self, flight: Flight, last: bool) -> None:
        """Append a flight to the ball path (without its final sample unless it is the last piece)."""
        self.contacts += flight.contacts
        self.pieces.append(flight if last else flight.until(flight.t[-1] - 1e-9))

    def finish(self, shot: _Shot, hitter: _Player, t_hit: float, pos: np.ndarray, box: str | None,
               t_serve: float) -> Rally:
        """Simulate the last flight exactly until the ball is dead plus the tail; assemble the rally."""
        v = shot.verdict
        t_dead_guess = v.t_end if v.kind == "in" else v.t
        tail = _uniform(self.rng, self.cfg.tail)
        fine = simulate_flight(self.court, pos, shot.vel, shot.spin, t_hit, t_dead_guess + tail + 0.5,
                               self.dt, self.model)
        fine_v = self.judge(fine, hitter.team, t_hit, box)
        t_dead = fine_v.t_end if fine_v.kind == "in" else fine_v.t
        if not np.isfinite(t_dead):
            t_dead = float(fine.t[-1])
        clip_end = t_dead + tail
        outcome = "winner" if fine_v.kind == "in" else fine_v.kind
        if self.cfg.around.enabled:
            return self.after_point(fine, t_serve, t_dead, outcome)
        self.add_piece(fine.until(clip_end), last=True)
        return self.assemble(t_serve, t_dead, clip_end, outcome)

    def after_point(self, fine: Flight, t_serve: float, t_dead: float, outcome: str) -> Rally:
        """The ball once the point is over (``around.after``): its contacts are not events."""
        sp, rng = self.cfg.around, self.rng
        kind = _weighted(rng, sp.after)
        clip_end = t_dead + (_uniform(rng, self.cfg.tail) if kind == "none" else _uniform(rng, sp.after_s))
        if kind in ("catch", "side_hit"):
            t_act = t_dead + rng.uniform(0.3, 0.9)
            if t_act < clip_end:
                fine = fine.until(t_act)
                pos = fine.pos[-1].copy()
                pos[2] = max(pos[2], self.radius)
                team = "near" if pos[1] < self.zones.net_y else "far"
                p = min(self.team(team), key=lambda q: np.linalg.norm(q.motion.sample(np.array([t_act]))[0] - pos[:2]))
                if kind == "side_hit":
                    side = 1.0 if pos[0] < self.zones.centre_x else -1.0
                    vel = np.array([side * rng.uniform(3.0, 7.0), rng.normal(0, 1.0), rng.uniform(2.0, 4.0)])
                    c = Contact(t_act, f"player_{team}", pos.copy(), player=p.pid, in_rally=False)
                    rest = simulate_flight(self.court, pos, vel, np.zeros(3), t_act, clip_end + 0.05, self.dt,
                                           self.model)
                    fine = Flight(np.concatenate([fine.t, rest.t[1:]]), np.concatenate([fine.pos, rest.pos[1:]]),
                                  np.concatenate([fine.vel, rest.vel[1:]]), np.concatenate([fine.spin, rest.spin[1:]]),
                                  fine.contacts + [c] + rest.contacts, rest.end)
                else:  # caught: the ball stays in the hand at waist height
                    hand = np.append(p.motion.sample(np.array([t_act]))[0], 1.0)
                    tt = np.array([t_act + 0.15, clip_end + 0.05])
                    fine = Flight(np.concatenate([fine.t, tt]), np.concatenate([fine.pos, [hand, hand]]),
                                  np.concatenate([fine.vel, np.zeros((2, 3))]),
                                  np.concatenate([fine.spin, np.zeros((2, 3))]), fine.contacts, "time")
        elif kind == "roll" and fine.t[-1] < clip_end:
            rest = simulate_flight(self.court, fine.pos[-1], fine.vel[-1], fine.spin[-1], float(fine.t[-1]),
                                   clip_end + 0.05, self.dt, self.model)
            fine = Flight(np.concatenate([fine.t, rest.t[1:]]), np.concatenate([fine.pos, rest.pos[1:]]),
                          np.concatenate([fine.vel, rest.vel[1:]]), np.concatenate([fine.spin, rest.spin[1:]]),
                          fine.contacts + rest.contacts, rest.end)
        fine = fine.until(clip_end)
        contacts = [c if c.t <= t_dead + 1e-6 else _outside(c) for c in fine.contacts]
        self.add_piece(Flight(fine.t, fine.pos, fine.vel, fine.spin, contacts, fine.end), last=True)
        return self.assemble(t_serve, t_dead, clip_end, outcome)

    # -- output ---------------------------------------------------------------------------------------

    def assemble(self, t_serve: float, t_dead: float, clip_end: float, outcome: str) -> Rally:
        """The :class:`Rally`: ball path, contacts, per-frame player plans and inactive balls."""
        n_frames = int(np.floor(clip_end * self.fps + 1e-9)) + 1
        ball = self.ball_path(t_serve, t_dead, (n_frames - 1) / self.fps)
        times = np.arange(n_frames) / self.fps
        ball_xy = ball.sample(times)[:, :2]
        plans = []
        for p in self.players:
            root = p.motion.sample(times)
            plans.append(PlayerPlan(
                player_id=p.pid, team=p.team, handed=p.handed, height=p.height, t=times, root=root,
                heading=self.headings(p, times, root, ball_xy, t_serve), swings=list(p.swings),
            ))
        contacts = sorted((c for c in self.contacts if 0.0 <= c.t <= times[-1]), key=lambda c: c.t)
        return Rally(
            sport=self.cfg.sport, fps=self.fps, n_frames=n_frames, ball=ball, contacts=contacts,
            players=plans, inactive_balls=self.inactive_balls(plans, ball, n_frames), outcome=outcome,
            t_serve=t_serve, t_dead=t_dead,
        )

    def ball_path(self, t_serve: float, t_dead: float, t_last: float) -> BallPath:
        """Concatenate the pieces over [0, t_last]: hold in the hand before, hold still after."""
        t = np.concatenate([f.t for f in self.pieces])
        data = np.concatenate([np.concatenate([f.pos, f.vel, f.spin], axis=1) for f in self.pieces])
        if t[0] > 0.0:  # the ball waits in the server's hand
            hold = np.arange(0.0, t[0] - 1e-9, self.dt)
            rest = np.concatenate([data[0, :3], np.zeros(6)])
            t, data = np.concatenate([hold, t]), np.concatenate([np.tile(rest, (len(hold), 1)), data])
        if t[-1] < t_last:  # the ball has left the court: it stays where it was last seen
            extra = np.arange(t[-1] + self.dt, t_last + self.dt, self.dt)
            rest = np.concatenate([data[-1, :3], np.zeros(6)])
            t, data = np.concatenate([t, extra]), np.concatenate([data, np.tile(rest, (len(extra), 1))])
        if t[0] < 0.0:
            at0 = np.array([np.interp(0.0, t, data[:, k]) for k in range(9)])
            keep = t > 1e-12
            t, data = np.concatenate([[0.0], t[keep]]), np.concatenate([at0[None], data[keep]])
        in_play = (t >= t_serve - 1e-9) & (t <= t_dead + 1e-9)
        return BallPath(t=t, pos=data[:, :3], vel=data[:, 3:6], spin=data[:, 6:9], in_play=in_play)

    def headings(self, p: _Player, times: np.ndarray, root: np.ndarray, ball_xy: np.ndarray,
                 t_serve: float) -> np.ndarray:
        """(T,) yaw (0 faces +y): towards the ball, towards the net around own strokes, rate-limited."""
        fwd = 0.0 if p.team == "near" else np.pi
        d = ball_xy - root
        toward_ball = np.arctan2(-d[:, 0], d[:, 1])
        ps = self.cfg.player
        w = np.where(times < t_serve, 1.0, 0.0)
        for s in p.swings:
            w = np.maximum(w, np.clip(1.0 - np.abs(times - s.t_hit) / ps.stroke_facing, 0.0, 1.0))
        w = np.where(np.linalg.norm(d, axis=1) < 0.3, 1.0, w)  # the ball is at the feet: face forward
        desired = (toward_ball + w * _wrap(fwd - toward_ball)).tolist()
        out = [desired[0]]
        max_turn = ps.turn_rate / self.fps
        for want in desired[1:]:
            turn = (want - out[-1] + np.pi) % TWO_PI - np.pi
            out.append(out[-1] + min(max(turn, -max_turn), max_turn))
        return _wrap(np.array(out))

    def inactive_balls(self, plans: list[PlayerPlan], ball: BallPath, n_frames: int) -> list[InactiveBall]:
        """Stationary balls on the floor, away from the players' feet and the ball's low path."""
        spec, rng, z = self.cfg.inactive, self.rng, self.zones
        n = int(rng.integers(spec.count[0], spec.count[1] + 1))
        floor = np.concatenate([pl.corners_3d() for pl in self.court.planes_for("ground")])
        lo, hi = floor.min(axis=0)[:2] + spec.edge_margin, floor.max(axis=0)[:2] - spec.edge_margin
        roots = np.stack([pl.root for pl in plans], axis=1)  # (T, P, 2)
        low = ball.pos[ball.pos[:, 2] < 1.0, :2]
        out: list[InactiveBall] = []
        for _ in range(60 * n):
            if len(out) == n:
                break
            xy = rng.uniform(lo, hi)
            if not spec.in_court and (z.in_half("near", xy, 0.3) or z.in_half("far", xy, 0.3)):
                continue
            first, last = 0, n_frames - 1
            if rng.random() < spec.p_partial:
                if rng.random() < 0.5:
                    first = int(rng.integers(0, n_frames // 2 + 1))
                else:
                    last = int(rng.integers(n_frames // 2, n_frames))
            near_feet = np.linalg.norm(roots[first : last + 1] - xy, axis=-1).min() < spec.feet_clearance
            near_ball = len(low) and np.linalg.norm(low - xy, axis=1).min() < spec.path_clearance
            near_other = any(np.linalg.norm(b.position[:2] - xy) < 0.3 for b in out)
            if near_feet or near_ball or near_other:
                continue
            out.append(InactiveBall(len(out), np.array([xy[0], xy[1], self.radius]), first, last))
        return out


def _outside(c: Contact) -> Contact:
    """The same contact marked as outside the point."""
    return Contact(c.t, c.event, c.position, c.plane, c.player, in_rally=False)


def _shifted(flight: Flight, dt: float) -> Flight:
    """The same flight ``dt`` seconds later."""
    contacts = [Contact(c.t + dt, c.event, c.position, c.plane, c.player, c.in_rally) for c in flight.contacts]
    return Flight(flight.t + dt, flight.pos, flight.vel, flight.spin, contacts, flight.end)


def _wrap(a):
    """Angles wrapped to (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a), TWO_PI)


def _weighted(rng: np.random.Generator, weights: dict[str, float]) -> str:
    """A key drawn with probability proportional to its weight."""
    names = list(weights)
    w = np.array([weights[n] for n in names], dtype=float)
    return names[int(rng.choice(len(names), p=w / w.sum()))]


def simulate_rally(
    court: Court,
    fps: float,
    rng: np.random.Generator,
    sport: str | None = None,
    n_players: int | None = None,
    config: RallyConfig | None = None,
) -> Rally:
    """Simulate one rally on a court.

    Args:
        court: the court model (its planes, materials and ball).
        fps: the clip's frame rate; the ball is integrated at ≤ 1/600 s and ≥ 10 substeps per frame.
        rng: the only source of randomness (same seed → identical rally).
        sport: rules to apply (default: the court's sport).
        n_players: 4 (doubles) or 2 (singles); default from the sport's config.
        config: planner constants (default: :func:`default_config` of the sport).
    Returns:
        the :class:`Rally` (ball path over the whole clip, contacts, player plans, inactive balls).
    """
    cfg = config or default_config(sport or court.sport)
    return _Planner(court, fps, rng, cfg, n_players or cfg.n_players).run()
