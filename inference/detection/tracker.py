"""Online ball tracker over per-frame heatmap candidates (original-frame pixels).

WASB-SBDT's public tracker keeps the highest-scoring blob within 300 px of the previous position; its
motion model is dead code. This one adds what that lacks, frame by frame and causally:

**Motion.** A constant-acceleration Kalman filter per track (both image axes share one 3×3 covariance;
white-jerk process noise), in pixels and seconds, so it is frame-rate aware. Candidates are gated by
the Mahalanobis distance ``m²`` to the prediction (``gate_chi2``).

**Selection.** The ball track considers the candidates in its gate and those it could **jump** to (a
hit or bounce the model could not foresee): within ``max_speed_px_s`` of its last detection and with at
least ``jump_score_ratio`` of its median score, at most ``jump_max_gap_s`` after that detection. It
takes the lowest

    cost = ½ min(m², gate_chi2) + jump_penalty · [outside the gate] · (1 + d / reach)
           − score_weight · log(score) + static_penalty · static + reflection_penalty · reflection

if it is below ``max_cost``, else it coasts. The default sizes make tiers: a clean candidate in the
gate beats any jump, a jump beats any flagged (static or reflection) candidate, and flagged candidates
exceed ``max_cost`` (``max_cost = inf`` keeps them as a last resort). After a jump the filter restarts
with the velocity of that jump.

**Static candidates.** A :class:`StaticMemory` remembers places where candidates keep reappearing
within ``static_radius_px`` (balls lying on court, court marks, a logo): after ``static_min_s`` of
sightings, forgotten after ``static_forget_s`` without one. Known still balls (``inactive_balls.csv``)
can be passed per frame too. Static candidates never start a track, are penalised in selection, and a
track whose recent detections all sit still is ended.

**Reflections.** A reflection of the ball in the glass (or a glossy floor) is its mirror image across a
horizontal line: same column, mirrored row, and it moves with the ball. Heuristic, per frame: two
candidates in nearly the same column (``|Δx| ≤ mirror_dx_px``, ``|Δy| ≥ mirror_min_dy_px``) are a
mirror pair about their mid-row (if ``glass_lines_y`` are given, only pairs whose mid-row is within
``mirror_line_tol_px`` of one of those image rows). The ball never crosses its mirror line, so the
member on the other side of the mid-row from the track's recent detections is the reflection. When the
ball track takes one member of a pair it remembers that mirror row for ``mirror_memory_s``: meanwhile
any candidate across it from the track is a reflection too, also when the ball itself was missed and
the reflection is alone. This is what resolves a bounce, where the reflection continues the pre-bounce
motion that the filter predicts.
Without a track, a pair about a configured glass line is resolved in favour of the upper member
(reflections of a ball in the floor and the lower glass appear below it); otherwise by score.

**Life cycle.** Every clean candidate that the ball track does not take seeds or extends a *tentative*
track; when no ball track exists, a tentative with ``confirm_frames`` consecutive-ish detections that
has moved at least ``birth_min_motion_px`` becomes the ball track (its earlier frames are back-filled
by :func:`track_candidates`). A track without a detection **coasts** on its prediction for up to
``max_gap_s`` (reported as an estimated position) and then dies; the next ball is found again by the
birth rule. Offline, :func:`track_candidates` withdraws coasts that no detection of the same track
closes (the ball left or was lost, so those estimates were guesses).

**Offline passes** (:func:`track_candidates`). The same tracker also runs over the reversed clip; frames
only that backward pass detected are added (the frames before a forward birth, after a forward death),
unless the forward pass had flagged that candidate static or a reflection, and without a dying backward
track's first detections cut off by a gap longer than ``backward_tail_gap_s``. Then :func:`fill_gaps`
takes, between two detections at most ``fill_max_gap_s`` apart, the clean candidate nearest the straight
path between them (within ``fill_radius_px``). Tuned on the val split by ``bench/tune_tracker.py``.

Pixel parameters are for a 720-row frame and scale with the frame height when ``image_size`` is given.

Example (``candidates``: one :class:`~.postprocess.FrameCandidates` per frame, original pixels)::

    result = track_candidates(candidates, fps=30.0, image_size=(1280, 720))
    ball = result.to_ball_track(1280, 720)          # BallTrack, i.e. ball.csv rows
"""
from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import IntEnum

import numpy as np

from inference.clipio.tables import BallTrack, InactiveBalls

from .postprocess import FrameCandidates


class TrackState(IntEnum):
    """What the tracker reports for a frame."""

    NONE = 0        # no ball
    DETECTED = 1    # a candidate was taken
    COASTED = 2     # no candidate: the track's prediction


_PIXEL_FIELDS = ("meas_std_px", "jerk_std", "birth_speed_std", "birth_accel_std", "max_speed_px_s",
                 "static_radius_px", "mirror_dx_px", "mirror_min_dy_px", "mirror_line_tol_px",
                 "birth_min_motion_px", "fill_radius_px")
"""Fields of :class:`TrackerConfig` in pixels (or px/s, px/s², px/s³), scaled with the frame height."""


