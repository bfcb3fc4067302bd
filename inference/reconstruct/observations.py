"""What the 3D reconstruction reads from a clip, and how a rally splits into flight segments.

Inputs are the clip folder only: camera.yaml (``P`` alone suffices), ball.csv, events.csv and, when
present, players.csv. Nothing needs court_points.csv, the video or ground truth.

Example:
    >>> obs = Observations.from_clip(Clip("datasets/sample/padel_sample"))
    >>> segs = obs.segments()                     # flights between consecutive events
    >>> priors = contact_priors(obs)              # 3D guesses for each event's contact point
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from inference.camera import Camera
from inference.clipio import BallTrack, Clip, FormatError, HitEvents, PlayerTracks
from inference.clipio.csvfiles import separate_same_frame
from inference.court import Court, Plane, load_court
from inference.court.geometry import intersect_planes
from inference.players.skeleton import COCO17

PLAYER_EVENTS = ("player_near", "player_far")
#: frames searched for a 2D ball around a surface contact when none is within 2 frames (the fit moves the
#: contact point on its surface, so a rough first guess is enough)
FAR_GAP = 10
#: COCO-17 indices of the wrists (the hitter's hand height when players.csv has poses)
WRISTS = (COCO17.index("left_wrist"), COCO17.index("right_wrist"))
SHOULDERS = (COCO17.index("left_shoulder"), COCO17.index("right_shoulder"))
#: a hand this far (m) above both shoulders is raised (a serve, a smash)
RAISED_M = 0.15


@dataclass
class Observations:
    """A rally's inputs, indexed by frame.

    Attributes:
        court, camera: the scene.
        fps: frame rate.
        uv: (F, 2) ball pixels for frames 0..F-1 (NaN where not visible or not labelled).
        events: (E,) frames and (E,) labels, sorted by frame.
        players: player tracks (court positions) or None.
        source: where it came from (for messages).
        pixel_sigma: the 2D noise of ``uv`` (px) when measured (:func:`clip_pixel_sigma`); None: the fit's
            default.
    """

    court: Court
    camera: Camera
    fps: float
    uv: np.ndarray
    event_frames: np.ndarray
    event_labels: list[str]
    players: PlayerTracks | None = None
    source: str = ""
    pixel_sigma: float | None = None

    def __post_init__(self) -> None:
        self.uv = np.asarray(self.uv, dtype=float).reshape(-1, 2)
        self.uv[~np.isfinite(self.uv).all(axis=1)] = np.nan
        frames = np.asarray(self.event_frames, dtype=np.int64).reshape(-1)
        if len(frames) != len(self.event_labels):
            raise ValueError("event_frames and event_labels must have the same length")
        # events on one frame (or out of order): sorted, each moved to its own frame as events.csv's reader does
        frames, labels, _ = separate_same_frame(frames, np.asarray(self.event_labels, dtype=object),
                                                len(self.uv) or None)
        self.event_frames = frames
        self.event_labels = [str(x) for x in labels]

    @property
    def single_event(self) -> bool:
        """At most one distinct event frame: the lead-in and run-out are the whole replay."""
        return len(np.unique(self.event_frames)) < 2

    @property
    def n_frames(self) -> int:
        return len(self.uv)

    @classmethod
    def from_tables(cls, court: Court, camera: Camera, fps: float, track: BallTrack, events: HitEvents,
                    n_frames: int, players: PlayerTracks | None = None, source: str = "") -> Observations:
        """Build from the clip tables; the ball's normalised coordinates become pixels."""
        uv = np.full((n_frames, 2), np.nan)
        keep = (track.visibility > 0) & (track.frame < n_frames)
        uv[track.frame[keep]] = track.xy[keep] * np.asarray(camera.image_size, float)
        ev = events.frame < n_frames
        return cls(court, camera, fps, uv, events.frame[ev], [str(e) for e in events.event[ev]], players, source)

    @classmethod
    def from_clip(cls, clip: Clip, court: Court | None = None, camera: Camera | None = None) -> Observations:
        """Read camera.yaml, ball.csv, events.csv and players.csv (if present) of a clip."""
        court = court or load_court(clip.court_path())
        camera = camera or clip.read_camera()
        try:  # players.csv is optional: a file that cannot be read costs the hitter prior, not the rally
            players = clip.read_players(missing_ok=True)
        except FormatError as err:
            warnings.warn(f"{err}; reconstructing without players' positions", stacklevel=2)
            players = None
        obs = cls.from_tables(court, camera, clip.info.fps, clip.read_ball(), clip.read_events(), clip.n_frames,
                              players if players is not None and len(players) else None, str(clip.root))
        return replace(obs, pixel_sigma=clip_pixel_sigma(clip, obs.uv))

    def with_track(self, uv: np.ndarray) -> Observations:
        """The same rally with other 2D positions (e.g. noisy or detected)."""
        return Observations(self.court, self.camera, self.fps, uv, self.event_frames, list(self.event_labels),
                            self.players, self.source, self.pixel_sigma)

    def beyond_edges(self) -> dict[int, int]:
        """Frames without a 2D ball where the track shows where the ball is: beyond the image edge it left
        through (a lob above the top, a wide ball off a side) — ``{frame: edge}``, edges :data:`EDGES`.

        A gap of the track whose last point before lies within :data:`EDGE_MARGIN` of an edge, moving towards
        it, is beyond that edge for its first half; one whose first point after lies near an edge, moving away
        from it, for its second half (both: the whole gap when they agree).
        """
        w, h = (float(v) for v in self.camera.image_size)
        seen = np.isfinite(self.uv).all(axis=1)
        out: dict[int, int] = {}
        m = np.r_[0, (~seen).astype(int), 0]
        edges = np.flatnonzero(np.diff(m))
        for a, b in zip(edges[::2], edges[1::2]):   # unobserved frames a .. b-1
            if a < 2 or b > len(seen) - 2:
                continue
            leave = _edge_of(self.uv[a - 1], self.uv[a - 1] - self.uv[a - 2], w, h)
            enter = _edge_of(self.uv[b], self.uv[b] - self.uv[b + 1], w, h)
            half = (a + b) // 2
            if leave is not None:
                out.update({f: leave for f in range(a, b if enter == leave else half + (b - a) % 2)})
            if enter is not None and enter != leave:
                out.update({f: enter for f in range(half, b)})
        return out

    def segments(self) -> list[Segment]:
        """The flights between consecutive events (E-1 segments)."""
        f, lab = self.event_frames, self.event_labels
        return [Segment(i, int(f[i]), int(f[i + 1]), lab[i], lab[i + 1]) for i in range(len(f) - 1)]


