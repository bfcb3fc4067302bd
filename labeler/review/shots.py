"""Per-shot analytics of a reconstructed rally: speeds, net clearance, bounce positions and line calls.

UI-free: everything here works on arrays and clip files, so it is unit-tested without a server.

A *shot* runs from one racket hit (``player_near`` / ``player_far`` in events.csv) to the next hit (or the
end of the clip). Its surface contacts (floor, glass, mesh, net) come from events.csv, placed in 3D by
segments.json's fitted contact points (else ball_3d.csv at that frame).

Rules applied (:func:`judge_shot`), with the court frame of docs/formats.md:

- **Target.** A shot must first bounce on the floor in the opponent's half, inside the lines. The lines
  belong to the court: the court YAML's coordinates are the lines' outer edges, and a bounce whose ball
  centre is on or inside them is *in* (the contact patch is not modelled). The serve (the first hit of the
  clip, when the hitter stands behind their own service line) must land in the diagonal service box.
- **Padel.** Before the floor bounce the ball may come off the hitter's *own* glass (a legal play); any
  contact with the opponent's glass or with any mesh before the floor bounce is *out* (*fault* on a serve).
  After a good bounce glass rebounds are legal; a serve that bounces in and then hits the mesh before
  bouncing again is a *fault*. A net touch followed by a good bounce is in (a *let* on a serve).
- **Tennis.** Singles lines when the court YAML says ``players: 2`` (the shipped ``tennis.yaml``), doubles
  lines otherwise; the service boxes are singles-width in both.
- **Distance to the nearest line** is signed, in centimetres: positive inside the target area (distance to
  its closest boundary line), negative outside (distance to the area), 0 on the line. Its 1-σ uncertainty is
  the bounce position's covariance (ball_3d.csv) along the direction across that line; a call with
  ``|distance| <= 2σ`` is flagged *too close to call* (the call stays, the flag says it is not certain).

What the review never does (:func:`analyse_reconstruction`): give a figure or a call from a flight that
failed its checks. A shot whose frames overlap a flight of segments.json with ``reconstructed: false``, or
that has no 3D row inside it, is marked *no 3D* (:attr:`Shot.no_3d`): no speed, no clearance, no call,
verdict ``-``. The clip-level check (segments.json's ``plausibility``) comes with the analysis
(:class:`Plausibility`).

Example:
    >>> analysis = analyse_clip(Clip("runs/demo/padel_sample"))
    >>> [(s.team, s.verdict, s.first_bounce.distance_cm) for s in analysis.shots]
    >>> write_shots_csv("shots.csv", analysis)
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inference.clipio import Ball3D, Clip, HitEvents
from inference.clipio.atomic import atomic_write_text
from inference.clipio.errors import FormatError
from inference.clipio.structured import load_json
from inference.court import Court, load_court

HIT_EVENTS = ("player_near", "player_far")
WALL_EVENTS = ("wall_near", "wall_far", "wall_left", "wall_right")
CALLS = ("in", "out", "fault", "-")
"""Line calls: ``-`` = not judged (before the serve, after the point was decided, or no 3D position)."""
VERDICTS = ("in", "out", "fault", "let", "-")
ON_LINE_TOL_M = 1e-9
TOO_CLOSE_SIGMAS = 2.0
"""A call whose distance to its line is at most this many σ (across the line) is *too close to call*."""
SERVE_REACH_M = 1.0
"""A serve's ball may be struck up to this far in front of the server's service line."""
KMH = 3.6


def other_team(team: str) -> str:
    return {"near": "far", "far": "near"}[team]


# ---------------------------------------------------------------------------------------- court areas
@dataclass(frozen=True)
class Area:
    """An axis-aligned rectangle on the floor, ``x0 <= x <= x1``, ``y0 <= y <= y1`` (metres), with the
    name of the line on each edge (order x0, x1, y0, y1)."""

    x0: float
    x1: float
    y0: float
    y1: float
    lines: tuple[str, str, str, str]
    name: str = ""

    def __post_init__(self) -> None:
        if not (self.x0 < self.x1 and self.y0 < self.y1):
            raise ValueError(f"area {self.name!r} must have x0 < x1 and y0 < y1, got {self}")

    def signed_distance(self, xy) -> tuple[float, str]:
        """(2,) floor point → (signed distance in m, name of the nearest line): > 0 inside, < 0 outside.

        Examples:
            >>> Area(0, 10, 10, 20, ("left", "right", "net", "baseline")).signed_distance((9.5, 15))
            (0.5, 'right')
        """
        x, y = float(xy[0]), float(xy[1])
        d = np.array([x - self.x0, self.x1 - x, y - self.y0, self.y1 - y])
        if (d >= -ON_LINE_TOL_M).all():
            k = int(np.argmin(d))
            return float(max(d[k], 0.0)), self.lines[k]
        ox, oy = max(-d[0], -d[1], 0.0), max(-d[2], -d[3], 0.0)
        k = int(np.argmin(d))  # the most violated edge is the line the ball landed beyond
        return -float(math.hypot(ox, oy)), self.lines[k]

    def across(self, xy) -> np.ndarray:
        """(2,) floor point → (2,) unit direction along which :meth:`signed_distance` changes fastest there:
        across the nearest line (inside, or beside the area), diagonal beyond a corner."""
        x, y = float(xy[0]), float(xy[1])
        ox = max(self.x0 - x, x - self.x1, 0.0)
        oy = max(self.y0 - y, y - self.y1, 0.0)
        if ox > ON_LINE_TOL_M or oy > ON_LINE_TOL_M:
            return np.array([ox, oy]) / math.hypot(ox, oy)
        d = np.array([x - self.x0, self.x1 - x, y - self.y0, self.y1 - y])
        return np.array([1.0, 0.0]) if int(np.argmin(d)) < 2 else np.array([0.0, 1.0])


def sigma_across(direction: np.ndarray, cov: np.ndarray) -> float:
    """1-σ (m) of a position with covariance ``cov`` ((3, 3) or (2, 2), m²) along the unit floor ``direction``
    (2,); NaN when the covariance is unknown (NaN) or not a covariance."""
    c = np.asarray(cov, float)[:2, :2]
    var = float(direction @ c @ direction)
    return math.sqrt(var) if math.isfinite(var) and var >= 0 else float("nan")


@dataclass(frozen=True)
class CourtRules:
    """What the line calls need from a court.

    Attributes:
        sport: ``padel`` or ``tennis``; walls: whether glass/mesh walls exist (padel).
        net_y: y of the net; length: court length (baselines at 0 and ``length``).
        x_min, x_max: side lines of the rally (tennis singles or doubles, padel side walls).
        service_y: (near, far) y of the service lines; centre_x: x of the centre service line.
        service_x: (min, max) side lines of the service boxes.
        singles: tennis singles lines in use.
    """

    sport: str
    walls: bool
    net_y: float
    length: float
    x_min: float
    x_max: float
    service_y: tuple[float, float]
    centre_x: float
    service_x: tuple[float, float]
    singles: bool = False

    @classmethod
    def from_court(cls, court: Court, singles: bool | None = None) -> CourtRules:
        """Read the rule geometry from the court's named points (padel and tennis YAMLs)."""
        sport = court.sport
        if sport not in ("padel", "tennis"):
            raise FormatError(court.source or court.name, f"no line-call rules for sport {sport!r}",
                              fix="line calls know padel and tennis; set `sport:` in the court YAML")

        def pt(name: str) -> np.ndarray:
            if name not in court.points:
                raise FormatError(court.source or court.name, f"line calls need the point {name!r}",
                                  fix="add it to the court YAML's `points:`")
            return court.points[name]

        length = float(court.size[1])
        service_y = (float(pt("near_service_center")[1]), float(pt("far_service_center")[1]))
        centre_x = float(pt("near_service_center")[0])
        service_x = (float(pt("near_service_left")[0]), float(pt("near_service_right")[0]))
        if sport == "tennis":
            singles = court.n_players == 2 if singles is None else singles
            if singles:
                x_min, x_max = float(pt("near_singles_left")[0]), float(pt("near_singles_right")[0])
            else:
                x_min, x_max = float(pt("near_left")[0]), float(pt("near_right")[0])
        else:
            singles = False
            x_min, x_max = 0.0, float(court.size[0])
        return cls(sport, sport == "padel", float(court.net_y), length, x_min, x_max, service_y, centre_x,
                   service_x, singles)

    def side_of(self, y: float) -> str:
        """``near`` (y < net) or ``far``."""
        return "near" if y < self.net_y else "far"

    def _side_names(self) -> tuple[str, str]:
        kind = "singles side line" if self.singles else "side line"
        return f"left {kind}", f"right {kind}"

    def half(self, side: str) -> Area:
        """The playing area of one half, net to baseline."""
        left, right = self._side_names()
        if side == "far":
            return Area(self.x_min, self.x_max, self.net_y, self.length, (left, right, "net", "far baseline"),
                        "far half")
        return Area(self.x_min, self.x_max, 0.0, self.net_y, (left, right, "near baseline", "net"), "near half")

    def service_box(self, side: str, server_x: float) -> Area:
        """The service box on ``side`` diagonal to a server standing at ``server_x`` (cross-court)."""
        left_of_centre = server_x >= self.centre_x  # serving from the right goes to the left box
        lo, hi = self.service_x
        side_kind = "singles side line" if self.sport == "tennis" else "side line"
        if left_of_centre:
            x0, x1, lx = lo, self.centre_x, (f"left {side_kind}", "centre service line")
        else:
            x0, x1, lx = self.centre_x, hi, ("centre service line", f"right {side_kind}")
        if side == "far":
            return Area(x0, x1, self.net_y, self.service_y[1], (*lx, "net", "far service line"),
                        f"far {'left' if left_of_centre else 'right'} service box")
        return Area(x0, x1, self.service_y[0], self.net_y, (*lx, "near service line", "net"),
                    f"near {'left' if left_of_centre else 'right'} service box")

    def behind_service_line(self, team: str, y: float, reach: float = SERVE_REACH_M) -> bool:
        """Whether a ball hit at ``y`` by ``team`` can be a serve: at most ``reach`` in front of the team's own
        service line (the server stands behind it; the ball is struck a little ahead of the feet)."""
        return y <= self.service_y[0] + reach if team == "near" else y >= self.service_y[1] - reach