@dataclass(frozen=True)
class TrackerConfig:
    """Knobs of :class:`BallTracker`. Pixels refer to a ``reference_height``-row frame; times in seconds."""

    # motion model
    meas_std_px: float = 1.5             # centroid noise
    jerk_std: float = 2.0e4              # px/s³, white-jerk process noise of the constant-acceleration model
    birth_speed_std: float = 1500.0      # px/s, velocity prior of a new track
    birth_accel_std: float = 3000.0      # px/s², acceleration prior of a new track
    gate_chi2: float = 16.0              # Mahalanobis² gate (2 dof): 16 ≈ 4σ
    max_speed_px_s: float = 4000.0       # farthest jump after an unforeseen hit or bounce
    jump_score_ratio: float = 0.5        # ... to a candidate with at least this × the track's median score
    jump_max_gap_s: float = 0.07         # ... and only this soon after the last detection
    # selection cost (tiers: gated clean < jump < flagged; see the module docstring)
    score_weight: float = 1.0
    jump_penalty: float = 40.0
    static_penalty: float = 100.0
    reflection_penalty: float = 100.0
    max_cost: float = 80.0               # costlier ones are not taken (inf: flagged ones as a last resort)
    # static memory
    static_radius_px: float = 3.0
    static_min_s: float = 0.5            # sighted this long (total) at one place → static
    static_forget_s: float = 2.0         # a place unseen this long is forgotten
    max_static_sites: int = 256
    # reflections
    mirror_dx_px: float = 6.0
    mirror_min_dy_px: float = 6.0
    glass_lines_y: tuple[float, ...] = ()  # image rows (px, this clip's frame) of glass / floor mirror lines
    mirror_line_tol_px: float = 10.0
    reflection_history: int = 3          # recent detections that decide the track's side of a mirror line
    mirror_memory_s: float = 0.3         # a mirror row seen in a pair stays known this long
    # life cycle
    confirm_frames: int = 3              # detections before a tentative track may become the ball track
    birth_min_motion_px: float = 3.0     # ... and how far it must have moved
    tentative_max_misses: int = 2        # val-tuned (bench/tune_tracker.py)
    max_tentatives: int = 8
    max_gap_s: float = 0.2               # coast this long through misses, then the track ends
    coast_score_decay: float = 0.5       # coasted score = last detection's score × decay^misses
    drop_trailing_coast: bool = True     # track_candidates: withdraw coasts not closed by a detection
    # offline passes of track_candidates (0 / False: the online tracker's output only)
    backward_pass: bool = True           # also track the reversed clip; fill frames only it detected,
    backward_tail_gap_s: float = 0.14    # ... but not a track's first detections cut off by a longer gap
    fill_max_gap_s: float = 0.2          # fill a gap between two detections at most this long ...
    fill_radius_px: float = 20.0         # ... with the clean candidate nearest the interpolated path
    claim_min_score: float = float("inf")  # frames still without a detection take their best unflagged
    #                                        candidate scoring at least this (inf: never; F1 charges a
    #                                        miss like a wrong answer, so answering often pays)
    history: int = 64                    # detections kept per track (back-fill, stillness test)
    reference_height: float | None = 720.0  # pixel knobs are for this frame height (None: never scale)

    def for_image_height(self, height: float) -> TrackerConfig:
        """The config with its pixel knobs scaled from ``reference_height`` to ``height`` rows."""
        if self.reference_height is None or height == self.reference_height:
            return self
        k = float(height) / self.reference_height
        return replace(self, reference_height=float(height),
                       **{f: getattr(self, f) * k for f in _PIXEL_FIELDS})

    def frames(self, seconds: float, fps: float) -> int:
        """A duration as a frame count (at least 1)."""
        return max(1, round(seconds * fps))