#: image edges a ball can leave through (:meth:`Observations.beyond_edges`)
EDGES = ("top", "bottom", "left", "right")
#: a ball this close to an edge (share of the image height) and moving towards it is leaving the picture
EDGE_MARGIN = 0.06


def _edge_of(uv: np.ndarray, motion: np.ndarray, w: float, h: float) -> int | None:
    """The index in :data:`EDGES` of the edge that a ball at ``uv`` (px) moving by ``motion`` (px a frame, towards
    the edge) is about to leave through, or None."""
    if not (np.isfinite(uv).all() and np.isfinite(motion).all()):
        return None
    m = EDGE_MARGIN * h
    dist = (uv[1], h - uv[1], uv[0], w - uv[0])
    towards = (motion[1] < 0, motion[1] > 0, motion[0] < 0, motion[0] > 0)
    near = [k for k in range(4) if dist[k] < m and towards[k]]
    return min(near, key=lambda k: dist[k]) if near else None


#: the 2D noise assumed at 720 lines (px); larger frames scale it (a detector sees a fixed input size)
PIXEL_SIGMA_720 = 2.0


def track_noise_px(uv: np.ndarray, half: int = 3) -> float | None:
    """The 2D noise (px) of a ball track ``uv`` (F, 2), NaN where missing: the robust spread (MAD) of each
    frame's distance from a quadratic through its ``2·half + 1`` neighbours, over every full window (a flight
    is smooth over a few frames; contacts are few and the median ignores them). None with fewer than 10
    windows."""
    uv = np.asarray(uv, float)
    t = np.arange(-half, half + 1, dtype=float)
    A = np.stack([np.ones_like(t), t, t * t], 1)
    H = A @ np.linalg.pinv(A)
    full = np.convolve(np.isfinite(uv).all(axis=1).astype(int), np.ones(2 * half + 1, int), "valid") == 2 * half + 1
    starts = np.flatnonzero(full)
    if len(starts) < 10:
        return None
    win = np.stack([uv[s:s + 2 * half + 1] for s in starts])           # (W, 2h+1, 2)
    r = (win - np.einsum("ij,wjk->wik", H, win))[:, half] / np.sqrt(1.0 - H[half, half])
    mad = 1.4826 * np.median(np.abs(r - np.median(r, axis=0)), axis=0)
    return float(np.sqrt(np.mean(mad**2)))


