"""From per-frame poses to the clip's players: identity tracking, stitching, selection, teams, gaps.

1. **Tracking** with OC-SORT (or ByteTrack / SORT) from Roboflow's maintained ``trackers`` library on the
   people's boxes; keypoints ride along with their detections.
2. **Stitching**: a track that ends and another that starts soon after, close enough on court for a
   player's speed, are the same person (identities survive long occlusions and crossings).
3. **Selection** as in the thesis: time on court plus distance travelled, the best ``n/2`` per court
   side (spectators, umpires and ball kids stand off court or still).
4. **Teams** by court side (near: y < net), ids 0..n-1 near team first, left to right.
5. **Gaps** up to ``max_gap_s`` are filled by linear interpolation, and court positions are smoothed
   with a short centred moving average (players move slowly; keypoint noise does not).

Example:
    >>> tracks = players_from_poses(poses, camera, court, fps=30.0)      # PlayerTracks (players.csv)
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from inference.camera import Camera
from inference.clipio import PlayerTracks
from inference.court import Court

from .positions import ANKLE_HEIGHT, court_positions
from .types import J, Persons, PoseSequence

TRACKERS = ("ocsort", "bytetrack", "sort")

@dataclass(frozen=True)
class TrackingConfig:
    """Knobs of the player pipeline."""

    tracker: str = "ocsort"
    min_person_score: float = 0.1     # detections below are dropped before tracking
    activation: float = 0.5           # tracks start from detections this confident (after normalisation)
    lost_buffer_s: float = 1.0        # the tracker keeps a lost track this long
    min_consecutive: int = 2          # frames before a track is confirmed
    iou_threshold: float = 0.1        # small far-court boxes overlap little between frames
    stitch_gap_s: float = 3.0         # fragments this far apart in time may be joined ...
    max_speed: float = 8.0            # ... if a player could run between them (m/s)
    max_gap_s: float = 0.6            # gaps filled by interpolation
    smooth_s: float = 0.2             # court positions: centred moving average over this window
    court_margin: float = 1.5         # m beyond the court's lines, for a court YAML without `player_area`
    static_m: float = 0.8             # a track whose positions spread less (m, 10-90 % range) stands still ...
    static_weight: float = 0.1        # ... (a line judge, a ball kid, the umpire): its score is scaled by this
    distance_weight: float = 0.3      # selection score = seconds on court + weight × metres travelled
    ankle_height: float = ANKLE_HEIGHT
    min_kp_score: float = 0.3
    extend_iou: float = 0.3           # a player's track carried past its ends onto detections overlapping it this much
    extend_s: float = 0.5             # ... for at most this long beyond each end ...
    extend_miss: int = 1              # ... across at most this many looks in a row with no such detection


@dataclass
class Track:
    """One tracked person: (T,) frames and per-frame arrays aligned with them."""

    frames: np.ndarray
    boxes: np.ndarray       # (T, 4)
    keypoints: np.ndarray   # (T, 17, 2)
    kp_scores: np.ndarray   # (T, 17)
    scores: np.ndarray      # (T,)
    court: np.ndarray       # (T, 2), NaN where unknown

    def __len__(self) -> int:
        return len(self.frames)

    def concat(self, other: Track) -> Track:
        return Track(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in
                       ("frames", "boxes", "keypoints", "kp_scores", "scores", "court")))

    def median_court(self) -> np.ndarray:
        ok = np.isfinite(self.court).all(axis=1)
        return np.median(self.court[ok], axis=0) if ok.any() else np.full(2, np.nan)


def _make_tracker(cfg: TrackingConfig, fps: float):
    import trackers  # imported here: it takes about a second

    if cfg.tracker not in TRACKERS:
        raise ValueError(f"unknown tracker {cfg.tracker!r}; choose one of {TRACKERS}")
    buffer = max(1, int(round(cfg.lost_buffer_s * fps)))
    common = dict(lost_track_buffer=buffer, frame_rate=fps, minimum_consecutive_frames=cfg.min_consecutive,
                  minimum_iou_threshold=cfg.iou_threshold)
    if cfg.tracker == "ocsort":
        return trackers.OCSORTTracker(high_conf_det_threshold=cfg.activation, **common)
    if cfg.tracker == "bytetrack":
        return trackers.ByteTrackTracker(track_activation_threshold=cfg.activation,
                                         high_conf_det_threshold=cfg.activation, **common)
    return trackers.SORTTracker(track_activation_threshold=cfg.activation * 0.5, **common)


def confidence_scale(seq: PoseSequence, frames: np.ndarray | None = None) -> float:
    """The 90th percentile of the clip's person scores (of ``frames`` (N,) bool only, when given): pose models
    differ in score scale (MoveNet's are often 0.2–0.5, RTMPose's box scores 0.5–0.9), so scores are divided by
    it before tracking."""
    scores = np.concatenate([p.scores for i, p in enumerate(seq.frames) if len(p) and (frames is None or frames[i])]
                            or [np.ones(1)])
    return float(max(np.percentile(scores, 90), 1e-6))


def confidence_scales(seq: PoseSequence) -> np.ndarray:
    """(N,) the divisor of each frame's person scores: :func:`confidence_scale` of its kind of look (whole
    frame, or tiles around people already seen: :attr:`PoseSequence.tiled`)."""
    if seq.tiled is None or not np.asarray(seq.tiled).any():
        return np.full(len(seq), confidence_scale(seq))
    tiled = np.zeros(len(seq), bool)
    tiled[: len(seq.tiled)] = np.asarray(seq.tiled, bool)[: len(seq)]
    return np.where(tiled, confidence_scale(seq, tiled), confidence_scale(seq, ~tiled))


def track_people(seq: PoseSequence, camera: Camera, fps: float, cfg: TrackingConfig) -> list[Track]:
    """Run the tracker over the clip's poses (the frames the model looked at, ``seq.looked``); one
    :class:`Track` per tracker identity, its frames numbered as the clip's."""
    import supervision as sv

    looked = np.flatnonzero(seq.looked) if seq.looked is not None else np.arange(len(seq))
    step = max(float(np.median(np.diff(looked))) if len(looked) > 1 else 1.0, 1.0)
    if step > 1:  # posed every N-th frame: the tracker runs at the rate of the looks, confirming a track as soon
        cfg = replace(cfg, min_consecutive=max(1, int(round(cfg.min_consecutive / step))))  # (in time)
    tracker = _make_tracker(cfg, fps / step)
    scale = confidence_scales(seq)
    rows: dict[int, list] = {}
    for f in looked.tolist():
        persons = seq.frames[f]
        keep = persons.scores >= cfg.min_person_score
        keep &= np.isfinite(persons.boxes).all(axis=1) & (persons.boxes[:, 2] > persons.boxes[:, 0])
        p = persons.select(keep)
        conf = np.clip(p.scores / scale[f], 0.0, 1.0).astype(np.float32)
        det = sv.Detections(xyxy=p.boxes.astype(np.float32), confidence=conf,
                            class_id=np.zeros(len(p), int), data={"idx": np.arange(len(p))})
        out = tracker.update(det)
        if len(out) == 0:
            continue
        court = court_positions(p.keypoints, p.kp_scores, camera, cfg.ankle_height, cfg.min_kp_score)
        for tid, i in zip(out.tracker_id, out.data["idx"]):
            if tid < 0:
                continue
            rows.setdefault(int(tid), []).append((f, p.boxes[i], p.keypoints[i], p.kp_scores[i], p.scores[i],
                                                  court[i]))
    return [Track(*(np.array([r[k] for r in rs]) for k in range(6))) for rs in rows.values()]