# -------------------------------------------------------------------------------------------- records
@dataclass(frozen=True)
class Contact:
    """One event of events.csv placed in 3D.

    Attributes:
        frame: frame of the contact; event: events.csv label; position: (3,) ball centre (m), NaN unknown;
        plane: court plane touched (segments.json), None for hits or when unknown;
        cov: (3, 3) the position's covariance (m², ball_3d.csv), NaN unknown.
    """

    frame: int
    event: str
    position: np.ndarray
    plane: str | None = None
    cov: np.ndarray | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float).reshape(3)
        object.__setattr__(self, "position", p)
        c = np.full((3, 3), np.nan) if self.cov is None else np.asarray(self.cov, dtype=float).reshape(3, 3)
        object.__setattr__(self, "cov", c)

    @property
    def known(self) -> bool:
        return bool(np.isfinite(self.position).all())

    @property
    def surface(self) -> str:
        """The plane's name when known, else the event label."""
        return self.plane or self.event


@dataclass(frozen=True)
class BounceCall:
    """The line call of one floor bounce.

    Attributes:
        frame: bounce frame; xy: (2,) ball centre on the floor (m); call: one of :data:`CALLS`;
        distance_cm: signed distance to the nearest line of the target area (+ in, − out), NaN when not
        judged; line: that line's name; reason: a sentence; target: the area judged against.
        sigma_cm: 1-σ of the bounce position across that line (cm), NaN unknown.
        uncertain: ``|distance_cm| <= 2 sigma_cm``: too close to call (False when σ is unknown).
    """

    frame: int
    xy: np.ndarray
    call: str
    distance_cm: float = float("nan")
    line: str = ""
    reason: str = ""
    target: str = ""
    sigma_cm: float = float("nan")
    uncertain: bool = False

    def __post_init__(self) -> None:
        if self.call not in CALLS:
            raise ValueError(f"call must be one of {CALLS}, got {self.call!r}")

    @property
    def judged(self) -> bool:
        """Whether the call was made against a line (a distance is known)."""
        return math.isfinite(self.distance_cm)


