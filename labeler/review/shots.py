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
  its closest boundary line), negative outside (distance to the area), 0 on the line.

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
        plane: court plane touched (segments.json), None for hits or when unknown.
    """

    frame: int
    event: str
    position: np.ndarray
    plane: str | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float).reshape(3)
        object.__setattr__(self, "position", p)

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
    """

    frame: int
    xy: np.ndarray
    call: str
    distance_cm: float = float("nan")
    line: str = ""
    reason: str = ""
    target: str = ""

    def __post_init__(self) -> None:
        if self.call not in CALLS:
            raise ValueError(f"call must be one of {CALLS}, got {self.call!r}")


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

    @property
    def first_bounce(self) -> BounceCall | None:
        return self.bounces[0] if self.bounces else None


@dataclass
class RallyAnalysis:
    """Every shot of a rally plus the floor bounces before the first hit (the padel serve's drop)."""

    shots: list[Shot]
    pre_serve: list[BounceCall] = field(default_factory=list)
    sport: str = ""

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
            calls.append(BounceCall(c.frame, xy, call, round(d * 100, 1), line, why, area.name))
            if call != "in":
                verdict, reason = call, f"first bounce {why}"
            else:
                bounced_in = True
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
                      else "bounced in; returned after the bounce")
        elif volleyed:
            verdict, reason = "in", "returned before the bounce (volley)"
        else:
            verdict, reason = "-", "no floor bounce before the end of the clip"
    return verdict, reason, calls


# --------------------------------------------------------------------------------------- the analysis
@dataclass(frozen=True)
class Trajectory:
    """The 3D ball per frame: frame (N,) sorted unique, xyz (N, 3) metres."""

    frame: np.ndarray
    xyz: np.ndarray

    @classmethod
    def from_ball_3d(cls, ball: Ball3D) -> Trajectory:
        """One position per frame; where a frame has several kinds, ``contact`` beats ``fitted`` beats ``gt``."""
        rank = {"contact": 0, "fitted": 1, "gt": 2}
        order = np.lexsort((np.array([rank.get(k, 3) for k in ball.kind]), ball.frame))
        f = ball.frame[order]
        keep = np.r_[True, f[1:] != f[:-1]] if len(f) else np.zeros(0, bool)
        return cls(f[keep], ball.xyz[order][keep])

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


def analyse_rally(court: Court, traj: Trajectory, contacts: list[Contact], fps: float, *,
                  rules: CourtRules | None = None, first_hit_is_serve: bool = True) -> RallyAnalysis:
    """Split a rally's contacts into shots and compute every figure and call.

    Args:
        court: the court; traj: the 3D ball; contacts: every event in frame order (hits and surfaces);
        fps: frame rate.
        rules: line-call geometry (default from ``court``).
        first_hit_is_serve: treat the clip's first hit as the serve when its hitter stands behind their
            service line and the clip shows the serve's set-up (:func:`looks_like_serve`); False judges
            every shot as a rally shot.
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
        verdict, reason, calls = judge_shot(rules, team, inner, serve=serve, server_x=float(hit.position[0]),
                                            volleyed=j < len(contacts))
        shot = Shot(n, team, bool(serve), hit, int(end), list(inner), calls, verdict, reason)
        _add_figures(shot, court, traj, fps)
        shots.append(shot)
    return RallyAnalysis(shots, pre_calls, rules.sport)


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
def read_segments(path: Path) -> list[dict]:
    """segments.json's ``segments`` list ([] when the file is absent)."""
    if not path.is_file():
        return []
    data = load_json(path, fix="re-run `rally3d reconstruct <clip>`")
    segs = data.get("segments") if isinstance(data, dict) else None
    if not isinstance(segs, list):
        raise FormatError(path, "expected an object with a `segments` list", fix="re-run `rally3d reconstruct <clip>`")
    return segs


def contacts_from_tables(events: HitEvents, traj: Trajectory, segments: list[dict]) -> list[Contact]:
    """Place each event in 3D: the fitted contact point of segments.json where a reconstructed segment
    starts or ends at that frame (with its plane), else the trajectory at that frame (NaN if none)."""
    fitted: dict[int, tuple[list, str | None]] = {}
    for s in segments:
        if not s.get("reconstructed"):
            continue
        if s.get("start_point_m") is not None:
            fitted.setdefault(int(s["start_frame"]), (s["start_point_m"], s.get("start_plane")))
        if s.get("end_point_m") is not None:
            fitted[int(s["end_frame"])] = (s["end_point_m"], s.get("end_plane"))
    out = []
    for f, ev in zip(events.frame.tolist(), events.event.tolist()):
        if f in fitted:
            p, plane = fitted[f]
            out.append(Contact(f, ev, np.asarray(p, float), plane if ev not in HIT_EVENTS else None))
        else:
            out.append(Contact(f, ev, traj.at(f)))
    return out


def analyse_clip(clip: Clip, court: Court | None = None, *, gt: bool = False,
                 first_hit_is_serve: bool = True) -> RallyAnalysis:
    """Analyse a clip's reconstruction (``ball_3d.csv`` + ``segments.json`` + ``events.csv``), or its
    ground truth (``gt/``) with ``gt=True``."""
    court = court or load_court(clip.court_path())
    path = (clip.gt_dir if gt else clip.root) / "ball_3d.csv"
    if not path.is_file():
        raise FormatError(path, "file not found", fix=f"run `rally3d reconstruct {clip.root}` first")
    traj = Trajectory.from_ball_3d(clip.read_ball_3d(gt=gt))
    events = clip.read_events(gt=gt and (clip.gt_dir / "events.csv").is_file())
    segments = [] if gt else read_segments(clip.segments_path)
    contacts = contacts_from_tables(events, traj, segments)
    return analyse_rally(court, traj, contacts, clip.info.fps, first_hit_is_serve=first_hit_is_serve)


CSV_COLUMNS = ("shot", "team", "serve", "hit_frame", "end_frame", "hit_x_m", "hit_y_m", "hit_z_m",
               "launch_speed_kmh", "max_speed_kmh", "net_clearance_m", "bounce_frame", "bounce_x_m",
               "bounce_y_m", "bounce_speed_kmh", "call", "line_distance_cm", "nearest_line", "target",
               "verdict", "reason", "contacts")


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