def stitch(tracks: list[Track], fps: float, cfg: TrackingConfig) -> list[Track]:
    """Join fragments of one person: greedily link a track's end to the nearest later start that a player
    could reach in the gap (on court), never overlapping in time."""
    tracks = sorted(tracks, key=lambda t: t.frames[0])
    changed = True
    while changed:
        changed = False
        best = None
        for i, a in enumerate(tracks):
            end_f, end_p = a.frames[-1], _last_position(a)
            for j, b in enumerate(tracks):
                gap = (b.frames[0] - end_f) / fps
                if j == i or gap <= 0 or gap > cfg.stitch_gap_s:
                    continue
                d = float(np.linalg.norm(_first_position(b) - end_p))
                if np.isfinite(d) and d <= cfg.max_speed * gap + 0.5 and (best is None or d < best[0]):
                    best = (d, i, j)
        if best is not None:
            _, i, j = best
            merged = tracks[i].concat(tracks[j])
            tracks = [t for k, t in enumerate(tracks) if k not in (i, j)] + [merged]
            tracks.sort(key=lambda t: t.frames[0])
            changed = True
    return tracks


def _last_position(t: Track) -> np.ndarray:
    ok = np.flatnonzero(np.isfinite(t.court).all(axis=1))
    return t.court[ok[-1]] if len(ok) else np.full(2, np.nan)