def _cm(v: float) -> str:
    return f"{v:.1f}" if abs(v) < 1 else f"{v:.0f}"


def sigma_note(b: BounceCall) -> str:
    """The uncertainty of a judged call in words: ``within 2σ (±4 cm): too close to call``, ``±4 cm at 2σ`` or
    ``σ unknown`` ("" for a call not judged against a line)."""
    if not b.judged:
        return ""
    if not math.isfinite(b.sigma_cm):
        return "σ unknown"
    band = _cm(TOO_CLOSE_SIGMAS * b.sigma_cm)
    return f"within 2σ (±{band} cm): too close to call" if b.uncertain else f"±{band} cm at 2σ"


def call_text(b: BounceCall) -> str:
    """A call in words, e.g. ``in, 3 cm inside the right side line — within 2σ (±4 cm): too close to call``;
    a call not judged against a line gives its reason."""
    if not b.judged:
        return f"{b.call}: {b.reason}" if b.reason else b.call
    d = b.distance_cm
    side = "inside" if d > 0 else "outside"
    where = f"on the {b.line}" if d == 0 else f"{_cm(abs(d))} cm {side} the {b.line}"
    note = sigma_note(b)
    return f"{b.call}, {where} — {note}" if b.uncertain else f"{b.call}, {where} ({note})"


@dataclass
class Shot:
    """One shot: from a racket hit to the next hit.

    Attributes:
        index: 0-based; team: ``near`` / ``far`` (the hitter's); serve: judged as a serve.
        hit: the racket contact; end_frame: last frame of the shot (next hit or end of the ball track).
        contacts: surface contacts after the hit, in order.
        bounces: the call of every floor bounce of the shot.
        verdict: one of :data:`VERDICTS` for the shot as a whole; reason: why.
        launch_speed_kmh, max_speed_kmh, bounce_speed_kmh: speeds (NaN unknown).
        net_clearance_m: height of the ball's bottom above the net top where it crosses the net plane
            (negative = below the top: it hit or went through the net; NaN if it did not cross).
        no_3d: why the shot has no trustworthy 3D ("" when it has): then no figure, no call, verdict ``-``.
        depth_from: what pinned its flight's depth along the line of sight (segments.json; "" unknown).
    """

    index: int
    team: str
    serve: bool
    hit: Contact
    end_frame: int
    contacts: list[Contact] = field(default_factory=list)
    bounces: list[BounceCall] = field(default_factory=list)
    verdict: str = "-"
    reason: str = ""
    launch_speed_kmh: float = float("nan")
    max_speed_kmh: float = float("nan")
    bounce_speed_kmh: float = float("nan")
    net_clearance_m: float = float("nan")
    no_3d: str = ""
    depth_from: str = ""

    @property
    def first_bounce(self) -> BounceCall | None:
        return self.bounces[0] if self.bounces else None

    @property
    def has_3d(self) -> bool:
        return not self.no_3d