# ------------------------------------------------------------------------------------- motion model
class ConstantAcceleration:
    """Kalman filter with state ``x (3, 2)`` = rows position, velocity, acceleration; columns image x, y.

    Both axes have the same dynamics and noise and are always measured together, so they share one
    ``(3, 3)`` covariance ``P``; the innovation variance is a scalar.
    """

    def __init__(self, dt: float, jerk_std: float, meas_std: float) -> None:
        self.dt = dt
        self.F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        g = np.array([dt ** 3 / 6.0, dt * dt / 2.0, dt])
        self.Q = np.outer(g, g) * jerk_std ** 2
        self.r2 = meas_std ** 2
        self.x = np.zeros((3, 2))
        self.P = np.eye(3)

    def start(self, xy, velocity=(0.0, 0.0), pos_std: float = 1.0, vel_std: float = 1.0,
              acc_std: float = 1.0) -> None:
        """(Re)initialise at ``xy (2,)`` with ``velocity (2,)`` px/s, zero acceleration."""
        self.x = np.array([xy, velocity, (0.0, 0.0)], dtype=np.float64)
        self.P = np.diag([pos_std ** 2, vel_std ** 2, acc_std ** 2])

    def predict(self) -> None:
        """Advance one frame."""
        self.x = self.F @ self.x
        self.P = self.F @ self.P @ self.F.T + self.Q

    @property
    def position(self) -> np.ndarray:
        """``(2,)`` current position estimate."""
        return self.x[0].copy()

    def extrapolate(self, steps) -> np.ndarray:
        """Positions ``(K, 2)`` ``steps (K,)`` frames after the current state (which is left unchanged)."""
        t = np.asarray(steps, np.float64)[:, None] * self.dt
        return self.x[0] + self.x[1] * t + 0.5 * self.x[2] * t * t

    def mahalanobis2(self, z: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distances ``(K,)`` of measurements ``z (K, 2)`` to the prediction."""
        s = self.P[0, 0] + self.r2
        return np.sum((z - self.x[0]) ** 2, axis=1) / s

    def update(self, z) -> None:
        """Correct with one measurement ``z (2,)``."""
        s = self.P[0, 0] + self.r2
        gain = self.P[:, 0] / s
        self.x = self.x + np.outer(gain, np.asarray(z, np.float64) - self.x[0])
        self.P = self.P - np.outer(gain, self.P[0])
        self.P = 0.5 * (self.P + self.P.T)


# ------------------------------------------------------------------------------------ static memory
class StaticMemory:
    """Places where candidates keep reappearing: ``sites (M, 2)``, sighting ``count (M,)``, ``last (M,)``."""

    def __init__(self, radius: float, min_frames: int, forget_frames: int, max_sites: int = 256) -> None:
        self.radius, self.min_frames, self.forget_frames = radius, min_frames, forget_frames
        self.max_sites = max_sites
        self.sites = np.empty((0, 2))
        self.count = np.empty(0, np.int64)
        self.last = np.empty(0, np.int64)

    def observe(self, xy: np.ndarray, frame: int) -> np.ndarray:
        """Record this frame's candidates ``xy (K, 2)``; return ``(K,) bool``: at a static place.

        A site counts at most one sighting per frame; its position is the running mean of the nearest
        candidate of each sighting.
        """
        self._forget(frame)
        site = self._nearest_site(xy)
        matched = site >= 0
        if matched.any():
            sites, first = np.unique(site[matched], return_index=True)
            idx = np.flatnonzero(matched)[first]
            n = self.count[sites][:, None]
            self.sites[sites] = (self.sites[sites] * n + xy[idx]) / (n + 1)
            self.count[sites] += 1
            self.last[sites] = frame
        static = np.zeros(len(xy), bool)
        static[matched] = self.count[site[matched]] >= self.min_frames
        self._add(xy[~matched], frame)
        return static

    def _nearest_site(self, xy: np.ndarray) -> np.ndarray:
        """``(K,) int`` index of the site within ``radius`` of each point, -1 for none."""
        if not len(self.sites) or not len(xy):
            return np.full(len(xy), -1)
        d = np.linalg.norm(xy[:, None] - self.sites[None], axis=-1)
        j = np.argmin(d, axis=1)
        return np.where(d[np.arange(len(xy)), j] <= self.radius, j, -1)

    def _add(self, xy: np.ndarray, frame: int) -> None:
        self.sites = np.concatenate([self.sites, xy])
        self.count = np.concatenate([self.count, np.ones(len(xy), np.int64)])
        self.last = np.concatenate([self.last, np.full(len(xy), frame)])
        if len(self.sites) > self.max_sites:   # keep the most-sighted, then the most recent
            keep = np.lexsort((self.last, self.count))[-self.max_sites:]
            self._keep(np.sort(keep))

    def _forget(self, frame: int) -> None:
        stale = frame - self.last > self.forget_frames
        if stale.any():
            self._keep(~stale)

    def _keep(self, index) -> None:
        self.sites, self.count, self.last = self.sites[index], self.count[index], self.last[index]


def near_any(xy: np.ndarray, points: np.ndarray | None, radius: float) -> np.ndarray:
    """``(K,) bool``: ``xy (K, 2)`` within ``radius`` of any of ``points (M, 2)``."""
    if points is None or not len(points) or not len(xy):
        return np.zeros(len(xy), bool)
    d = np.linalg.norm(xy[:, None] - np.asarray(points, np.float64).reshape(-1, 2)[None], axis=-1)
    return d.min(axis=1) <= radius


# -------------------------------------------------------------------------------------- reflections
def mirror_pairs(xy: np.ndarray, dx_max: float, dy_min: float, lines_y: Sequence[float] = (),
                 line_tol: float = 10.0) -> np.ndarray:
    """``(K, K) bool``: candidates ``i, j`` that may be mirror images across a horizontal line.

    ``|x_i − x_j| ≤ dx_max`` and ``|y_i − y_j| ≥ dy_min``; when ``lines_y`` (image rows of glass or
    floor mirror lines) are given, their mid-row must also lie within ``line_tol`` of one of them.
    """
    x, y = xy[:, 0], xy[:, 1]
    pair = (np.abs(x[:, None] - x[None, :]) <= dx_max) & (np.abs(y[:, None] - y[None, :]) >= dy_min)
    if len(lines_y) and len(xy):
        mid = 0.5 * (y[:, None] + y[None, :])
        pair &= np.min(np.abs(mid[..., None] - np.asarray(lines_y, np.float64)), axis=-1) <= line_tol
    return pair


def across(y: np.ndarray, line_y, y_ref: float) -> np.ndarray:
    """Elementwise: ``y`` lies strictly on the other side of ``line_y`` than ``y_ref``."""
    ref_side = np.sign(y_ref - line_y)
    return (np.sign(y - line_y) == -ref_side) & (ref_side != 0)


def reflection_flags(xy: np.ndarray, y_ref: float, pairs: np.ndarray) -> np.ndarray:
    """``(K,) bool``: the member of each mirror pair on the other side of its mid-row from ``y_ref``
    (the track's recent rows; ``-inf`` flags the lower member)."""
    if len(xy) < 2 or np.isnan(y_ref):
        return np.zeros(len(xy), bool)
    y = xy[:, 1]
    mid = 0.5 * (y[:, None] + y[None, :])
    return np.any(pairs & across(y[:, None], mid, y_ref), axis=1)


# ------------------------------------------------------------------------------------------- tracks
@dataclass
class _Track:
    """One hypothesis: its filter, recent detections and consecutive misses."""

    id: int
    filter: ConstantAcceleration
    maxlen: int
    frames: deque = field(init=False)
    xy: deque = field(init=False)
    scores: deque = field(init=False)
    static: deque = field(init=False)
    misses: int = 0
    hits: int = 0
    mirror_y: float = float("nan")   # last mirror row seen in a pair with this track's ball
    mirror_frame: int = -1

    def __post_init__(self) -> None:
        self.frames, self.xy, self.scores, self.static = (deque(maxlen=self.maxlen) for _ in range(4))

    def record(self, frame: int, xy: np.ndarray, score: float, static: bool) -> None:
        self.frames.append(frame)
        self.xy.append(np.asarray(xy, np.float64).copy())
        self.scores.append(float(score))
        self.static.append(bool(static))
        self.misses = 0
        self.hits += 1

    def recent_y(self, n: int) -> float:
        """Mean row of the last ``n`` detections."""
        return float(np.mean([p[1] for p in list(self.xy)[-n:]]))

    def moved(self) -> float:
        """Distance between the first and the last kept detection."""
        return float(np.linalg.norm(self.xy[-1] - self.xy[0]))

    def still(self, n: int, radius: float) -> bool:
        """The last ``n`` detections all lie within ``radius`` of their mean and were flagged static."""
        if len(self.xy) < n:
            return False
        pts = np.array(list(self.xy)[-n:])
        spread = np.linalg.norm(pts - pts.mean(axis=0), axis=1).max()
        return bool(spread <= radius and all(list(self.static)[-n:]))


@dataclass(frozen=True)
class FrameEstimate:
    """What :meth:`BallTracker.update` reports for one frame.

    Attributes:
        state: :class:`TrackState`.
        xy: ``(2,)`` pixels (NaN when ``NONE``).
        score: the taken candidate's score, a decayed score when coasting, 0 when ``NONE``.
        track_id: the ball track's id (-1 when ``NONE``).
        backfill: ``(frame, xy (2,), score)`` detections of earlier frames that a just-confirmed track
            made before it became the ball track.
    """

    state: TrackState
    xy: np.ndarray
    score: float
    track_id: int = -1
    backfill: tuple[tuple[int, np.ndarray, float], ...] = ()


NO_BALL = FrameEstimate(TrackState.NONE, np.full(2, np.nan), 0.0)


class BallTracker:
    """Causal single-ball tracker; feed one frame's candidates at a time to :meth:`update`.

    Args:
        fps: frame rate (velocities are per second).
        config: :class:`TrackerConfig`.
        image_size: ``(width, height)`` of the frames: scales the pixel knobs and stops reporting coasts
            that leave the frame.
    """

    def __init__(self, fps: float, config: TrackerConfig = TrackerConfig(),
                 image_size: tuple[int, int] | None = None) -> None:
        if fps <= 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        self.fps = float(fps)
        self.cfg = config if image_size is None else config.for_image_height(image_size[1])
        self.image_size = image_size
        c = self.cfg
        self.max_gap = c.frames(c.max_gap_s, fps)
        self.static_frames = c.frames(c.static_min_s, fps)
        self.reset()

    def reset(self) -> None:
        """Forget all tracks and static places."""
        c = self.cfg
        self.frame = 0
        self.main: _Track | None = None
        self.tentatives: list[_Track] = []
        forget = c.frames(c.static_forget_s, self.fps)
        self.memory = StaticMemory(c.static_radius_px, self.static_frames, forget, c.max_static_sites)
        self._next_id = 0
        self._last_detection = -1   # last frame reported DETECTED
        self.flagged = np.zeros(0, bool)   # last frame's candidates flagged static or reflection

    # -------------------------------------------------------------------------------------- update
    def update(self, xy, score, static_xy=None) -> FrameEstimate:
        """Process the next frame.

        Args:
            xy: ``(K, 2)`` candidate centres in original-frame pixels.
            score: ``(K,)`` candidate scores (> 0; e.g. Σ heatmap).
            static_xy: ``(M, 2)`` known still balls in this frame (e.g. ``inactive_balls.csv``), or None.

        Returns:
            :class:`FrameEstimate` for this frame.
        """
        cand = FrameCandidates.from_arrays(xy, score)
        xy, score = cand.xy, np.maximum(cand.score, 1e-9)
        static = self.memory.observe(xy, self.frame) | near_any(xy, static_xy, self.cfg.static_radius_px)
        reflection = np.zeros(len(xy), bool)
        used = np.zeros(len(xy), bool)
        estimate = NO_BALL
        if self.main is not None:
            pairs = self._pairs(xy)
            reflection = self._reflections(self.main, xy, pairs)
            estimate, j = self._step_main(xy, score, static, reflection)
            if j >= 0:
                used[j] = True
                self._remember_mirror(xy, pairs, j)
        self._step_tentatives(xy, score, static, used | reflection)
        if self.main is None:
            estimate = self._promote() or estimate
        if estimate.state == TrackState.DETECTED:
            self._last_detection = self.frame
        self.flagged = static | reflection
        self.frame += 1
        return estimate

    def expected(self, steps) -> tuple[np.ndarray, float] | None:
        """Where the ball track expects the ball ``steps (K,)`` frames after the last frame fed to
        :meth:`update` (``(K, 2)`` px), with its last detection's score; ``None`` without a ball track or
        while it coasts (crop-tracking then runs the full frame)."""
        track = self.main
        if track is None or track.misses > 0:
            return None
        return track.filter.extrapolate(steps), float(track.scores[-1])

    def _pairs(self, xy: np.ndarray) -> np.ndarray:
        c = self.cfg
        return mirror_pairs(xy, c.mirror_dx_px, c.mirror_min_dy_px, c.glass_lines_y, c.mirror_line_tol_px)

    def _reflections(self, track: _Track, xy: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """``(K,) bool``: reflections of the track's ball, from this frame's pairs and the remembered row."""
        y_ref = track.recent_y(self.cfg.reflection_history)
        flags = reflection_flags(xy, y_ref, pairs)
        if self.frame - track.mirror_frame <= self.cfg.frames(self.cfg.mirror_memory_s, self.fps):
            flags |= across(xy[:, 1], track.mirror_y, y_ref)
        return flags

    def _remember_mirror(self, xy: np.ndarray, pairs: np.ndarray, j: int) -> None:
        """If the taken candidate ``j`` has a mirror partner, remember their mid-row on the ball track."""
        if self.main is None or not pairs[j].any():
            return
        partners = np.flatnonzero(pairs[j])
        k = partners[np.argmin(np.abs(xy[partners, 0] - xy[j, 0]))]
        self.main.mirror_y = 0.5 * (xy[j, 1] + xy[k, 1])
        self.main.mirror_frame = self.frame

    # ---------------------------------------------------------------------------------- ball track
    def _step_main(self, xy, score, static, reflection) -> tuple[FrameEstimate, int]:
        """Predict the ball track and take a candidate; returns the estimate and the index taken (-1)."""
        c, track = self.cfg, self.main
        track.filter.predict()
        cost, jump = self._selection_cost(track, xy, score, static, reflection)
        j = int(np.argmin(cost)) if len(cost) else -1
        if j >= 0 and cost[j] >= c.max_cost:
            j = -1
        if j < 0:
            return self._coast(track), -1
        if jump[j]:
            self._restart_after_jump(track, xy[j])
        else:
            track.filter.update(xy[j])
        track.record(self.frame, xy[j], score[j], static[j])
        if track.still(self.static_frames, c.static_radius_px):
            self.main = None                         # locked on something lying still: let go
            return NO_BALL, j
        return FrameEstimate(TrackState.DETECTED, xy[j].copy(), float(score[j]), track.id), j

    def _selection_cost(self, track: _Track, xy, score, static, reflection
                        ) -> tuple[np.ndarray, np.ndarray]:
        """``cost (K,)`` (inf where neither gated nor reachable) and ``jump (K,) bool`` (outside the gate)."""
        c = self.cfg
        m2 = track.filter.mahalanobis2(xy)
        gap = self.frame - track.frames[-1]
        reach = c.max_speed_px_s * gap / self.fps
        jump = m2 > c.gate_chi2
        reachable = ((np.linalg.norm(xy - track.xy[-1], axis=1) <= reach)
                     & (score >= c.jump_score_ratio * np.median(track.scores))
                     & (gap <= self.cfg.frames(c.jump_max_gap_s, self.fps)))
        d = np.linalg.norm(xy - track.filter.position, axis=1)
        cost = (0.5 * np.minimum(m2, c.gate_chi2) + c.jump_penalty * jump * (1.0 + d / reach)
                - c.score_weight * np.log(score) + c.static_penalty * static
                + c.reflection_penalty * reflection)
        return np.where(~jump | reachable, cost, np.inf), jump

    def _restart_after_jump(self, track: _Track, z: np.ndarray) -> None:
        c = self.cfg
        gap = self.frame - track.frames[-1]
        velocity = (z - track.xy[-1]) * self.fps / gap
        track.filter.start(z, velocity, c.meas_std_px, 0.25 * c.birth_speed_std, c.birth_accel_std)

    def _coast(self, track: _Track) -> FrameEstimate:
        track.misses += 1
        if track.misses > self.max_gap:
            self.main = None
            return NO_BALL
        self._bounce_off_mirror(track)
        xy = track.filter.position
        if self.image_size is not None and not _inside(xy, self.image_size):
            return NO_BALL
        score = track.scores[-1] * self.cfg.coast_score_decay ** track.misses
        return FrameEstimate(TrackState.COASTED, xy, float(score), track.id)

    def _bounce_off_mirror(self, track: _Track) -> None:
        """A coast that crosses the remembered mirror row bounces: mirror the row, reverse its speed."""
        if self.frame - track.mirror_frame > self.cfg.frames(self.cfg.mirror_memory_s, self.fps):
            return
        y_ref = track.recent_y(self.cfg.reflection_history)
        if across(track.filter.x[0, 1], track.mirror_y, y_ref):
            track.filter.x[0, 1] = 2.0 * track.mirror_y - track.filter.x[0, 1]
            track.filter.x[1, 1] *= -1.0

    # ---------------------------------------------------------------------------------- tentatives
    def _step_tentatives(self, xy, score, static, taken) -> None:
        """Extend tentative tracks with free clean candidates, start new ones, drop stale ones."""
        c = self.cfg
        free = ~(taken | static)
        for track in sorted(self.tentatives, key=lambda t: -t.hits):
            track.filter.predict()
            m2 = track.filter.mahalanobis2(xy)
            ok = np.flatnonzero(free & (m2 <= c.gate_chi2))
            if len(ok):
                j = int(ok[np.argmin(m2[ok])])
                track.filter.update(xy[j])
                track.record(self.frame, xy[j], score[j], False)
                free[j] = False
            else:
                track.misses += 1
        self.tentatives = [t for t in self.tentatives if t.misses <= c.tentative_max_misses]
        for j in np.flatnonzero(free)[np.argsort(-score[free], kind="stable")]:
            self.tentatives.append(self._new_track(xy[j], score[j]))
        self.tentatives = sorted(self.tentatives, key=lambda t: (-t.hits, -np.mean(t.scores)))
        del self.tentatives[c.max_tentatives:]

    def _new_track(self, xy, score) -> _Track:
        c = self.cfg
        f = ConstantAcceleration(1.0 / self.fps, c.jerk_std, c.meas_std_px)
        f.start(xy, (0.0, 0.0), c.meas_std_px, c.birth_speed_std, c.birth_accel_std)
        track = _Track(self._next_id, f, c.history)
        self._next_id += 1
        track.record(self.frame, xy, score, False)
        return track

    def _promote(self) -> FrameEstimate | None:
        """Make the best confirmed, moving tentative (detected this frame) the ball track."""
        c = self.cfg
        ready = [t for t in self.tentatives if t.misses == 0 and t.hits >= c.confirm_frames
                 and t.moved() >= c.birth_min_motion_px]
        if not ready:
            return None
        if c.glass_lines_y and len(ready) > 1:   # a mirror pair about a glass line: the upper one
            xy = np.array([t.xy[-1] for t in ready])
            flags = reflection_flags(xy, -np.inf, self._pairs(xy))
            ready = [t for t, f in zip(ready, flags) if not f] or ready
        best = max(ready, key=lambda t: np.mean(t.scores))
        self.tentatives.remove(best)
        self.main = best
        earlier = [(f, p, s) for f, p, s in zip(best.frames, best.xy, best.scores)
                   if self._last_detection < f < self.frame]
        return FrameEstimate(TrackState.DETECTED, best.xy[-1].copy(), best.scores[-1], best.id,
                             tuple(earlier))


def _inside(xy: np.ndarray, image_size: tuple[int, int]) -> bool:
    return bool(0.0 <= xy[0] <= image_size[0] and 0.0 <= xy[1] <= image_size[1])


# ------------------------------------------------------------------------------------------ results
@dataclass
class TrackResult:
    """Per-frame tracker output for frames ``0..T-1``.

    Attributes:
        state: ``(T,) int8`` :class:`TrackState`.
        xy: ``(T, 2)`` original-frame pixels, NaN where ``NONE``.
        score: ``(T,)`` confidence (candidate score; decayed when coasting; 0 when ``NONE``).
        track_id: ``(T,) int64`` ball-track id, -1 where ``NONE``.
    """

    state: np.ndarray
    xy: np.ndarray
    score: np.ndarray
    track_id: np.ndarray

    @classmethod
    def empty(cls, n_frames: int) -> TrackResult:
        return cls(np.zeros(n_frames, np.int8), np.full((n_frames, 2), np.nan), np.zeros(n_frames),
                   np.full(n_frames, -1, np.int64))

    def __len__(self) -> int:
        return len(self.state)

    @property
    def visible(self) -> np.ndarray:
        """``(T,) bool``: a position is reported."""
        return self.state != TrackState.NONE

    def reversed(self) -> TrackResult:
        """The result with its frames in reverse order (a copy)."""
        return TrackResult(self.state[::-1].copy(), self.xy[::-1].copy(), self.score[::-1].copy(),
                           self.track_id[::-1].copy())

    def set(self, frame: int, state: TrackState, xy, score: float, track_id: int) -> None:
        """Write one frame's report."""
        self.state[frame], self.xy[frame] = state, xy
        self.score[frame], self.track_id[frame] = score, track_id

    def to_ball_track(self, width: int, height: int, coast_visibility: int = 3, first_frame: int = 0
                      ) -> BallTrack:
        """``ball.csv`` rows for every frame: visibility 1 for detections, ``coast_visibility`` for coasts
        (3, "occluded, estimated position", by default; 0 withdraws them), 0 for no ball."""
        vis = np.select([self.state == TrackState.DETECTED, self.state == TrackState.COASTED],
                        [1, coast_visibility], default=0).astype(np.int8)
        size = np.array([width, height], np.float64)
        xy = np.where(vis[:, None] > 0, np.clip(self.xy, 0.0, size), np.nan)
        return BallTrack.from_pixels(np.arange(len(self)) + first_frame, vis, xy, width, height)


def track_candidates(candidates: Sequence[FrameCandidates], fps: float,
                     config: TrackerConfig = TrackerConfig(), image_size: tuple[int, int] | None = None,
                     static_xy: Sequence[np.ndarray | None] | None = None) -> TrackResult:
    """Run :class:`BallTracker` over a clip's candidates (original-frame pixels), with the offline passes.

    1. The online tracker, forwards, with back-filling of each new track's tentative frames.
    2. ``backward_pass``: the same tracker over the reversed clip; frames that only it detected (mostly
       the frames before a forward birth, and after a forward track ended) are taken from it.
    3. ``fill_max_gap_s``: :func:`fill_gaps` between detections with clean candidates near the path.
    4. ``claim_min_score``: :func:`claim_free_frames`, the best unflagged candidate where still none.
    5. ``drop_trailing_coast``: :func:`drop_unclosed_coasts`.

    Args:
        candidates: ``T`` :class:`FrameCandidates` (or ``(xy, score[, area])`` tuples).
        fps, config, image_size: see :class:`BallTracker`.
        static_xy: optional ``T`` arrays ``(M, 2)`` of known still balls per frame
            (:func:`inactive_positions`).
    """
    cands = [FrameCandidates.from_arrays(c[0], c[1]) for c in candidates]
    static_xy = [None] * len(cands) if static_xy is None else list(static_xy)
    out, flagged, cfg = _one_pass(cands, fps, config, image_size, static_xy)
    if cfg.backward_pass and len(cands):
        back, back_flagged, _ = _one_pass(cands[::-1], fps, config, image_size, static_xy[::-1])
        back = back.reversed()
        peel_tails(back, cfg.frames(cfg.backward_tail_gap_s, fps))
        merge_backward(out, back, cands, flagged)
        flagged = [f | b for f, b in zip(flagged, back_flagged[::-1])]
    if cfg.fill_max_gap_s > 0:
        fill_gaps(out, cands, flagged, cfg.frames(cfg.fill_max_gap_s, fps), cfg.fill_radius_px)
    if np.isfinite(cfg.claim_min_score):
        claim_free_frames(out, cands, flagged, cfg.claim_min_score)
    if cfg.drop_trailing_coast:
        drop_unclosed_coasts(out)
    return out


def _one_pass(cands: list[FrameCandidates], fps: float, config: TrackerConfig,
              image_size: tuple[int, int] | None, static_xy: list
              ) -> tuple[TrackResult, list[np.ndarray], TrackerConfig]:
    """The online tracker over ``cands`` with back-filling; also each frame's ``(K,) bool`` flagged
    (static or reflection) candidates, and the (image-scaled) config."""
    tracker = BallTracker(fps, config, image_size)
    out = TrackResult.empty(len(cands))
    flagged = []
    for t, cand in enumerate(cands):
        est = tracker.update(cand.xy, cand.score, static_xy[t])
        flagged.append(tracker.flagged)
        out.set(t, est.state, est.xy, est.score, est.track_id)
        for f, xy, score in est.backfill:
            out.set(f, TrackState.DETECTED, xy, score, est.track_id)
    return out, flagged, tracker.cfg


def peel_tails(result: TrackResult, max_gap: int) -> None:
    """In place: drop each track's first detections while more than ``max_gap`` frames separate them
    from its next one (a dying backward track that grabbed clutter before giving up)."""
    for tid in np.unique(result.track_id[result.state == TrackState.DETECTED]):
        frames = np.flatnonzero((result.track_id == tid) & (result.state == TrackState.DETECTED))
        gaps = np.diff(frames)
        n = 0
        while n < len(gaps) and gaps[n] > max_gap:
            n += 1
        drop = frames[:n]
        result.state[drop], result.xy[drop], result.score[drop], result.track_id[drop] = 0, np.nan, 0.0, -1


def merge_backward(result: TrackResult, backward: TrackResult, candidates: Sequence[FrameCandidates] = (),
                   flagged: Sequence[np.ndarray] = ()) -> None:
    """In place: frames ``result`` did not detect but ``backward`` (a pass over the reversed clip, put
    back in order) did take its detection, unless ``result``'s pass ``flagged`` that candidate (static
    or a reflection: e.g. a backward birth on the brighter mirror image at the end of a flight); its
    track ids are shifted past ``result``'s.

    ``candidates`` / ``flagged``: per frame, the candidates and ``(K,) bool`` flags of ``result``'s pass
    (empty: no veto).
    """
    take = (result.state != TrackState.DETECTED) & (backward.state == TrackState.DETECTED)
    for t in np.flatnonzero(take) if len(flagged) else ():
        hit = np.all(candidates[t].xy == backward.xy[t], axis=1) & np.asarray(flagged[t], bool)
        take[t] = not hit.any()
    shift = int(result.track_id.max(initial=-1)) + 1
    result.state[take], result.xy[take] = TrackState.DETECTED, backward.xy[take]
    result.score[take], result.track_id[take] = backward.score[take], backward.track_id[take] + shift


def fill_gaps(result: TrackResult, candidates: Sequence[FrameCandidates], flagged: Sequence[np.ndarray],
              max_gap: int, radius: float) -> None:
    """In place: in each run of at most ``max_gap`` frames without a detection between two detections,
    take in every frame the unflagged candidate nearest the straight path between the two detections,
    if it is within ``radius`` px of it (a ball missed by the tracker's gate, e.g. after a bounce).

    ``flagged``: per frame ``(K,) bool``, candidates that are static or reflections.
    """
    det = np.flatnonzero(result.state == TrackState.DETECTED)
    for a, b in zip(det[:-1], det[1:]):
        if not 1 < b - a <= max_gap + 1:
            continue
        for t in range(a + 1, b):
            cand = candidates[t]
            ok = _unflagged(cand, flagged[t])
            if not ok.any():
                continue
            w = (t - a) / (b - a)
            path = (1.0 - w) * result.xy[a] + w * result.xy[b]
            d = np.where(ok, np.linalg.norm(cand.xy - path, axis=1), np.inf)
            j = int(np.argmin(d))
            if d[j] <= radius:
                result.set(t, TrackState.DETECTED, cand.xy[j], float(cand.score[j]), int(result.track_id[a]))


def _unflagged(cand: FrameCandidates, flags: np.ndarray) -> np.ndarray:
    """``(K,) bool``: candidates no pass flagged (all of them when the flags do not match the frame)."""
    return ~np.asarray(flags, bool) if len(flags) == cand.count else np.ones(cand.count, bool)


def claim_free_frames(result: TrackResult, candidates: Sequence[FrameCandidates],
                      flagged: Sequence[np.ndarray], min_score: float) -> None:
    """In place: every frame without a detection takes its highest-scoring candidate that no pass
    flagged (static or a reflection) and that scores at least ``min_score`` — max-score's answer with
    the tracker's vetoes — as a detection of its own (track id -1). A coasting track's frames prefer the
    candidate nearest the coasted position among those scoring at least half the best."""
    for t in np.flatnonzero(result.state != TrackState.DETECTED):
        cand = candidates[t]
        if not cand.count:
            continue
        ok = _unflagged(cand, flagged[t])
        ok &= cand.score >= min_score
        if not ok.any():
            continue
        score = np.where(ok, cand.score, -np.inf)
        j = int(np.argmax(score))
        if result.state[t] == TrackState.COASTED:
            near = ok & (cand.score >= 0.5 * score[j])
            d = np.where(near, np.linalg.norm(cand.xy - result.xy[t], axis=1), np.inf)
            j = int(np.argmin(d))
        result.set(t, TrackState.DETECTED, cand.xy[j], float(cand.score[j]), -1)


def drop_unclosed_coasts(result: TrackResult) -> None:
    """In place: coasted runs not followed by a detection of the same track become ``NONE``."""
    coast = result.state == TrackState.COASTED
    if not coast.any():
        return
    edges = np.diff(np.concatenate([[0], coast.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)   # run = [start, end)
    nxt = np.minimum(ends, len(result) - 1)
    closed = ((ends < len(result)) & (result.state[nxt] == TrackState.DETECTED)
              & (result.track_id[nxt] == result.track_id[starts]))
    run_of = np.cumsum(edges[:-1] == 1) - 1
    drop = coast & ~closed[np.maximum(run_of, 0)]
    result.state[drop] = TrackState.NONE
    result.xy[drop] = np.nan
    result.score[drop] = 0.0
    result.track_id[drop] = -1


def inactive_positions(inactive: InactiveBalls, n_frames: int, width: int, height: int) -> list[np.ndarray]:
    """Known still balls per frame: ``n_frames`` arrays ``(M_t, 2)`` in pixels, for ``static_xy``."""
    px = inactive.xy * np.array([width, height], np.float64)
    bounds = np.searchsorted(inactive.frame, np.arange(n_frames + 1))
    return [px[bounds[t]:bounds[t + 1]] for t in range(n_frames)]


# ----------------------------------------------------------------------------------------- baseline
def max_score_track(candidates: Sequence[FrameCandidates], max_disp: float = 300.0) -> TrackResult:
    """WASB-SBDT's online tracker, the baseline: the highest-scoring candidate, and when the previous
    frame had a ball only among those closer than ``max_disp`` px to it; none left → no ball."""
    out = TrackResult.empty(len(candidates))
    prev = None
    for t, cand in enumerate(candidates):
        xy = np.asarray(cand[0], np.float64).reshape(-1, 2)
        score = np.asarray(cand[1], np.float64).reshape(-1)
        ok = np.ones(len(xy), bool) if prev is None else np.linalg.norm(xy - prev, axis=1) < max_disp
        if ok.any():
            j = int(np.flatnonzero(ok)[np.argmax(score[ok])])
            out.set(t, TrackState.DETECTED, xy[j], score[j], 0)
            prev = xy[j]
        else:
            prev = None
    return out