def clip_pixel_sigma(clip: Clip, uv: np.ndarray) -> float:
    """The 2D noise (px) the fit assumes for a clip: :data:`PIXEL_SIGMA_720` scaled to its frame height, or
    the noise measured on its track when larger (the detector's raw track, ``.rally3d/ball_detected.csv``,
    when the pipeline kept it: ball.csv is smoothed). On real 1080p broadcasts the detector's noise is
    3–5 px, which a fixed 2 px would call a failed flight."""
    floor = PIXEL_SIGMA_720 * clip.info.height / 720.0
    raw = clip.root / ".rally3d" / "ball_detected.csv"
    if raw.is_file():
        try:
            from inference.clipio import read_ball_csv

            t = read_ball_csv(raw)
            keep = (t.visibility == 1) & (t.frame < len(uv))  # detections (coasts are the tracker's guesses)
            uv = np.full_like(uv, np.nan)
            uv[t.frame[keep]] = t.xy[keep] * np.array([clip.info.width, clip.info.height], float)
        except (FormatError, OSError):
            pass
    measured = track_noise_px(uv)
    return float(max(floor, measured or 0.0))


@dataclass(frozen=True)
class Segment:
    """The ball's flight from one contact (event) to the next.

    Attributes:
        index: position in the rally; start, end: event frames; start_event, end_event: their labels (None
            for a free end: the flight before the first event or after the last one).
    """

    index: int
    start: int
    end: int
    start_event: str | None
    end_event: str | None

    @property
    def frames(self) -> np.ndarray:
        """(n,) the frames from start to end inclusive."""
        return np.arange(self.start, self.end + 1)

    @property
    def duration_frames(self) -> int:
        return self.end - self.start


@dataclass
class ContactPrior:
    """What is known about one contact before fitting.

    Attributes:
        frame: the event frame; label: its label.
        kind: ``plane`` (floor/wall/net: the point lies on a known surface) or ``hit`` (a racket).
        point: (3,) a first 3D guess of the ball centre (NaN if none could be made).
        plane: the surface touched (for ``plane`` contacts whose line of sight meets one), else None.
        candidates: the planes the label allows.
        hitter_xy: (2,) the hitter's court position for a racket hit when players.csv has it.
        hand_z: the hitter's hand (wrist) height (m) when players.csv has a pose for that frame, else None.
        hand_raised: that hand is above both shoulders (a serve, a smash: the ball is above it).
        outside: the line of sight misses the surface's extent: the point is on the unbounded plane.
        reason: why no point could be made (empty when fine).
    """

    frame: int
    label: str
    kind: str
    point: np.ndarray
    plane: Plane | None = None
    candidates: list[Plane] = field(default_factory=list)
    hitter_xy: np.ndarray | None = None
    hand_z: float | None = None
    hand_raised: bool = False
    outside: bool = False
    reason: str = ""

    @property
    def ok(self) -> bool:
        return bool(np.all(np.isfinite(self.point)))


def nearest_observed(uv: np.ndarray, frame: int, max_gap: int = 2) -> tuple[np.ndarray | None, int]:
    """The ball pixel at ``frame``, or at the nearest frame within ``max_gap`` that has one."""
    for d in range(max_gap + 1):
        for f in (frame - d, frame + d):
            if 0 <= f < len(uv) and np.all(np.isfinite(uv[f])):
                return uv[f], f
    return None, -1


def hitter_position(obs: Observations, frame: int, label: str) -> np.ndarray | None:
    """(2,) the court position of the hitter of a racket hit: the player of the named team nearest to the
    ball's line of sight at that frame (players.csv), or None."""
    row = hitter_row(obs, frame, label)
    return None if row is None else obs.players.court_xy[row]


#: a player whose court position (at 1 m height) lies farther than the court's reach + this (m) from the ball's
#: line of sight at a hit is not its hitter (the players stage found the partner, not the hitter: its pull
#: had sent a real-looking lob 97 px off its track); the margin holds the position's and the hit frame's error
HITTER_RAY_MARGIN_M = 1.5
#: with no ball within 2 frames of a hit, its hitter is the player of the team nearest to the line of sight of
#: the ball seen nearest in time, up to this long (s) before or after (no reach check: the ball has moved)
HITTER_LOOK_S = 0.4