@dataclass(frozen=True)
class Plausibility:
    """The clip-level check of a reconstruction (segments.json's ``plausibility``), as the review reports it.

    Attributes:
        judged: a check exists (False: no segments.json, or one without ``plausibility``).
        plausible: the check passed (only a JSON ``true`` counts); because: its sentences when it did not.
        flights, failed: flight counts (None unknown); covered_share: share of the rally's frames with 3D
            (0–1, None unknown).
    """

    judged: bool
    plausible: bool = False
    because: tuple[str, ...] = ()
    flights: int | None = None
    failed: int | None = None
    covered_share: float | None = None

    @classmethod
    def from_segments_json(cls, doc: object) -> Plausibility:
        """From segments.json's parsed content (None when the file is absent); tolerant of damaged values."""
        p = doc.get("plausibility") if isinstance(doc, dict) else None
        if not isinstance(p, dict):
            return cls(judged=False)
        because = p.get("not_plausible_because")
        because = tuple(str(b) for b in because) if isinstance(because, list) else ()
        return cls(True, p.get("plausible") is True, because, _count(p.get("flights")),
                   _count(p.get("failed")), _share(p.get("covered_share")))

    def banner(self) -> str:
        """The warning that comes first in every view ("" when the check passed)."""
        if not self.judged:
            return ("3D NOT judged: segments.json has no plausibility check (absent, or from an older "
                    "rally3d) — calls and figures below are unchecked")
        if self.plausible:
            return ""
        why = "; ".join(self.because) or (f"{self.failed}/{self.flights} flights failed" if self.failed else
                                          "the reconstruction failed its checks")
        return (f"3D NOT plausible: {why} — calls and figures below come only from the flights that passed "
                "their checks")

    def coverage(self) -> str:
        """``3D covers 76% of the rally`` ("" when unknown)."""
        return "" if self.covered_share is None else f"3D covers {self.covered_share:.0%} of the rally"

    def lines(self) -> list[str]:
        """The status lines every view shows first: the banner (or ``3D plausible: …``), then the coverage."""
        head = self.banner()
        if not head:
            ok = f"{self.flights - (self.failed or 0)}/{self.flights}" if self.flights else ""
            head = "3D plausible" + (f": {ok} flights reconstructed" if ok else "")
        return [head, *([self.coverage()] if self.coverage() else [])]


def _count(v: object) -> int | None:
    return v if isinstance(v, int) and not isinstance(v, bool) and v >= 0 else None


def _share(v: object) -> float | None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and 0 <= v <= 1
    return float(v) if ok else None


@dataclass
class RallyAnalysis:
    """Every shot of a rally plus the floor bounces before the first hit (the padel serve's drop), and the
    clip-level check of its reconstruction (None: not a reconstruction, e.g. ground truth)."""

    shots: list[Shot]
    pre_serve: list[BounceCall] = field(default_factory=list)
    sport: str = ""
    plausibility: Plausibility | None = None

    def status_lines(self) -> list[str]:
        """What every view shows first about the 3D (:meth:`Plausibility.lines`; [] without a check)."""
        return self.plausibility.lines() if self.plausibility is not None else []

    @property
    def bounces(self) -> list[BounceCall]:
        """Every floor bounce with its call, in frame order."""
        return sorted([*self.pre_serve, *(b for s in self.shots for b in s.bounces)], key=lambda b: b.frame)

    def shot_at(self, frame: int) -> Shot | None:
        """The shot in flight at ``frame`` (None before the first hit)."""
        cur = None
        for s in self.shots:
            if s.hit.frame <= frame:
                cur = s
        return cur


# ------------------------------------------------------------------------------------------ the rules
def judge_shot(rules: CourtRules, team: str, contacts: list[Contact], *, serve: bool = False,
               server_x: float = float("nan"), volleyed: bool = False) -> tuple[str, str, list[BounceCall]]:
    """Apply the rules (module docstring) to one shot by ``team``.

    Args:
        rules: the court's rule geometry.
        team: the hitter's team, ``near`` or ``far``.
        contacts: the surface contacts after the hit, in time order (no racket hits).
        serve: judge against the diagonal service box of a server at ``server_x``.
        volleyed: the next racket hit ended the shot (a volley when no floor bounce came first).
    Returns:
        (verdict, reason, one :class:`BounceCall` per floor contact).
    """
    if team not in ("near", "far"):
        raise ValueError(f"team must be near or far, got {team!r}")
    opp = other_team(team)
    bad = "fault" if serve else "out"
    verdict, reason = "", ""
    calls: list[BounceCall] = []
    bounced_in = False
    touched_net = False
    close_note = ""
    for c in contacts:
        xy = c.position[:2]
        if verdict:  # the point is decided; later contacts are not judged
            if c.event == "ground":
                calls.append(BounceCall(c.frame, xy, "-", reason="after the point was decided"))
            continue
        if c.event in HIT_EVENTS:
            raise ValueError(f"frame {c.frame}: a racket hit inside a shot's contacts")
        if not c.known:
            if c.event == "ground":
                calls.append(BounceCall(c.frame, xy, "-", reason="no 3D position for this bounce"))
            if not bounced_in:
                verdict, reason = "-", f"no 3D position for the {c.event} contact at frame {c.frame}"
            continue
        if c.event == "net":
            touched_net = True
            continue
        if c.event == "ground":
            if bounced_in:  # the receiver let it bounce twice
                calls.append(BounceCall(c.frame, xy, "-", reason="second bounce: the point goes to the hitter"))
                verdict, reason = "in", "bounced in, then bounced again before a return"
                continue
            area = rules.service_box(opp, server_x) if serve else rules.half(opp)
            d, line = area.signed_distance(xy)
            if rules.side_of(xy[1]) == team:
                call, why = bad, "bounced on the hitter's own side (did not cross the net)"
            elif d >= -ON_LINE_TOL_M:
                call, why = "in", f"inside the {area.name}"
            else:
                call, why = bad, f"{-d * 100:.0f} cm beyond the {line}"
            sigma = sigma_across(area.across(xy), c.cov)
            close = bool(sigma > 0 and abs(d) <= TOO_CLOSE_SIGMAS * sigma)
            b = BounceCall(c.frame, xy, call, round(d * 100, 1), line, why, area.name,
                           round(sigma * 100, 1) if math.isfinite(sigma) else float("nan"), close)
            calls.append(b)
            note = (f"; the bounce is within 2σ (±{_cm(TOO_CLOSE_SIGMAS * b.sigma_cm)} cm) of the {line}: "
                    "too close to call" if close else "")
            if call != "in":
                verdict, reason = call, f"first bounce {why}{note}"
            else:
                bounced_in = True
                close_note = note
            continue
        # a wall or the mesh (padel)
        if not bounced_in:
            if rules.walls and c.event in WALL_EVENTS and rules.side_of(c.position[1]) == team:
                continue  # played off the hitter's own glass: legal
            verdict, reason = bad, f"hit the {c.surface} before bouncing on the floor"
        elif serve and c.event == "mesh":
            verdict, reason = "fault", "the serve bounced in, then hit the mesh"
        # glass (and, in the rally, mesh) after a good bounce: legal
    if not verdict:
        if bounced_in:
            verdict = "let" if serve and touched_net else "in"
            reason = ("touched the net, then bounced in the service box" if verdict == "let"
                      else "bounced in; returned after the bounce") + close_note
        elif volleyed:
            verdict, reason = "in", "returned before the bounce (volley)"
        else:
            verdict, reason = "-", "no floor bounce before the end of the clip"
    return verdict, reason, calls