def _first_position(t: Track) -> np.ndarray:
    ok = np.flatnonzero(np.isfinite(t.court).all(axis=1))
    return t.court[ok[0]] if len(ok) else np.full(2, np.nan)


def player_area(court: Court, margin: float = 1.5) -> np.ndarray:
    """``(K, 4)`` rectangles ``x0, x1, y0, y1`` (court metres) where the sport's players play: the court YAML's
    ``player_area`` (tennis: up to 8 m behind the baselines and 5 m outside the doubles lines; padel: inside
    the glass, and out through the side doors near the net), else the court's lines extended by ``margin``."""
    rects = court.extra.get("player_area")
    if rects is None:
        sx, sy = court.size
        return np.array([[-margin, sx + margin, -margin, sy + margin]], float)
    out = np.asarray(rects, float).reshape(-1, 4)
    if not np.isfinite(out).all() or (out[:, 1] <= out[:, 0]).any() or (out[:, 3] <= out[:, 2]).any():
        raise ValueError(f"{court.source}: player_area must be [[x0, x1, y0, y1], ...] with x0 < x1, y0 < y1")
    return out


def on_court(court_xy: np.ndarray, court: Court, margin: float, slack_m: float = 0.0) -> np.ndarray:
    """(T, 2) positions → (T,) inside the sport's playing area (:func:`player_area`), grown by ``slack_m``."""
    x, y = court_xy[:, 0:1], court_xy[:, 1:2]
    r = player_area(court, margin)
    with np.errstate(invalid="ignore"):
        return ((x >= r[:, 0] - slack_m) & (x <= r[:, 1] + slack_m)
                & (y >= r[:, 2] - slack_m) & (y <= r[:, 3] + slack_m)).any(axis=1)


def in_play_area(camera: Camera, court: Court, cfg: TrackingConfig | None = None, slack_m: float = 2.0):
    """A pose backend's ``focus``: ``Persons`` → (N,) bool, False for those whose feet stand on the floor more than
    ``slack_m`` outside the sport's playing area (:func:`player_area`: spectators, people beside the next court),
    whom player selection would drop anyway; True where the feet are not seen."""
    cfg = cfg or TrackingConfig()
    player_area(court, cfg.court_margin)  # a bad player_area fails here, not at the first look

    def focus(persons: Persons) -> np.ndarray:
        xy = court_positions(persons.keypoints, persons.kp_scores, camera, cfg.ankle_height, cfg.min_kp_score)
        return ~np.isfinite(xy).all(axis=1) | on_court(xy, court, cfg.court_margin, slack_m)

    return focus


def spread_m(t: Track) -> float:
    """How far a track moves: the larger 10-90 % range of its court x and y (m; 0 without positions)."""
    p = t.court[np.isfinite(t.court).all(axis=1)]
    if len(p) < 2:
        return 0.0
    lo, hi = np.percentile(p, [10, 90], axis=0)
    return float(np.max(hi - lo))


def selection_score(t: Track, court: Court, fps: float, cfg: TrackingConfig) -> float:
    """Seconds in the playing area + weight × metres travelled there (the thesis's player selection),
    scaled down for a person who stands still (:attr:`TrackingConfig.static_m`): beside a tennis court
    line judges, ball kids and the umpire stand inside the area players use."""
    inside = on_court(t.court, court, cfg.court_margin)
    pts = t.court[inside]
    dist = float(np.nansum(np.linalg.norm(np.diff(pts, axis=0), axis=1))) if len(pts) > 1 else 0.0
    score = inside.sum() / fps + cfg.distance_weight * dist
    return score * (cfg.static_weight if spread_m(t) < cfg.static_m else 1.0)


