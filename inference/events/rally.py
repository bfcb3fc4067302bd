"""Rally segmentation: where the point starts (the serve) and ends (the ball is dead), from the ball
track, the decoded events and the model's hit probability, so that the server's bounces before the serve
and the ball after the point are reported apart from the rally's events.

The serve (:func:`find_serve`): candidates are the decoded racket hits, the peaks of the model's hit
probability (a serve the decoder dropped) and the track's sharp turns. A candidate is a serve when the
ball was not resting in a hand just before (:func:`held_still`: a drop or a toss starts from rest), and
the ball then leaves: much faster than it moved in the second before (:func:`launch_scores`; a bounce in
the hand or a toss is slow), or far compared with how far it moved before and for good (``away_s``: a
bounce in the hand comes back, a serve does not), or out of the box of the server's last ``zone_s`` of
bounces (:func:`box_exit`: a far padel serve is slow in the image but leaves that box). Of the passing
candidates within ``serve_window_s`` of the first, the one the ball leaves fastest; when one was picked
at the start of a toss or a rebound that rises and falls at one image x, the launch after its top is the
serve (:func:`after_toss`). On a poor track (a tracker's misses and wrong positions) these tests can pass a
late candidate and skip the rally's first hits: when the decoded hits hold a run of alternating sides
(:func:`chain_serve`) and the track's serve comes after the run's second hit, the run's first hit is the serve. Sports whose serve bounces first (padel) keep that bounce in the point.

A clip cut mid-rally has no serve: when its track starts with the ball flying and an event comes at once
(:func:`starts_in_play`) and the serve found shows no set-up before it (:func:`serve_setup`: held, tossed,
bounced by the server, a pause), the point starts at the first tracked frame and nothing before the serve
found is outside it.

The end: with a camera, by the rules where the bounces land on the court (:func:`rule_end`: after a hit
the ball must first land in the other half, inside the lines; the net, a wall first, out, or a second
bounce in one half end the point); else the second floor bounce after a hit (not when the camera puts
the two in opposite halves: a hit was missed between them); else, when the events stop
(a gap of ``gap_s`` in the track — not one above the top of the picture, a lob —, no event for
``max_flight_s``), where the ball is lost, stands still,
or ``dead_s`` after the last event. When the decoded hits after that end hold a run of alternating sides
(:func:`chain_serve`) starting within ``resume_s``, the end was false and the point goes on from the run. A
rally found of fewer racket hits than such a run (:func:`point_hits`: the server's bounces, a first serve's
fault knocked back, a ball hit back between points) gives way to a served point with more hits at least
``between_s`` later, the ball out of play between (:func:`next_point`). Times are in seconds and distances
in image heights, so the constants hold at 25–60 fps.

Example:
    >>> seg = segment_rally(xy, fps, events.frame, events.event, hit_prob=p_hit, camera=cam,
    ...                     sides=CourtSides.from_court(court))
    >>> seg.start, seg.end, seg.inside
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class RallyParams:
    """Segmentation constants (seconds and image heights; see the module docstring for their use).

    Attributes:
        away_s: the window after a frame in which the ball must stay away (:func:`away_and_back`);
            behind_s: how far back its earlier motion (and the fastest speed before a launch) is read.
        leave_ratio, hit_travel: a serve leaves more than ``leave_ratio`` × its motion before and
            ``hit_travel`` image heights.
        speed_s: the speed after a frame is the median over this long; launch_ratio: a serve leaves this many
            times faster than the ball moved before (at least ``launch_floor`` × the clip's 75th-percentile
            speed); far_leave, far_ratio: or it goes ``far_leave`` × farther than it moved before and at least
            ``far_ratio`` as fast; exit_ratio, zone_s: or it leaves the box of the last ``zone_s`` of track by
            ``exit_ratio`` × the box's size; fallback_speed: when no candidate passes, the one with the
            largest speed ratio ** fallback_speed × (away / back).
        turn_sharpness: a track turn is a candidate when its acceleration is this many times the clip's median.
        median_s: the tests read a running median over ± this long (0: the raw track).
        toss_s, toss_dx, toss_fall_s, toss_speedup: a toss rises within ``toss_s`` with its top within
            ``toss_dx`` × its rise of the start's x; the serve is launched within ``toss_fall_s`` after the
            top ``toss_speedup`` × faster than the ball rose.
        hold_s, hold_travel: the ball moving less than ``hold_travel`` in the ``hold_s`` before a frame rests
            in a hand (not a serve).
        peak_prob: peaks of the hit probability at least this high are candidates; refine_s: a candidate's
            launch frame is looked for this close to it.
        serve_window_s: passing candidates this close to the first compete (the fastest wins).
        snap_s: a decoded racket hit this close to the serve's frame gives its frame.
        chain_hits: the first hit of the first run of this many decoded hits by alternating sides
            (:func:`chain_serve`) is the serve when the track's serve comes after the run's second hit (less
            ``snap_s``) or the track gives none (0: off). A track serve between the two is kept: a HitNet's
            decoded serve is often early (the toss), the track times it.
        hits_timed: the model times its hits (the event taggers; set by the detector): the chain's first hit
            is the serve as soon as the track's serve comes more than ``snap_s`` after it (padel serves within
            ±3 frames on degraded tracks 38 → 49 % on the tuning rallies, the rest unchanged; with the HitNets
            it costs 11–31 points, so they leave it off).
        serve_bounce: the sport's serve bounces first (padel); serve_bounce_s: how long before the serve.
        gap_s: a gap this long ends the point; max_flight_s: no event for this long after an event ends it
            (the frames of a lob above the picture not counted);
        dead_s: the ball is dead this long after the last event when the track goes on.
        resume_s: an end is undone when, within this long after it, the ball lands in the other half (a rules'
            end) or a run of ``chain_hits`` alternating hits starts.
        still_s, still_speed: the ball moving less than ``still_speed`` image heights per second for
            ``still_s`` ends the point.
        in_play_s, setup_s: a clip whose track starts with the ball flying and an event within ``in_play_s``
            starts in play (cut mid-rally) unless the serve found shows its set-up in the ``setup_s`` before
            it (:func:`serve_setup`: the ball held, tossed or bounced by the server, or a pause).
        between_s: a clip that starts in play and whose rally ends, then at least this long later shows a
            served point (:func:`next_point`), began with the previous point's end: the point is the served
            one (real per-point clips of a broadcast open so; between two points lie 20–25 s); so does a rally
            of fewer hits than a run when a served one with more follows this long after it.
        edge: a gap of the track that the ball leaves and re-enters through the top of the picture within
            this share of the image height (a lob) is no loss of the ball.
    """

    away_s: tuple[float, float] = (0.3, 0.8)
    behind_s: float = 1.0
    leave_ratio: float = 1.0
    hit_travel: float = 0.02
    speed_s: float = 0.12
    launch_ratio: float = 2.0
    launch_floor: float = 0.5
    far_leave: float = 3.0
    far_ratio: float = 1.0
    fallback_speed: float = 1.0
    zone_s: float = 3.0
    turn_sharpness: float = 3.0
    median_s: float = 0.0
    toss_s: float = 1.2
    toss_dx: float = 0.3
    toss_fall_s: float = 0.5
    toss_speedup: float = 1.5
    exit_ratio: float = 1e9
    hold_s: float = 0.2
    hold_travel: float = 0.004
    peak_prob: float = 0.3
    refine_s: float = 0.04
    serve_window_s: float = 1.2
    snap_s: float = 0.2
    chain_hits: int = 3
    hits_timed: bool = False
    serve_bounce: bool = False
    serve_bounce_s: float = 1.2
    gap_s: float = 1.0
    max_flight_s: float = 2.6
    dead_s: float = 0.5
    resume_s: float = 3.0
    still_s: float = 0.5
    still_speed: float = 0.05
    in_play_s: float = 1.0
    setup_s: float = 1.5
    edge: float = 0.06
    between_s: float = 5.0

    @classmethod
    def for_sport(cls, sport: str | None) -> RallyParams:
        """The sport's constants (tuned on 100 simulated rallies of seed 7007 per sport, ``bench_rally.py``
        reports on others): padel's serve bounces first and is slow in the image when far (the longer
        ``away_s``, the zone's box, the median against a detector's outliers); tennis serves are fast."""
        if sport == "padel":
            return cls(serve_bounce=True, leave_ratio=2.0, away_s=(0.4, 1.0), far_leave=2.0, far_ratio=0.5,
                       fallback_speed=0.0, exit_ratio=0.5, median_s=0.06)
        if sport == "tennis":
            return cls(hit_travel=0.05)
        return cls()


@dataclass
class RallySegment:
    """The point of a clip.

    Attributes:
        start: the serve's frame; end: the frame where the ball is dead (``start <= end``).
        inside: ``(N,)`` bool per event given, True for the rally's events.
        serve_source: ``hit`` (a decoded racket hit), ``model`` (a peak of the hit probability the decoder
            dropped), ``track`` (the track's turn), ``chain`` (the first of the decoded hits' alternating run,
            :func:`chain_serve`), ``in_play`` (the clip starts mid-rally: ``start`` is its first tracked
            frame, no serve) or ``none``.
    """

    start: int
    end: int
    inside: np.ndarray
    serve_source: str = "hit"


def _scaled(xy: np.ndarray, aspect: float) -> np.ndarray:
    """Normalised image positions → image-height units (x scaled by width / height)."""
    return xy * np.array([aspect, 1.0])


def away_and_back(xy: np.ndarray, fps: float, aspect: float, params: RallyParams) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``t`` (image heights): ``away`` = the smallest distance from ``p[t]`` of the known
    positions within ``away_s`` after ``t`` (inf when too few are known: ``-inf`` is never away) and
    ``back`` = the largest distance moved during the ``behind_s`` before ``t``."""
    p = _scaled(xy, aspect)
    T = len(p)
    a, b = (max(1, int(round(s * fps))) for s in params.away_s)
    away = np.full(T, np.inf)
    known = np.zeros(T, int)
    for s in range(a, min(b, T - 1) + 1):
        d = np.linalg.norm(p[s:] - p[:-s], axis=1)
        ok = np.isfinite(d)
        away[:-s] = np.where(ok, np.minimum(away[:-s], np.where(ok, d, np.inf)), away[:-s])
        known[:-s] += ok
    away[(known < max(2, (b - a + 1) // 3)) | ~np.isfinite(p).all(axis=1)] = -np.inf
    back = np.zeros(T)
    for s in range(1, min(max(1, int(round(params.behind_s * fps))), T - 1) + 1):
        d = np.linalg.norm(p[s:] - p[:-s], axis=1)
        back[s:] = np.fmax(back[s:], np.nan_to_num(d, nan=0.0))
    return away, back


def sharpest_turn(xy: np.ndarray, lo: int, hi: int, aspect: float) -> int | None:
    """Frame in ``[lo, hi]`` with the largest change of the ball's velocity (None: not enough track)."""
    p = _scaled(xy, aspect)
    acc = np.full(len(p), -1.0)
    if len(p) >= 3:
        a = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1)
        acc[1:-1] = np.nan_to_num(a, nan=-1.0)
    lo, hi = max(lo, 0), min(hi, len(p) - 1)
    if hi < lo or acc[lo:hi + 1].max() < 0:
        return None
    return lo + int(np.argmax(acc[lo:hi + 1]))


def rally_end(xy: np.ndarray, fps: float, start: int, frames: np.ndarray, labels: list[str], hits, aspect: float,
              params: RallyParams, land: np.ndarray | None = None, sides: CourtSides | None = None) -> tuple[int, int]:
    """``(end frame, index of the last rally event + 1)`` given the serve frame and the sorted events:
    the point is over at the second floor bounce after a hit (two bounces that ``land`` puts in opposite
    halves are not: a hit between them was missed), or, when the events stop (a gap of
    ``gap_s``, no event for ``max_flight_s``), where the ball is lost, stands still or ``dead_s`` later."""
    T = len(xy)
    above = above_picture(xy, params.edge)
    seen = np.isfinite(xy).all(axis=1) | above  # a lob above the view is in play
    gap = max(1, int(round(params.gap_s * fps)))
    max_flight = int(round(params.max_flight_s * fps))
    # the time a lob spends above the picture does not count against the longest flight: a real padel lob
    # flies up to ~3.7 s hit to hit, 1.7 s of it above a broadcast's top edge
    shown = np.r_[0, np.cumsum(~above)]

    def too_long(a: int, b: int) -> bool:
        return int(shown[b] - shown[a]) > max_flight
    k = int(np.searchsorted(frames, start, side="left"))
    if land is not None and sides is not None:
        i = rule_end(frames, labels, land, k, hits, sides, int(round(params.resume_s * fps)))
        if i is not None and not any(_gap_between(seen, int(frames[j - 1]) if j > k else start, int(frames[j]), gap)
                                     or too_long(int(frames[j - 1]) if j > k else start, int(frames[j]))
                                     for j in range(k, i + 1)):
            return int(frames[i]), i + 1
    last, bounces, half = k, 0, None  # events [.., last) are in the rally; half: of the last bounce, if known
    while last < len(frames):
        f = int(frames[last])
        prev = int(frames[last - 1]) if last > k else start
        if too_long(prev, f) or _gap_between(seen, prev, f, gap):
            break
        last += 1
        if labels[last - 1] in hits:
            bounces, half = 0, None
        elif labels[last - 1] == "ground":
            here = _bounce_half(land, sides, last - 1)
            # two bounces in opposite halves: a hit between them was missed, this one starts the next shot
            bounces = 1 if bounces and here is not None and half is not None and here != half else bounces + 1
            half = here
        if bounces >= 2:
            return f, last  # the second bounce: the point is over
    last_f = int(frames[last - 1]) if last > k else start
    end = min(T - 1, last_f + int(round(params.dead_s * fps)))
    nxt = np.flatnonzero(~seen[last_f + 1:])
    if len(nxt):
        g0 = last_f + 1 + int(nxt[0])
        run = np.flatnonzero(seen[g0:])
        if (len(run) == 0 or run[0] >= gap) and g0 - 1 < end:
            end = max(g0 - 1, last_f)
    p = _scaled(xy, aspect)
    still = max(2, int(round(params.still_s * fps)))
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) * fps
    for t in range(last_f + 1, min(end, T - still)):
        w = v[t:t + still]
        if np.isfinite(w).all() and (w < params.still_speed).all():
            end = t
            break
    return int(max(end, start)), last


def _bounce_half(land: np.ndarray | None, sides: CourtSides | None, i: int) -> str | None:
    """``near``/``far``: the half event ``i`` landed in, or None when no camera placed it."""
    if land is None or sides is None or not np.isfinite(land[i]).all():
        return None
    return sides.side(float(land[i][1]))


def above_picture(xy: np.ndarray, edge: float) -> np.ndarray:
    """``(T,)`` True on the frames of the gaps in the track that the ball leaves and re-enters through the
    top of the picture (within ``edge`` of it): a lob above the camera's view is still in play."""
    seen = np.isfinite(xy).all(axis=1)
    out = np.zeros(len(xy), bool)
    m = np.r_[0, (~seen).astype(int), 0]
    edges = np.flatnonzero(np.diff(m))
    for a, b in zip(edges[::2], edges[1::2]):
        if 0 < a and b < len(xy) and xy[a - 1, 1] < edge and xy[b, 1] < edge:
            out[a:b] = True
    return out


def _gap_between(seen: np.ndarray, a: int, b: int, gap: int) -> bool:
    """Whether the track has a run of ``gap`` or more missing frames between frames a and b."""
    miss = ~seen[a + 1:b]
    if len(miss) < gap:
        return False
    run = np.convolve(miss.astype(int), np.ones(gap, int), "valid")
    return bool((run >= gap).any())


@dataclass(frozen=True)
class CourtSides:
    """What the end-of-point rules need of a court (metres, the court frame of docs/formats.md).

    Attributes:
        net_y: the net line; x_lo, x_hi: the playing lines across (tennis: singles); length: baseline to
        baseline; walls: the court has walls (padel: a wall before the floor ends the point, a bounce
        cannot land beyond the lines); margin: a landing this far outside the lines still counts in.
    """

    net_y: float
    x_lo: float
    x_hi: float
    length: float
    walls: bool = False
    margin: float = 0.15

    @classmethod
    def from_court(cls, court) -> CourtSides:
        """From an :class:`inference.court.Court` (singles lines when the court names them)."""
        pts = court.points
        x_lo = float(pts["near_singles_left"][0]) if "near_singles_left" in pts else 0.0
        x_hi = float(pts["near_singles_right"][0]) if "near_singles_right" in pts else float(court.size[0])
        walls = any(pl.event.startswith("wall") for pl in court.planes)
        return cls(float(court.net_y), x_lo, x_hi, float(court.size[1]), walls)

    def side(self, y: float) -> str:
        return "near" if y < self.net_y else "far"

    def inside(self, x: float, y: float) -> bool:
        m = self.margin
        return self.x_lo - m <= x <= self.x_hi + m and -m <= y <= self.length + m


def floor_positions(xy: np.ndarray, frames: np.ndarray, camera, height: float = 0.0) -> np.ndarray:
    """``(N, 2)`` court positions (m) where the line of sight through the ball at each event frame meets the
    plane ``z = height`` (the floor under a bouncing ball); NaN where the ball is missing near the frame or
    the ray does not reach the floor in front of the camera."""
    out = np.full((len(frames), 2), np.nan)
    T = len(xy)
    for k, f in enumerate(np.asarray(frames, np.int64)):
        for d in (0, -1, 1, -2, 2):
            g = int(f) + d
            if 0 <= g < T and np.isfinite(xy[g]).all():
                o, v = camera.rays_normalized(xy[g][None])
                o, v = np.asarray(o, float).reshape(-1, 3)[0], np.asarray(v, float).reshape(-1, 3)[0]
                if abs(v[2]) > 1e-9:
                    t = (height - o[2]) / v[2]
                    if t > 0:
                        out[k] = (o + t * v)[:2]
                break
    return out


def rule_end(frames: np.ndarray, labels: list[str], land: np.ndarray, first: int, hits,
             sides: CourtSides, resume: int = 0) -> int | None:
    """Index of the event that ends the point by the rules, from event ``first`` (the serve) on, or None:
    after a racket hit the first contact must be the floor in the other half (a bounce on the hitter's
    own side: the ball hit the net; outside the lines: out; a wall or the net first: a fault), and a
    second floor bounce in the same half ends it. Two bounces in opposite halves mean a hit was missed
    in between (the second then counts as the first of the next shot). When within ``resume`` frames
    after such an end the ball lands in the other half, the play went on (a missed or false event misled
    the rules): the rules restart there."""
    def goes_on(i: int) -> bool:
        if not resume or not np.isfinite(land[i]).all():
            return False
        half = sides.side(land[i][1])
        later = [j for j in range(i + 1, len(frames)) if frames[j] - frames[i] <= resume and labels[j] == "ground"
                 and np.isfinite(land[j]).all()]
        return any(sides.side(land[j][1]) != half and sides.inside(*land[j]) for j in later)

    hitter, bounced = None, None  # the last hitter's side; the half of the bounce since that hit
    for i in range(first, len(frames)):
        lab = labels[i]
        if lab in hits:  # the hitter stands where the ball last bounced (the label when it did not)
            hitter = bounced or ("near" if lab.endswith("near") else "far")
            bounced = None
            continue
        if hitter is None:
            continue
        if lab == "net" or (sides.walls and lab != "ground" and bounced is None):
            if not goes_on(i):
                return i  # the net, or a wall before the floor
            hitter, bounced = None, None
            continue
        if lab != "ground" or not np.isfinite(land[i]).all():
            continue
        x, y = land[i]
        half = sides.side(y)
        if bounced is None:
            if half == hitter or not sides.inside(x, y):
                if not goes_on(i):
                    return i  # into the net (falls on the hitter's side) or out
                hitter, bounced = None, None
                continue
            bounced = half
        elif half == bounced:
            if not goes_on(i):
                return i  # the second bounce
            hitter, bounced = None, None
        else:  # a missed hit: the ball came back over the net
            hitter, bounced = bounced, None
            if not sides.inside(x, y) and not goes_on(i):
                return i
            bounced = half
    return None


def running_median(xy: np.ndarray, half: int) -> np.ndarray:
    """``(T, 2)`` positions → their median over ``±half`` frames (NaN where fewer than half the window is
    known): a detector's short runs of wrong positions do not survive it, a flight does."""
    from numpy.lib.stride_tricks import sliding_window_view

    w = 2 * half + 1
    pad = np.concatenate([np.full((half, 2), np.nan), xy, np.full((half, 2), np.nan)])
    win = sliding_window_view(pad, w, axis=0)  # (T, 2, w)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(win, axis=2)
    med[np.isfinite(win).sum(axis=2).min(axis=1) < half + 1] = np.nan
    return med


def forward_speed(p: np.ndarray, fps: float) -> np.ndarray:
    """``(T,)`` image speed leaving each frame, ``|p[t+1] - p[t]| · fps`` (NaN where either is missing)."""
    v = np.full(len(p), np.nan)
    if len(p) > 1:
        v[:-1] = np.linalg.norm(np.diff(p, axis=0), axis=1) * fps
    return v


def launch_scores(p: np.ndarray, fps: float, params: RallyParams) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``t``: ``after`` = median image speed over the ``speed_s`` leaving ``t`` and ``ratio`` =
    ``after`` / the fastest the ball moved in the ``behind_s`` before (at least ``launch_floor`` × the
    clip's 75th-percentile speed): a serve leaves much faster than any bounce in the hand or toss before
    it; a return does not leave faster than the serve it answers."""
    from numpy.lib.stride_tricks import sliding_window_view

    T = len(p)
    v = forward_speed(p, fps)
    k = max(2, int(round(params.speed_s * fps)))
    b = max(2, int(round(params.behind_s * fps)))
    after = np.full(T, np.nan)
    if T >= k:
        w = sliding_window_view(v, k)
        n_ok = np.isfinite(w).sum(axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(w, axis=1)
        after[:T - k + 1] = np.where(n_ok >= 2, med, np.nan)
    pad = np.concatenate([np.full(b, np.nan), v])  # before[t] = max v[t-b .. t-2]
    w = sliding_window_view(pad, b - 1)[:T]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        before = np.nanmax(w, axis=1)
        floor = params.launch_floor * (np.nanpercentile(v, 75) if np.isfinite(v).any() else 0.0)
    ratio = after / np.maximum(np.nan_to_num(before, nan=0.0), max(floor, 1e-6))
    return np.nan_to_num(ratio, nan=0.0), np.nan_to_num(after, nan=0.0)


def held_still(p: np.ndarray, fps: float, params: RallyParams) -> np.ndarray:
    """``(T,)`` True where the ball moved less than ``hold_travel`` image heights during the ``hold_s``
    before the frame: it rests in a hand, so what follows is a drop, a throw or a toss, not a serve (a serve
    meets a falling or rebounding ball)."""
    T = len(p)
    n = max(2, int(round(params.hold_s * fps)))
    moved = np.zeros(T)
    known = np.zeros(T, int)
    for s in range(1, min(n, T - 1) + 1):
        d = np.linalg.norm(p[s:] - p[:-s], axis=1)
        ok = np.isfinite(d)
        moved[s:] = np.fmax(moved[s:], np.where(ok, d, 0.0))
        known[s:] += ok
    return (known >= n // 2) & (moved < params.hold_travel)


def box_exit(p: np.ndarray, fps: float, params: RallyParams) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``t``: ``exit`` = the smallest distance of the positions within ``away_s`` after ``t`` from
    the bounding box of the positions in the ``zone_s`` up to ``t`` (the server's bounces and toss), and
    ``size`` = that box's larger side (image heights; exit -1 where too little is known)."""
    from numpy.lib.stride_tricks import sliding_window_view

    T = len(p)
    z = max(2, int(round(params.zone_s * fps)))
    ok = np.isfinite(p).all(axis=1)
    pad = np.full((z - 1, 2), np.nan)
    win_lo = sliding_window_view(np.concatenate([pad, np.where(ok[:, None], p, np.inf)]).T, z, axis=1)
    win_hi = sliding_window_view(np.concatenate([pad, np.where(ok[:, None], p, -np.inf)]).T, z, axis=1)
    box_lo = np.nanmin(win_lo, axis=2).T  # (T, 2): the box of the positions in [t - z + 1, t]
    box_hi = np.nanmax(win_hi, axis=2).T
    size = np.where(np.isfinite(box_hi - box_lo).all(axis=1), (box_hi - box_lo).max(axis=1), np.nan)
    a, b = (max(1, int(round(x * fps))) for x in params.away_s)
    exit_ = np.full(T, np.inf)
    known = np.zeros(T, int)
    for s in range(a, min(b, T - 1) + 1):
        q = p[s:]
        d = np.linalg.norm(np.maximum(np.maximum(box_lo[:-s] - q, q - box_hi[:-s]), 0.0), axis=1)
        good = np.isfinite(d)
        exit_[:-s] = np.where(good, np.minimum(exit_[:-s], d), exit_[:-s])
        known[:-s] += good
    exit_[(known < max(2, (b - a + 1) // 3)) | ~ok | ~np.isfinite(size)] = -1.0
    return exit_, np.nan_to_num(size, nan=0.0)


def after_toss(p: np.ndarray, fps: float, t: int, after: np.ndarray, params: RallyParams) -> int | None:
    """When the ball rises from frame ``t`` and falls back at one image x (a toss, a bounce's rebound), the
    frame after the top where it is launched at least ``toss_speedup`` × faster than it rose (the serve's
    contact); None when ``t`` starts no such rise."""
    T = len(p)
    end = min(T, t + max(3, int(round(params.toss_s * fps))))
    seg = p[t:end]
    if len(seg) < 4 or not np.isfinite(seg[0]).all():
        return None
    dy = np.diff(seg[:, 1])
    falls = np.flatnonzero(~(dy < 0))  # the first frame the ball stops rising (a missing one too): the top
    top = int(falls[0]) if len(falls) else len(seg) - 1
    rise = seg[0, 1] - seg[top, 1]
    if top < 2 or top >= len(seg) - 2 or not np.isfinite(rise) or rise < params.hit_travel or \
            abs(seg[top, 0] - seg[0, 0]) > params.toss_dx * rise:
        return None
    a, b = t + top + 1, min(T - 1, t + top + max(2, int(round(params.toss_fall_s * fps))))
    v = forward_speed(p, fps)[t:t + top]
    rose = np.nanmax(v) if np.isfinite(v).any() else np.inf
    ok = [u for u in range(a, b + 1) if after[u] >= params.toss_speedup * rose]
    if not ok:
        return None
    turn = sharpest_turn(p, ok[0] - 1, min(ok[0] + 2, T - 1), 1.0)
    return turn if turn is not None else ok[0]


def _peaks(x: np.ndarray, lo: float, half: int = 2) -> np.ndarray:
    """Frames where ``x`` is at least ``lo`` and the largest within ``half`` frames."""
    from scipy.ndimage import maximum_filter1d

    x = np.nan_to_num(np.asarray(x, float), nan=0.0)
    return np.flatnonzero((x >= lo) & (x >= maximum_filter1d(x, 2 * half + 1, mode="nearest")))


def find_serve(xy: np.ndarray, fps: float, hit_frames: np.ndarray, aspect: float, params: RallyParams,
               hit_prob: np.ndarray | None = None) -> tuple[int | None, str]:
    """The serve's frame and where it came from (``hit``: a decoded racket hit, ``model``: a peak of the
    model's hit probability the decoder dropped, ``track``: the track alone), or ``(None, "none")``.

    Candidates are the decoded hits, the peaks of ``hit_prob`` (``(T,)``, optional) and the track's
    sharpest velocity changes; a candidate passes when the ball leaves it much faster than it moved before
    (:func:`launch_scores`) and stays away (:func:`away_and_back`). Of the passing candidates within
    ``serve_window_s`` of the first, the one the ball leaves fastest (a toss passes too, slower).
    """
    T = len(xy)
    raw = xy  # contacts are timed on the track as given; the tests read a median-filtered one
    if params.median_s > 0:
        xy = running_median(xy, max(1, int(round(params.median_s * fps))))
    p = _scaled(xy, aspect)
    ratio, after = launch_scores(p, fps, params)
    away, back = away_and_back(xy, fps, aspect, params)
    leaves = away > np.maximum(params.hit_travel, params.leave_ratio * back)
    ex, size = box_exit(p, fps, params)
    fast = ratio >= params.launch_ratio
    far = (ratio >= params.far_ratio) & (away > params.far_leave * np.maximum(back, 1e-6))
    out_of_zone = (ex > params.hit_travel) & (ex > params.exit_ratio * size)
    launched = ~held_still(p, fps, params) & (fast | far | out_of_zone)
    near = max(1, int(round(params.refine_s * fps)))

    def passing(t: int) -> int | None:  # the frame near t the ball is launched from, if it passes
        lo, hi = max(t - near, 0), min(t + near, T - 1)
        ok = [u for u in range(lo, hi + 1) if launched[u] and leaves[max(u - 1, 0):u + 2].any()]
        if not ok:
            return None
        turn = sharpest_turn(raw, lo, hi, aspect)
        return turn if turn is not None and lo <= turn <= hi and turn in ok else max(ok, key=lambda u: ratio[u])

    cands: dict[int, str] = {}
    for h in hit_frames:
        cands.setdefault(int(h), "hit")
    if hit_prob is not None and len(hit_prob):
        for t in _peaks(hit_prob[:T], params.peak_prob):
            cands.setdefault(int(t), "model")
    acc = np.zeros(T)
    if T >= 3:
        acc[1:-1] = np.nan_to_num(np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1), nan=0.0)
    moving = acc[acc > 0]
    sharp = params.turn_sharpness * float(np.median(moving)) if len(moving) else np.inf
    for t in _peaks(acc, sharp):
        if launched[t] and acc[t] > acc[max(t - 1, 0)]:  # a sharp turn (not a plateau of steady curvature)
            cands.setdefault(int(t), "track")
    found = []
    for t in sorted(cands):
        u = passing(t)
        if u is not None:
            found.append((u, cands[t], t))
    if not found:  # nothing passes: the candidate the ball leaves most decidedly (far, slow serves)
        still = held_still(p, fps, params)
        best = [(ratio[t] ** params.fallback_speed * away[t] / max(back[t], 1e-6), t) for t in sorted(cands)
                if not still[t] and np.isfinite(away[t]) and away[t] > params.hit_travel]
        if not best:
            return None, "none"
        u = max(best, key=lambda b: (round(b[0], 6), -b[1]))[1]  # a tie: the earliest
        source = cands[u]
    else:
        first = found[0][0]
        window = [f for f in found if f[0] - first <= params.serve_window_s * fps]
        u, source, _ = max(window, key=lambda f: (after[f[0]], f[1] == "hit"))
    tossed = after_toss(p, fps, u, after, params)  # a toss (or a rebound) was picked: its end is the serve
    if tossed is not None:
        u, source = tossed, "track"
    snap = hit_frames[np.abs(hit_frames - u) <= max(1, int(round(params.snap_s * fps)))] if len(hit_frames) else []
    if len(snap):
        return int(snap[np.argmin(np.abs(snap - u))]), "hit"
    return int(u), source


def chain_serve(frames: np.ndarray, labels: list[str], hits, fps: float, params: RallyParams) -> tuple[int, int] | None:
    """The frames of the first two racket hits of the first run of ``chain_hits`` or more hits by alternating
    sides (near, far, near, …), each within ``max_flight_s`` of the one before: the decoded events' own
    account of where the rally starts (the server's bounces and catches before it are one side's, the
    point's hits alternate). None when no such run exists or ``chain_hits`` is 0."""
    if params.chain_hits <= 0:
        return None
    idx = [i for i, c in enumerate(labels) if c in hits]
    limit = params.max_flight_s * fps
    run = []
    for i in idx:
        if run and (labels[i] == labels[run[-1]] or frames[i] - frames[run[-1]] > limit):
            run = []
        run.append(i)
        if len(run) >= params.chain_hits:
            return int(frames[run[0]]), int(frames[run[1]])
    return None


def point_hits(frames: np.ndarray, labels: list[str], hits, start: int, first: int, last: int, fps: float,
               params: RallyParams) -> int:
    """The racket hits of the rally of events ``first..last-1`` served at ``start``, the serve counted once
    (also when only the track or the hit probability found it)."""
    inside = [int(f) for f, c in zip(frames[first:last], labels[first:last]) if c in hits]
    served = any(abs(f - start) <= params.snap_s * fps for f in inside)
    return len(inside) + (0 if served else 1)


def _side_at(xy: np.ndarray, frames: np.ndarray, labels: list[str], hits, t: int) -> str | None:
    """Which racket-hit label's side of the image the ball is on at frame ``t`` (the nearest seen frame
    within 3): the one whose decoded hits' median image height is nearer; None when unknown or when the
    decoded hits are all one side's."""
    T = len(xy)
    seen = [u for d in range(4) for u in (t - d, t + d) if 0 <= u < T and np.isfinite(xy[u]).all()]
    heights = {h: [xy[f, 1] for f, c in zip(frames, labels) if c == h and 0 <= f < T and np.isfinite(xy[f, 1])]
               for h in hits}
    if not seen or sum(1 for v in heights.values() if v) < 2:
        return None
    y = xy[seen[0], 1]
    return min((h for h in hits if heights[h]), key=lambda h: abs(y - float(np.median(heights[h]))))


def _servers_warm_up(xy: np.ndarray, frames: np.ndarray, labels: list[str], hits, start: int | None,
                     first: int) -> bool:
    """Whether a serve found at ``start`` before the first hit ``first`` of the alternating run is the
    server's warm-up instead (a bounce or a catch that looked like a launch): no decoded event between them
    (a serve bounces before it is answered; with a bounce between, the answer may be the one missed) and the
    ball on the same side as that first hit — a serve's answer comes from the other side."""
    if start is None or start >= first:
        return False
    if any(start < f < first for f in frames):
        return False
    label = labels[int(np.flatnonzero(frames == first)[0])]
    return _side_at(xy, frames, labels, hits, start) == label


def serve_setup(xy: np.ndarray, fps: float, start: int, frames: np.ndarray, labels: list[str], hits,
                aspect: float, params: RallyParams) -> bool:
    """Whether the ``setup_s`` before a serve found at ``start`` show a serve's set-up: the ball held still
    or tossed (it rises and falls at one image x), bounced by the server (a floor event with no racket hit
    between it and the serve), or a pause (the ball unseen or still for most of that time). A rally shot
    has none of these: the ball arrives from the other side."""
    a = max(0, start - int(round(params.setup_s * fps)))
    if start - a < 3:
        return False
    p = _scaled(xy, aspect)
    before = p[a:start]
    seen = np.isfinite(before).all(axis=1) | above_picture(xy, params.edge)[a:start]  # a lob is no pause
    if seen.mean() < 0.4:
        return True                                         # a pause: the ball out of sight before the serve
    if held_still(p, fps, params)[a:start].any():
        return True
    _, after = launch_scores(p, fps, params)
    if any(after_toss(p, fps, t, after, params) is not None for t in range(a, max(a + 1, start - 3))):
        return True
    bounced = [f for f, c in zip(frames, labels) if a <= f < start and c == "ground"]
    hit_between = [f for f, c in zip(frames, labels) if bounced and bounced[-1] < f < start and c in hits]
    if not bounced or hit_between:
        return False
    # the server's bounce falls from the hand; a rally's bounce comes from the other side's shot, fast
    v = forward_speed(p, fps)
    typical = np.nanpercentile(v, 75) if np.isfinite(v).any() else np.inf
    arriving = v[max(0, bounced[-1] - int(round(0.3 * fps))):bounced[-1]]
    return bool(np.isfinite(arriving).any() and np.nanmax(arriving) < 0.5 * typical)


def starts_in_play(xy: np.ndarray, fps: float, frames: np.ndarray, labels: list[str], hits, aspect: float,
                   params: RallyParams) -> int | None:
    """The first tracked frame when the clip starts with the ball in play (cut mid-rally: the ball already
    flies, an event comes within ``in_play_s``, and the first events are a rally's — not two floor bounces
    without a racket hit between, as a server bouncing the ball), else None."""
    seen = np.flatnonzero(np.isfinite(xy).all(axis=1))
    if not len(seen) or not len(frames):
        return None
    t0 = int(seen[0])
    if frames[0] - t0 > params.in_play_s * fps:
        return None
    first = [c for c in labels[:3]]
    if len(first) >= 2 and first[0] == first[1] == "ground":
        return None
    p = _scaled(xy, aspect)
    n = max(2, int(round(params.hold_s * fps)))
    if held_still(p, fps, params)[t0:t0 + n + 1].any():
        return None
    return t0


def segment_rally(xy: np.ndarray, fps: float, frames: np.ndarray, labels, hits=("player_near", "player_far"),
                  aspect: float = 16 / 9, params: RallyParams | None = None,
                  hit_prob: np.ndarray | None = None, camera=None, sides: CourtSides | None = None) -> RallySegment:
    """Segment one clip.

    Args:
        xy: ``(T, 2)`` normalised ball positions at the clip's frames, NaN where missing.
        fps: the clip's frame rate; frames: ``(N,)`` event frames (sorted); labels: their N labels
            (events.csv's; ``ground`` counts bounces).
        hits: the racket-hit labels; aspect: image width / height.
        hit_prob: ``(T,)`` the model's probability of a racket hit per frame (optional: finds a serve the
            decoder dropped).
        camera, sides: with both, the end follows the rules from where the bounces land (:func:`rule_end`).
    Returns:
        the :class:`RallySegment`.
    """
    params = params or RallyParams()
    frames = np.asarray(frames, np.int64)
    labels = [str(c) for c in labels]
    T = len(xy)
    hit_frames = np.array([f for f, c in zip(frames, labels) if c in hits], np.int64)
    start, source = find_serve(xy, fps, hit_frames, aspect, params, hit_prob)
    chained = chain_serve(frames, labels, hits, fps, params)
    if chained is not None:
        # too late: after the hit that answered the chain's first, or with hits_timed already after that first
        # hit (the track found its bounce or a glass); before it on the same side: the server's bounces
        late = chained[0] + params.snap_s * fps if params.hits_timed else chained[1] - params.snap_s * fps
        if start is None or start > late or _servers_warm_up(xy, frames, labels, hits, start, chained[0]):
            start, source = chained[0], "chain"
    if start is None:
        start = int(hit_frames[0]) if len(hit_frames) else (int(frames[0]) if len(frames) else 0)
        source = "hit" if len(hit_frames) else "none"
    begun = starts_in_play(xy, fps, frames, labels, hits, aspect, params)
    if begun is not None and begun < start and not serve_setup(xy, fps, start, frames, labels, hits, aspect, params):
        start, source = begun, "in_play"   # cut mid-rally: no serve in the clip, nothing before it is outside
    land = floor_positions(xy, frames, camera) if camera is not None and sides is not None else None
    end, last = rally_end(xy, fps, start, frames, labels, hits, aspect, params, land, sides)
    while params.chain_hits > 0 and last < len(frames):   # the hits go on alternating: the end was false
        more = chain_serve(frames[last:], labels[last:], hits, fps, params)
        if more is None or more[0] - end > params.resume_s * fps:
            break
        end, last = rally_end(xy, fps, more[0], frames, labels, hits, aspect, params, land, sides)
    first = int(np.searchsorted(frames, start, side="left"))
    n_hits = point_hits(frames, labels, hits, start, first, last, fps, params)
    if last < len(frames) and params.chain_hits > 0:
        # opened in play: the previous point's end, the point is a served run after it; fewer hits than a run:
        # a stray exchange between points (the server's bounces, a ball knocked back), the point has more
        opened_in_play = begun is not None and begun <= start
        weak = n_hits < params.chain_hits
        set_up = not opened_in_play and serve_setup(xy, fps, start, frames, labels, hits, aspect, params)
        later = None if not (opened_in_play or weak) else \
            next_point(xy, fps, end, frames, labels, hits, aspect, params, hit_prob, camera, sides,
                       beat=(n_hits, set_up) if weak else None)
        if later is not None:
            return later
    if params.serve_bounce and first > 0 and labels[first - 1] not in hits and \
            start - frames[first - 1] <= params.serve_bounce_s * fps:
        first -= 1
    inside = np.zeros(len(frames), bool)
    inside[first:last] = True
    return RallySegment(int(min(start, T - 1)) if T else 0, int(min(end, T - 1)) if T else 0, inside, source)


def out_of_play(xy: np.ndarray, fps: float, a: int, b: int, aspect: float, params: RallyParams,
                flying: float = 0.4) -> bool:
    """Whether the ball is out of play over frames ``a..b``: in flight (seen or above the picture, moving at
    least half the clip's typical speed) for less than ``flying`` of the time — between two points it is lost,
    held or bounced by the server; a rally's ball flies. On a real final's tracker tracks 0.4 judges 96 % of
    the 5 s windows before the serve out of play and 31 % inside a rally (tracker gaps; 0.3: 84 / 28 %)."""
    if b - a < 2:
        return False
    p = _scaled(xy, aspect)
    v = forward_speed(p, fps)
    typical = np.nanpercentile(v, 75) if np.isfinite(v).any() else np.inf
    above = above_picture(xy, params.edge)[a:b]
    moving = np.nan_to_num(v[a:b], nan=0.0) >= 0.5 * typical
    return bool(np.mean(moving | above) < flying)


def next_point(xy: np.ndarray, fps: float, end: int, frames: np.ndarray, labels: list[str], hits, aspect: float,
               params: RallyParams, hit_prob: np.ndarray | None = None, camera=None,
               sides: CourtSides | None = None, beat: tuple[int, bool] | None = None) -> RallySegment | None:
    """The point served at least ``between_s`` after a rally that ended at ``end``, as a segment of the whole
    clip, or None: the ball must be out of play in between (:func:`out_of_play`: lost, held, bounced by the
    server, not flying) and the later rally hold a run of ``chain_hits`` alternating hits (a point, not the
    server's bounces or a stray hit between points; its serve may be one the model missed). With ``beat =
    (hits, set_up)`` (the earlier rally held fewer hits than a run: a first serve's fault knocked back, a ball
    hit back between points) the later one needs more racket hits (:func:`point_hits`) instead, or as many
    when only its serve shows a set-up (:func:`serve_setup`). What lies before it (the previous point's end,
    the wait) is outside it."""
    a = int(end) + int(round(params.between_s * fps))
    keep = np.asarray(frames) > a
    if a >= len(xy) - 1 or keep.sum() < max(params.chain_hits, 1) or params.chain_hits <= 0:
        return None
    if not out_of_play(xy, fps, int(end), a, aspect, params):
        return None
    sub_labels = [c for c, k in zip(labels, keep) if k]
    sub_frames = np.asarray(frames)[keep] - a
    if beat is None and chain_serve(sub_frames, sub_labels, hits, fps, params) is None:
        return None
    sub = segment_rally(xy[a:], fps, sub_frames, sub_labels, hits, aspect, replace(params, in_play_s=-1.0),
                        hit_prob[a:] if hit_prob is not None else None, camera, sides)
    if sub.serve_source in ("in_play", "none") or not sub.inside.any():
        return None
    if beat is not None:
        ins = np.flatnonzero(sub.inside)
        n = point_hits(sub_frames, sub_labels, hits, sub.start, int(ins[0]), int(ins[-1]) + 1, fps, params)
        tie_won = n == beat[0] and not beat[1] and serve_setup(xy[a:], fps, sub.start, sub_frames, sub_labels,
                                                               hits, aspect, params)
        if n < beat[0] or (n == beat[0] and not tie_won):
            return None
    elif chain_serve(sub_frames[sub.inside], [c for c, k in zip(sub_labels, sub.inside) if k], hits, fps,
                     params) is None:
        return None
    inside = np.zeros(len(frames), bool)
    inside[np.flatnonzero(keep)[sub.inside]] = True
    return RallySegment(sub.start + a, sub.end + a, inside, sub.serve_source)


def rally_summary(seg: RallySegment, fps: float, outside_labels, kept: bool) -> str:
    """One line for the terminal: the point's frames and times, where the serve came from, and the events
    judged outside it by label (``kept``: they stay in events.csv)."""
    counts: dict[str, int] = {}
    for e in outside_labels:
        counts[str(e)] = counts.get(str(e), 0) + 1
    out = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    n = sum(counts.values())
    how = "the clip starts mid-rally" if seg.serve_source == "in_play" else f"serve from {seg.serve_source}"
    return (f"rally frames {seg.start}–{seg.end} ({seg.start / fps:.2f}–{seg.end / fps:.2f} s, {how}); "
            f"{n} event{'' if n == 1 else 's'} outside the point" + (f" ({out})" if out else "")
            + (", kept in events.csv (--rally-only leaves them out)" if kept and counts else
               ", left out of events.csv" if counts else ""))


# ------------------------------------------------------------------------------------------- file
def write_rally_yaml(path: str | Path, seg: RallySegment, fps: float, outside: list[tuple[int, str]] | None = None,
                     source: str = "rally3d events") -> Path:
    """Write ``rally.yaml`` (docs/formats.md): the point's start/end frames and times and the events
    detected outside it."""
    import yaml

    from inference.clipio import atomic_write_bytes

    d = {"start": int(seg.start), "end": int(seg.end), "start_s": round(seg.start / fps, 4),
         "end_s": round(seg.end / fps, 4), "serve": seg.serve_source, "source": source,
         "outside": [{"frame": int(f), "event": str(e)} for f, e in (outside or [])]}
    return atomic_write_bytes(Path(path), yaml.safe_dump(d, sort_keys=False).encode())


def read_rally_yaml(path: str | Path) -> tuple[int, int]:
    """``(start, end)`` frames of ``rally.yaml``; a clear error naming the file when malformed."""
    import yaml

    path = Path(path)
    try:
        d = yaml.safe_load(path.read_text())
        start, end = int(d["start"]), int(d["end"])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a rally.yaml with integer `start` and `end` frames ({type(e).__name__}: "
                         f"{e}); fix or delete the file") from None
    if not 0 <= start <= end:
        raise ValueError(f"{path}: need 0 <= start <= end, got start={start}, end={end}")
    return start, end