# --------------------------------------------------------------------------------------- the analysis
COV_COLUMNS = ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2")
"""ball_3d.csv's optional covariance columns (docs/formats.md §13)."""


def covariances(ball: Ball3D) -> np.ndarray:
    """(N, 3, 3) the rows' position covariances (m²) from :data:`COV_COLUMNS`; NaN where unknown (a column
    absent, a cell empty or not a number)."""
    out = np.full((len(ball), 3, 3), np.nan)
    if not all(c in ball.extra for c in COV_COLUMNS):
        return out
    v = {c: _floats(ball.extra[c]) for c in COV_COLUMNS}
    for c, (i, j) in zip(COV_COLUMNS, ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        out[:, i, j] = out[:, j, i] = v[c]
    return out


def _floats(text: np.ndarray) -> np.ndarray:
    """(N,) strings → (N,) floats, NaN for empty, non-numeric or infinite cells."""
    out = np.full(len(text), np.nan)
    for k, t in enumerate(np.asarray(text).tolist()):
        try:
            out[k] = float(t)
        except (TypeError, ValueError):
            pass
    out[~np.isfinite(out)] = np.nan
    return out


@dataclass(frozen=True)
class Trajectory:
    """The 3D ball per frame: frame (N,) sorted unique, xyz (N, 3) metres; cov (N, 3, 3) m², NaN unknown
    (None: no covariance at all)."""

    frame: np.ndarray
    xyz: np.ndarray
    cov: np.ndarray | None = None

    @classmethod
    def from_ball_3d(cls, ball: Ball3D) -> Trajectory:
        """One position per frame; where a frame has several kinds, ``contact`` beats ``fitted`` beats ``gt``."""
        rank = {"contact": 0, "fitted": 1, "gt": 2}
        order = np.lexsort((np.array([rank.get(k, 3) for k in ball.kind]), ball.frame))
        f = ball.frame[order]
        keep = np.r_[True, f[1:] != f[:-1]] if len(f) else np.zeros(0, bool)
        return cls(f[keep], ball.xyz[order][keep], covariances(ball)[order][keep])

    def without(self, spans: list[tuple[int, int]]) -> Trajectory:
        """The trajectory less the frames strictly inside each ``(start, end)`` span."""
        drop = np.zeros(len(self.frame), bool)
        for a, b in spans:
            drop |= (self.frame > a) & (self.frame < b)
        return Trajectory(self.frame[~drop], self.xyz[~drop], None if self.cov is None else self.cov[~drop])

    def cov_near(self, frame: int, start: int, stop: int) -> np.ndarray:
        """(3, 3) the covariance at ``frame``, else at the nearest frame of ``start … stop`` that has one;
        NaN when none does."""
        if self.cov is None:
            return np.full((3, 3), np.nan)
        m = (self.frame >= start) & (self.frame <= stop) & np.isfinite(self.cov).all(axis=(1, 2))
        if not m.any():
            return np.full((3, 3), np.nan)
        k = np.flatnonzero(m)[int(np.argmin(np.abs(self.frame[m] - frame)))]
        return self.cov[k]

    def at(self, frame: int) -> np.ndarray:
        """(3,) position at ``frame``; NaN where there is none."""
        k = int(np.searchsorted(self.frame, frame))
        if k < len(self.frame) and self.frame[k] == frame:
            return self.xyz[k]
        return np.full(3, np.nan)

    def window(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Frames and positions with ``start <= frame <= stop``."""
        m = (self.frame >= start) & (self.frame <= stop)
        return self.frame[m], self.xyz[m]


def speeds_kmh(frames: np.ndarray, xyz: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Speeds between consecutive frames: (M,) the later frame of each pair and (M,) km/h."""
    if len(frames) < 2:
        return np.zeros(0, np.int64), np.zeros(0)
    ok = np.diff(frames) == 1
    v = np.linalg.norm(np.diff(xyz, axis=0), axis=1) * fps * KMH
    return frames[1:][ok], v[ok]


def net_clearance(court: Court, xyz: np.ndarray) -> float:
    """Ball bottom above the net top where the path (K, 3) first crosses the net plane; NaN if it does not."""
    from inference.reconstruct.joint import net_height

    nets = [p for p in court.planes if p.event == "net"]
    if not nets or len(xyz) < 2:
        return float("nan")
    net = nets[0]
    d = (xyz - net.origin) @ net.normal
    cross = np.flatnonzero((np.sign(d[:-1]) * np.sign(d[1:]) < 0) | (d[1:] == 0))
    if not len(cross):
        return float("nan")
    k = int(cross[0])
    f = d[k] / (d[k] - d[k + 1]) if d[k] != d[k + 1] else 1.0
    p = xyz[k] + f * (xyz[k + 1] - xyz[k])
    return float(p[2] - court.ball.radius - net_height(net, p))


#: a tennis serve is struck overhead: its hit is at least this high (m); a rally shot rarely is
OVERHEAD_SERVE_M = 1.8
#: a padel serve's drop falls from the hand: slower than this horizontally (m/s) before the hit
DROP_SPEED_MS = 3.0


def looks_like_serve(rules: CourtRules, traj: Trajectory, team: str, hit: Contact, pre: list[Contact],
                     fps: float) -> bool:
    """Whether the clip's first hit shows a serve's set-up, so that it is judged as a serve (clips cut
    mid-rally are normal: without the set-up the first hit is a rally shot). Padel: nothing before it but
    the drop's floor bounce on the server's side, and the ball slow horizontally over the 0.4 s before the
    hit (dropped from the hand, not arriving from the other side; at least 3 frames of the 3D track show
    it). Tennis: nothing before it and an overhead hit."""
    if rules.sport != "padel":
        return not pre and float(hit.position[2]) >= OVERHEAD_SERVE_M
    if len(pre) > 1 or (pre and (pre[0].event != "ground" or not pre[0].known
                                 or rules.side_of(float(pre[0].position[1])) != team)):
        return False
    frames, xyz = traj.window(hit.frame - int(round(0.4 * fps)), hit.frame - 1)
    if len(frames) < 3:
        return False
    speed = np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1) / (np.diff(frames) / fps)
    return bool(speed.max() < DROP_SPEED_MS)


@dataclass(frozen=True)
class Flight:
    """One flight of segments.json: frames ``start … end``; ``reason`` why it failed ("" if reconstructed);
    ``depth_from``: what pinned its depth along the camera's line of sight ("" when not said)."""

    index: int
    start: int
    end: int
    reconstructed: bool
    reason: str = ""
    depth_from: str = ""


def flights_of(segments: list) -> list[Flight]:
    """segments.json's ``segments`` → :class:`Flight` s; entries without integer frames are skipped. Only a
    JSON ``true`` counts as reconstructed."""
    out = []
    for s in segments:
        if not isinstance(s, dict):
            continue
        a, b = s.get("start_frame"), s.get("end_frame")
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (a, b)) or b < a:
            continue
        ok = s.get("reconstructed") is True
        idx = s.get("index")
        idx = idx if isinstance(idx, int) and not isinstance(idx, bool) else -1
        depth = s.get("depth_from") if ok and isinstance(s.get("depth_from"), str) else ""
        out.append(Flight(idx, a, b, ok, "" if ok else str(s.get("reason") or "failed its checks"), depth))
    return out