def hitter_row(obs: Observations, frame: int, label: str) -> int | None:
    """players.csv row of the hitter of a racket hit at ``frame`` (see :func:`hitter_position`): players of
    the named team, or, where players.csv has no team, on that side of the net; None when the nearest of them
    stands farther from the ball's line of sight than the reach allows (:data:`HITTER_RAY_MARGIN_M`). With no
    ball within 2 frames of the hit, the line of sight of the ball seen nearest in time (:data:`HITTER_LOOK_S`)
    decides, without the reach check."""
    if obs.players is None or label not in PLAYER_EVENTS:
        return None
    team = label.split("_")[1]
    p = obs.players
    here = np.flatnonzero((p.frame == frame) & np.isfinite(p.court_xy).all(axis=1))
    side = np.where(p.court_xy[here, 1] < obs.court.net_y, "near", "far")
    rows = here[(p.team[here] == team) | ((p.team[here] == "") & (side == team))]
    if not len(rows):
        return None
    uv, _ = nearest_observed(obs.uv, frame)
    wide = uv is None  # no ball at the hit (a lob out of the picture, a tracker's gap): the nearest one seen
    if wide:
        uv, _ = nearest_observed(obs.uv, frame, max(2, int(round(HITTER_LOOK_S * obs.fps))))
        if uv is None or len(rows) == 1:
            return int(rows[0])
    o, d = obs.camera.rays(uv[None])
    # distance from each candidate (at 1 m height) to the line of sight
    X = np.column_stack([p.court_xy[rows], np.ones(len(rows))])
    v = X - o
    dist = np.linalg.norm(v - (v @ d[0])[:, None] * d, axis=1)
    k = int(np.argmin(dist))
    if not wide and dist[k] > float(obs.court.hits.reach) + HITTER_RAY_MARGIN_M:
        return None
    return int(rows[k])


def keypoint_heights(obs: Observations, row: int, joints: tuple[int, ...]) -> np.ndarray:
    """(J,) heights (m) of the hitter's keypoints ``joints``: each one's line of sight meets the upright plane
    through the player's court position facing the camera; NaN where the keypoint is missing, unsure
    (score ≤ 0.3) or its height is outside 0–3.5 m."""
    p = obs.players
    kp = p.keypoints[row, list(joints)]                                   # (J, 3) normalised x, y, score
    out = np.full(len(joints), np.nan)
    ok = np.isfinite(kp).all(axis=1) & (kp[:, 2] > 0.3)
    foot = np.array([*p.court_xy[row], 0.0])
    n = foot - obs.camera.centre
    n[2] = 0.0
    if not ok.any() or np.linalg.norm(n) < 1e-6:
        return out
    o, d = obs.camera.rays(kp[ok, :2] * np.asarray(obs.camera.image_size, float))
    dn = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (o + (((foot - o) @ n) / dn)[:, None] * d)[:, 2]
    z[(np.abs(dn) < 1e-9) | ~((z >= 0.0) & (z <= 3.5))] = np.nan
    out[ok] = z
    return out


def hand_height(obs: Observations, row: int, uv: np.ndarray | None) -> tuple[float | None, bool]:
    """Height (m) of the hitter's hand nearest the ball in the image (:func:`keypoint_heights`; None without a
    usable wrist), and whether that hand is raised above both shoulders (a serve or a smash: the ball is
    then above the hand by about the racket's length)."""
    z = keypoint_heights(obs, row, WRISTS + SHOULDERS)
    wz = z[:2]
    if not np.isfinite(wz).any():
        return None, False
    k = np.flatnonzero(np.isfinite(wz))
    if uv is not None and len(k) > 1:
        px = obs.players.keypoints[row, list(WRISTS), :2] * np.asarray(obs.camera.image_size, float)
        k = k[[int(np.argmin(np.linalg.norm(px[k] - uv, axis=1)))]]
    hand = float(wz[k[0]])
    shoulders = z[2:]
    raised = bool(np.isfinite(shoulders).all() and hand > shoulders.max() + RAISED_M)
    return hand, raised


#: height (m) of a racket hit's first guess when neither the ball nor the hitter's hand says more
HIT_HEIGHT_GUESS_M = 1.1