def select_players(tracks: list[Track], court: Court, fps: float, cfg: TrackingConfig) -> list[Track]:
    """The best ``court.n_players / 2`` tracks on each side of the net, near side first, left to right."""
    per_side = max(1, court.n_players // 2)
    sides: dict[str, list[tuple[float, Track]]] = {"near": [], "far": []}
    for t in tracks:
        m = t.median_court()
        if not np.isfinite(m).all():
            continue
        score = selection_score(t, court, fps, cfg)
        if score > 0:
            sides["near" if m[1] < court.net_y else "far"].append((score, t))
    chosen = []
    for side in ("near", "far"):
        best = sorted(sides[side], key=lambda st: -st[0])[:per_side]
        chosen += sorted((t for _, t in best), key=lambda t: t.median_court()[0])
    return chosen


def extend_ends(players: list[Track], seq: PoseSequence, camera: Camera, fps: float, cfg: TrackingConfig
                ) -> list[Track]:
    """Each chosen player's track carried past its ends onto the looks the tracker left out: the first looks
    before a tracker confirms a track, and a player leaving the picture (running wide past its edge, the feet
    out of it or under a score box: a weak, cut-off detection the tracker no longer takes). A detection
    continues a track when its box overlaps the track's box at that end by ≥ ``extend_iou`` (no other player's
    box more), for at most ``extend_s`` and across at most ``extend_miss`` looks in a row without one; the court
    position comes from its keypoints (NaN when the feet are out of the picture)."""
    from supervision import box_iou_batch

    def iou_with(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:   # (N,); NaN boxes overlap nothing
        return box_iou_batch(box[None], np.asarray(boxes, float).reshape(-1, 4))[0]

    looked = np.flatnonzero(seq.looked) if seq.looked is not None else np.arange(len(seq))
    reach = cfg.extend_s * fps
    out = [t for t in players]
    for k in range(len(out)):
        for forward in (False, True):
            t = out[k]
            end = t.frames[-1] if forward else t.frames[0]
            box = t.boxes[-1] if forward else t.boxes[0]
            steps = looked[looked > end] if forward else looked[looked < end][::-1]
            rows, misses = [], 0
            for f in steps[np.abs(steps - end) <= reach].tolist():
                p = seq.frames[f]
                ok = (p.scores >= cfg.min_person_score) & np.isfinite(p.boxes).all(axis=1)
                iou = np.where(ok, iou_with(box, p.boxes), 0.0)
                for j, other in enumerate(out):  # a detection another player's track holds there is theirs
                    if j != k and np.isin(f, other.frames):
                        taken = iou_with(other.boxes[np.searchsorted(other.frames, f)], p.boxes) > 0.5
                        iou = np.where(taken, 0.0, iou)
                i = int(np.argmax(iou)) if len(iou) else -1
                if i < 0 or iou[i] < cfg.extend_iou:
                    misses += 1
                    if misses > cfg.extend_miss:
                        break
                    continue
                misses = 0
                box = p.boxes[i]
                court = court_positions(p.keypoints[i:i + 1], p.kp_scores[i:i + 1], camera, cfg.ankle_height,
                                        cfg.min_kp_score)[0]
                rows.append((f, p.boxes[i], p.keypoints[i], p.kp_scores[i], p.scores[i], court))
            if rows:
                rows = rows if forward else rows[::-1]
                more = Track(*(np.array([r[c] for r in rows]) for c in range(6)))
                out[k] = t.concat(more) if forward else more.concat(t)
    return out


def interpolate(t: Track, fps: float, cfg: TrackingConfig) -> Track:
    """Fill gaps of at most ``max_gap_s`` by linear interpolation of every per-frame array."""
    max_gap = int(round(cfg.max_gap_s * fps))
    full = np.arange(t.frames[0], t.frames[-1] + 1)
    gap_to_prev = np.searchsorted(t.frames, full)
    known = np.isin(full, t.frames)
    # frames inside a gap short enough to fill
    prev = t.frames[np.clip(gap_to_prev - 1, 0, len(t.frames) - 1)]
    nxt = t.frames[np.clip(gap_to_prev, 0, len(t.frames) - 1)]
    fill = known | ((nxt - prev) <= max_gap + 1)
    frames = full[fill]

    def interp(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(len(values), -1)
        out = np.empty((len(frames), flat.shape[1]))
        for k in range(flat.shape[1]):
            ok = np.isfinite(flat[:, k])
            out[:, k] = np.interp(frames, t.frames[ok], flat[ok, k]) if ok.sum() > 1 else (
                flat[ok, k][0] if ok.any() else np.nan)
        return out.reshape((len(frames),) + values.shape[1:])

    scores = np.interp(frames, t.frames, t.scores)
    kp_scores = interp(t.kp_scores)
    new = ~np.isin(frames, t.frames)
    scores[new] *= 0.5  # interpolated rows are marked by a halved score
    return Track(frames, interp(t.boxes), interp(t.keypoints), kp_scores, scores, interp(t.court))


def smooth_court(t: Track, fps: float, cfg: TrackingConfig) -> Track:
    """Centred moving average of the court positions over ``smooth_s`` (NaN-aware, frames contiguous)."""
    half = int(round(cfg.smooth_s * fps / 2))
    if half < 1 or len(t) < 3:
        return t
    xy = t.court
    ok = np.isfinite(xy).all(axis=1)
    n = len(xy)
    i = np.arange(n)
    h = np.minimum(half, np.minimum(i, n - 1 - i))  # symmetric windows, narrower at the ends: no lag
    csum = np.concatenate([np.zeros((1, 2)), np.cumsum(np.where(ok[:, None], xy, 0.0), axis=0)])
    ccount = np.concatenate([[0.0], np.cumsum(ok)])
    num = csum[i + h + 1] - csum[i - h]
    den = (ccount[i + h + 1] - ccount[i - h])[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = np.where(den > 0, num / den, np.nan)
    return replace(t, court=np.where(ok[:, None], smooth, np.nan))


def to_player_tracks(players: list[Track], court: Court, image_size: tuple[int, int]) -> PlayerTracks:
    """players.csv rows: ids in list order, team by side, normalised boxes and keypoints."""
    wh = np.asarray(image_size, float)
    rows = []
    for pid, t in enumerate(players):
        team = "near" if t.median_court()[1] < court.net_y else "far"
        kp = np.concatenate([t.keypoints / wh, t.kp_scores[..., None]], axis=2)
        for k, f in enumerate(t.frames):
            rows.append((int(f), pid, team, float(t.scores[k]), t.boxes[k] / np.tile(wh, 2), kp[k], t.court[k]))
    if not rows:
        return PlayerTracks.empty()
    rows.sort(key=lambda r: (r[0], r[1]))
    n = len(rows)
    return PlayerTracks(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), [r[2] for r in rows],
                        np.array([r[3] for r in rows]), np.array([r[4] for r in rows]).reshape(n, 4),
                        np.array([r[5] for r in rows]).reshape(n, J, 3), np.array([r[6] for r in rows]).reshape(n, 2))


def players_from_poses(seq: PoseSequence, camera: Camera, court: Court, fps: float,
                       config: TrackingConfig | None = None,
                       active: np.ndarray | None = None) -> PlayerTracks:
    """The whole pipeline: track → stitch → select per side → extend the ends (:func:`extend_ends`) → interpolate
    gaps → players.csv table.

    ``active`` (N,) bool: the frames to use (court-view scenes, :mod:`inference.video.scenes`); the poses of the other
    frames are ignored and no row is written there — no gap is filled and no position smoothed across them.
    """
    cfg = config or TrackingConfig()
    if active is not None:
        active = np.asarray(active, bool)
        seq = only_frames(seq, active)
    tracks = track_people(seq, camera, fps, cfg)
    tracks = stitch(tracks, fps, cfg)
    players = [interpolate(t, fps, cfg) for t in extend_ends(select_players(tracks, court, fps, cfg), seq, camera, fps,
                                                             cfg)]
    if active is None:
        players = [smooth_court(t, fps, cfg) for t in players]
    else:
        players = [_smooth_within(t, active, fps, cfg) for t in players]
    return to_player_tracks(players, court, camera.image_size)


def only_frames(seq: PoseSequence, active: np.ndarray) -> PoseSequence:
    """``seq`` with nobody in the frames where ``active`` is False (or beyond its end)."""
    kept = [p if i < len(active) and active[i] else Persons.empty() for i, p in enumerate(seq.frames)]
    return PoseSequence(kept, seq.source, seq.looked, seq.tiled)


def take_frames(t: Track, keep: np.ndarray) -> Track:
    """The rows of ``t`` where ``keep`` (T,) bool is True."""
    fields = ("frames", "boxes", "keypoints", "kp_scores", "scores", "court")
    return Track(*(getattr(t, f)[keep] for f in fields))


def _smooth_within(t: Track, active: np.ndarray, fps: float, cfg: TrackingConfig) -> Track:
    """``t`` cut to the ``active`` frames, its court positions smoothed within each run of them."""
    from inference.video.scenes import segments

    pieces = [take_frames(t, (t.frames >= a) & (t.frames < b)) for a, b in segments(active)]
    pieces = [smooth_court(p, fps, cfg) for p in pieces if len(p)]
    if not pieces:
        return take_frames(t, np.zeros(len(t), bool))
    out = pieces[0]
    for p in pieces[1:]:
        out = out.concat(p)
    return out


def with_tracker(cfg: TrackingConfig, name: str) -> TrackingConfig:
    return replace(cfg, tracker=name)