def no_3d_reason(start: int, end: int, traj: Trajectory, flights: list[Flight]) -> str:
    """Why frames ``start … end`` (a shot) have no trustworthy 3D: the failed flights that overlap them (more
    than a shared end frame), else a trajectory with no row strictly inside them; "" when they have 3D."""
    failed = [f for f in flights if not f.reconstructed and f.start < end and f.end > start]
    if failed:
        return "; ".join(f"flight {f.start}–{f.end} failed: {f.reason}" for f in failed)
    inner = traj.window(start + 1, end - 1) if end - start > 1 else traj.window(start, end)
    return "" if len(inner[0]) else f"no 3D rows for frames {start}–{end}"


def depth_from(start: int, end: int, flights: list[Flight]) -> str:
    """What pinned the depth of the reconstructed flight leaving the hit at ``start`` (the first one that
    overlaps frames ``start … end``), "" when segments.json does not say."""
    for f in flights:
        if f.reconstructed and f.start < end and f.end > start and f.depth_from:
            return f.depth_from
    return ""


def analyse_rally(court: Court, traj: Trajectory, contacts: list[Contact], fps: float, *,
                  rules: CourtRules | None = None, first_hit_is_serve: bool = True,
                  flights: list[Flight] | None = None,
                  plausibility: Plausibility | None = None) -> RallyAnalysis:
    """Split a rally's contacts into shots and compute every figure and call.

    Args:
        court: the court; traj: the 3D ball; contacts: every event in frame order (hits and surfaces);
        fps: frame rate.
        rules: line-call geometry (default from ``court``).
        first_hit_is_serve: treat the clip's first hit as the serve when its hitter stands behind their
            service line and the clip shows the serve's set-up (:func:`looks_like_serve`); False judges
            every shot as a rally shot.
        flights: segments.json's flights; a shot overlapping a failed one gets no figure and no call
            (:func:`no_3d_reason`; so does a shot with no 3D row).
        plausibility: the clip-level check, carried to the result.
    """
    rules = rules or CourtRules.from_court(court)
    contacts = sorted(contacts, key=lambda c: c.frame)
    hits = [i for i, c in enumerate(contacts) if c.event in HIT_EVENTS]
    last_frame = int(traj.frame[-1]) if len(traj.frame) else (contacts[-1].frame if contacts else 0)
    pre = contacts[: hits[0]] if hits else contacts
    pre_calls = [BounceCall(c.frame, c.position[:2], "-", reason="before the first hit (serve drop)")
                 for c in pre if c.event == "ground"]
    shots: list[Shot] = []
    for n, i in enumerate(hits):
        hit = contacts[i]
        j = hits[n + 1] if n + 1 < len(hits) else len(contacts)
        end = contacts[j].frame if j < len(contacts) else max(last_frame, contacts[-1].frame)
        team = hit.event.removeprefix("player_")
        serve = (first_hit_is_serve and n == 0 and hit.known
                 and rules.behind_service_line(team, float(hit.position[1]))
                 and looks_like_serve(rules, traj, team, hit, pre, fps))
        inner = contacts[i + 1: j]
        why = no_3d_reason(hit.frame, int(end), traj, flights or [])
        if why:
            shots.append(_shot_without_3d(n, team, bool(serve), hit, int(end), list(inner), why))
            continue
        verdict, reason, calls = judge_shot(rules, team, inner, serve=serve, server_x=float(hit.position[0]),
                                            volleyed=j < len(contacts))
        shot = Shot(n, team, bool(serve), hit, int(end), list(inner), calls, verdict, reason,
                    depth_from=depth_from(hit.frame, int(end), flights or []))
        _add_figures(shot, court, traj, fps)
        shots.append(shot)
    return RallyAnalysis(shots, pre_calls, rules.sport, plausibility)