def hit_point_guess(obs: Observations, uv: np.ndarray, hitter_xy: np.ndarray | None) -> np.ndarray:
    """(3,) a racket hit's 3D guess on the line of sight: at the hitter's depth when known, else at the
    middle of the court's hit-height range."""
    o, d = obs.camera.rays(uv[None])
    o, d = o[0], d[0]
    if hitter_xy is not None:
        # the point of the ray closest (horizontally) to the hitter
        dh = d[:2] / max(np.linalg.norm(d[:2]), 1e-9)
        s = (hitter_xy - o[:2]) @ dh / max(np.linalg.norm(d[:2]), 1e-9)
    else:
        h = float(np.mean(obs.court.hits.height))
        s = (h - o[2]) / d[2] if abs(d[2]) > 1e-9 else np.nan
    lo, hi = obs.court.hits.height
    p = o + s * d
    if not np.isfinite(s) or s <= 0:
        return np.full(3, np.nan)
    if not lo <= p[2] <= hi:  # move along the ray into the height range
        z = np.clip(p[2], lo, hi)
        s = (z - o[2]) / d[2] if abs(d[2]) > 1e-9 else s
        p = o + s * d
    return p


def unbounded(plane: Plane) -> Plane:
    """The same plane without its extent (a landing beyond the court polygon)."""
    big = 1e4
    return replace(plane, polygon=np.array([[-big, -big], [big, -big], [big, big], [-big, big]]))


def contact_priors(obs: Observations, unbounded_ok: bool = True) -> list[ContactPrior]:
    """One :class:`ContactPrior` per event (:func:`contact_prior`)."""
    return [contact_prior(obs, frame, label, unbounded_ok)
            for frame, label in zip(obs.event_frames.tolist(), obs.event_labels)]


def contact_prior(obs: Observations, frame: int, label: str, unbounded_ok: bool = True) -> ContactPrior:
    """What is known of a contact at ``frame`` with event ``label``: a surface contact from the line of sight ∩
    the label's planes (ball radius included, first valid plane of a group; with ``unbounded_ok`` a line of
    sight that misses every extent falls back to the unbounded plane, flagged ``outside``), a racket hit from
    its hitter or a height prior."""
    r = obs.court.ball.radius
    uv, _ = nearest_observed(obs.uv, frame)
    if label in PLAYER_EVENTS:
        row = hitter_row(obs, frame, label)
        hitter = None if row is None else obs.players.court_xy[row]
        point = hit_point_guess(obs, uv, hitter) if uv is not None else np.full(3, np.nan)
        reason = "" if uv is not None else "no 2D ball near the hit frame"
        hand, raised = hand_height(obs, row, uv) if row is not None else (None, False)
        if uv is None and hitter is not None:  # no ball near the hit (a lob leaving the picture): at the hitter
            point = np.r_[hitter, hand if hand is not None else HIT_HEIGHT_GUESS_M]
        return ContactPrior(frame, label, "hit", point, hitter_xy=hitter, hand_z=hand, hand_raised=raised,
                            reason=reason)
    planes = obs.court.planes_for(label)
    if not planes:
        return ContactPrior(frame, label, "plane", np.full(3, np.nan),
                            reason=f"court {obs.court.name} has no surface for event {label!r}")
    if uv is None:  # e.g. a bounce on the near glass right under the camera: use a farther frame
        uv, _ = nearest_observed(obs.uv, frame, max_gap=FAR_GAP)
    if uv is None:
        return ContactPrior(frame, label, "plane", np.full(3, np.nan), plane=planes[0], candidates=planes,
                            reason=f"no 2D ball within {FAR_GAP} frames of the event")
    o, d = obs.camera.rays(uv[None])
    hit = intersect_planes(o, d, planes, offset=r)
    if hit.valid[0]:
        return ContactPrior(frame, label, "plane", hit.points[0], planes[hit.plane_index[0]], planes)
    wide = intersect_planes(o, d, [unbounded(p) for p in planes], offset=r) if unbounded_ok else hit
    if wide.valid[0]:
        return ContactPrior(frame, label, "plane", wide.points[0], planes[wide.plane_index[0]], planes, outside=True)
    return ContactPrior(frame, label, "plane", np.full(3, np.nan), plane=planes[0], candidates=planes,
                        reason=f"the line of sight at frame {frame} misses every {label} surface")