def _shot_without_3d(index: int, team: str, serve: bool, hit: Contact, end: int, contacts: list[Contact],
                     why: str) -> Shot:
    """A shot with no trustworthy 3D: its floor bounces listed, none called, no figure, verdict ``-``."""
    reason = f"no 3D: {why}"
    nowhere = np.full(2, np.nan)
    calls = [BounceCall(c.frame, nowhere, "-", reason=reason) for c in contacts if c.event == "ground"]
    return Shot(index, team, serve, hit, end, contacts, calls, "-", reason, no_3d=why)


def _add_figures(shot: Shot, court: Court, traj: Trajectory, fps: float) -> None:
    """Speeds and net clearance of a shot from the per-frame trajectory."""
    f0 = shot.hit.frame
    grounds = [c.frame for c in shot.contacts if c.event == "ground"]
    bounce = grounds[0] if grounds else shot.end_frame
    frames, xyz = traj.window(f0, shot.end_frame)
    sf, sv = speeds_kmh(frames, xyz, fps)
    after = sv[sf >= f0 + 2]  # strictly after the hit: the hit frame is rounded to the nearest frame
    if len(after):
        shot.launch_speed_kmh = round(float(after[0]), 1)
        shot.max_speed_kmh = round(float(after.max()), 1)
    if grounds:
        before = sv[(sf < bounce) & (sf > f0 + 1)]
        if len(before):
            shot.bounce_speed_kmh = round(float(before[-1]), 1)
    fl, pts = traj.window(f0, bounce)
    if len(pts) >= 2:
        c = net_clearance(court, pts)
        shot.net_clearance_m = round(c, 3) if math.isfinite(c) else float("nan")


# ------------------------------------------------------------------------------------------- clip I/O
def read_segments_json(path: Path) -> dict | None:
    """segments.json's content (None when the file is absent); :class:`FormatError` unless it is an object
    with a ``segments`` list."""
    if not path.is_file():
        return None
    data = load_json(path, fix="re-run `rally3d reconstruct <clip>`")
    if not isinstance(data, dict) or not isinstance(data.get("segments"), list):
        raise FormatError(path, "expected an object with a `segments` list", fix="re-run `rally3d reconstruct <clip>`")
    return data


def read_segments(path: Path) -> list[dict]:
    """segments.json's ``segments`` list ([] when the file is absent)."""
    data = read_segments_json(path)
    return [] if data is None else data["segments"]


def contacts_from_tables(events: HitEvents, traj: Trajectory, segments: list[dict]) -> list[Contact]:
    """Place each event in 3D: the fitted contact point of segments.json where a reconstructed segment
    starts or ends at that frame (with its plane), else the trajectory at that frame (NaN if none). Its
    covariance is the trajectory's at that frame, else at the nearest frame of a reconstructed flight through
    it (:meth:`Trajectory.cov_near`)."""
    fitted: dict[int, tuple[list, str | None]] = {}
    spans: dict[int, tuple[int, int]] = {}
    ok = {(f.start, f.end) for f in flights_of(segments) if f.reconstructed}
    for s in segments:
        if not isinstance(s, dict) or (s.get("start_frame"), s.get("end_frame")) not in ok:
            continue
        a, b = int(s["start_frame"]), int(s["end_frame"])
        for f in (a, b):
            lo, hi = spans.get(f, (f, f))
            spans[f] = (min(lo, a), max(hi, b))
        if _point(s.get("start_point_m")) is not None:
            fitted.setdefault(a, (_point(s["start_point_m"]), s.get("start_plane")))
        if _point(s.get("end_point_m")) is not None:
            fitted[b] = (_point(s["end_point_m"]), s.get("end_plane"))
    out = []
    for f, ev in zip(events.frame.tolist(), events.event.tolist()):
        cov = traj.cov_near(f, *spans.get(f, (f, f)))
        if f in fitted:
            p, plane = fitted[f]
            plane = plane if isinstance(plane, str) and ev not in HIT_EVENTS else None
            out.append(Contact(f, ev, p, plane, cov))
        else:
            out.append(Contact(f, ev, traj.at(f), cov=cov))
    return out


def _point(v: object) -> np.ndarray | None:
    """segments.json's ``[x, y, z]`` → (3,) floats; None when it is not one."""
    try:
        p = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        return None
    return p if p.shape == (3,) else None


def analyse_reconstruction(court: Court, traj: Trajectory, events: HitEvents, segments_doc: dict | None,
                           fps: float, *,
                           first_hit_is_serve: bool = True) -> tuple[list[Contact], RallyAnalysis]:
    """Analyse a reconstruction as the review shows it: the rows strictly inside failed flights are left out
    (a row there is no trustworthy 3D), shots over them get no figure and no call, and the analysis carries
    segments.json's plausibility ("not judged" when ``segments_doc`` is None or has none).

    Returns:
        (every event placed in 3D, the analysis).
    """
    segments = segments_doc["segments"] if segments_doc is not None else []
    flights = flights_of(segments)
    trusted = traj.without([(f.start, f.end) for f in flights if not f.reconstructed])
    contacts = contacts_from_tables(events, trusted, segments)
    analysis = analyse_rally(court, trusted, contacts, fps, first_hit_is_serve=first_hit_is_serve,
                             flights=flights, plausibility=Plausibility.from_segments_json(segments_doc))
    return contacts, analysis


def analyse_clip(clip: Clip, court: Court | None = None, *, gt: bool = False,
                 first_hit_is_serve: bool = True) -> RallyAnalysis:
    """Analyse a clip's reconstruction (``ball_3d.csv`` + ``segments.json`` + ``events.csv``,
    :func:`analyse_reconstruction`), or its ground truth (``gt/``) with ``gt=True`` (no plausibility)."""
    court = court or load_court(clip.court_path())
    path = (clip.gt_dir if gt else clip.root) / "ball_3d.csv"
    if not path.is_file():
        raise FormatError(path, "file not found", fix=f"run `rally3d reconstruct {clip.root}` first")
    traj = Trajectory.from_ball_3d(clip.read_ball_3d(gt=gt))
    events = clip.read_events(gt=gt and (clip.gt_dir / "events.csv").is_file())
    if gt:
        return analyse_rally(court, traj, contacts_from_tables(events, traj, []), clip.info.fps,
                             first_hit_is_serve=first_hit_is_serve)
    return analyse_reconstruction(court, traj, events, read_segments_json(clip.segments_path), clip.info.fps,
                                  first_hit_is_serve=first_hit_is_serve)[1]


CSV_COLUMNS = ("shot", "team", "serve", "hit_frame", "end_frame", "hit_x_m", "hit_y_m", "hit_z_m",
               "launch_speed_kmh", "max_speed_kmh", "net_clearance_m", "bounce_frame", "bounce_x_m",
               "bounce_y_m", "bounce_speed_kmh", "call", "line_distance_cm", "nearest_line", "target",
               "verdict", "reason", "contacts", "status", "no_3d_reason", "line_sigma_cm",
               "too_close_to_call", "call_note", "depth_from")
"""shots.csv's columns. ``status``: ``ok`` or ``no 3D`` (then ``no_3d_reason`` says why and no figure or call
is given); ``line_sigma_cm``: 1-σ of the first bounce across its line; ``too_close_to_call``: 1 when the line
is within 2σ, 0 when not, empty when σ is unknown or nothing was judged; ``call_note``: that in words;
``depth_from``: what pinned the shot's depth along the camera's line of sight (segments.json)."""


def shot_rows(analysis: RallyAnalysis) -> list[dict]:
    """One dict per shot with :data:`CSV_COLUMNS` (empty string for unknown values)."""

    def num(v, nd=3):
        return "" if v is None or not math.isfinite(float(v)) else round(float(v), nd)

    rows = []
    for s in analysis.shots:
        b = s.first_bounce
        rows.append({
            "shot": s.index, "team": s.team, "serve": int(s.serve), "hit_frame": s.hit.frame,
            "end_frame": s.end_frame, "hit_x_m": num(s.hit.position[0]), "hit_y_m": num(s.hit.position[1]),
            "hit_z_m": num(s.hit.position[2]), "launch_speed_kmh": num(s.launch_speed_kmh, 1),
            "max_speed_kmh": num(s.max_speed_kmh, 1), "net_clearance_m": num(s.net_clearance_m),
            "bounce_frame": "" if b is None else b.frame, "bounce_x_m": "" if b is None else num(b.xy[0]),
            "bounce_y_m": "" if b is None else num(b.xy[1]), "bounce_speed_kmh": num(s.bounce_speed_kmh, 1),
            "call": "" if b is None else b.call, "line_distance_cm": "" if b is None else num(b.distance_cm, 1),
            "nearest_line": "" if b is None else b.line, "target": "" if b is None else b.target,
            "verdict": s.verdict, "reason": s.reason,
            "contacts": ";".join(f"{c.surface}@{c.frame}" for c in s.contacts),
            "status": "ok" if s.has_3d else "no 3D", "no_3d_reason": s.no_3d,
            "line_sigma_cm": "" if b is None else num(b.sigma_cm, 1),
            "too_close_to_call": ("" if b is None or not b.judged or not math.isfinite(b.sigma_cm)
                                  else int(b.uncertain)),
            "call_note": "" if b is None else sigma_note(b),
            "depth_from": s.depth_from,
        })
    return rows


def shots_csv_text(analysis: RallyAnalysis) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(shot_rows(analysis))
    return buf.getvalue()


def write_shots_csv(path: str | Path, analysis: RallyAnalysis) -> Path:
    """Write the per-shot table (one row per shot, :data:`CSV_COLUMNS`) atomically."""
    return atomic_write_text(path, shots_csv_text(analysis))
