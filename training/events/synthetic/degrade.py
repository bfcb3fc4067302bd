"""A ball-detector degradation model: make an annotated (or simulated) 2D ball track look like what the
real pipeline writes to ``ball.csv`` (``rally3d infer``: WASB heatmaps → tracker → coasts dropped → RTS
smoother cut at change points), so the hit-event models can be trained and tuned on such tracks.

What a real detector track looks like (measured on the embedded sample and the rendered ``synth_padel``
clips): recall ~0.5–0.65, with the ball missed for 5–15 frames (at 30 fps) around the near player's hits
where the body hides it and in runs of 3–10 frames elsewhere; precision ~0.85–0.9, the wrong positions
15–150 px off (stuck on a reflection, lagging behind, a blob beside the ball); 1–3 px jitter. The
tracker's coasts are dropped by the pipeline, so every miss is a gap (no row / visibility 0), and the
smoother then drops isolated outliers and smooths each piece. :func:`degrade` applies, in this order:

1. jitter: Gaussian, σ drawn per clip in ``jitter_px`` (pixels of the clip's frame);
2. gaps around events: each ``player_near`` hit is hidden with probability ``p_occlude_near`` for
   ``occlude_s`` seconds (the body; the hit at a random place inside the gap), ``player_far`` hits with
   ``p_occlude_far`` for ``occlude_far_s`` (default half as long), and every other event (bounce, wall, net) with ``p_gap_event`` for
   ``event_gap_s`` — on real tracks the tracker and the smoother's change-point cuts lose the ball at
   most direction changes, so the ball is missing around most events; the far player's serve with
   ``p_serve_gap_far`` in a longer gap that lies mostly before the contact (the toss lost against the crowd);
3. random runs of misses of ``miss_run_s`` seconds until ``miss_frac`` of the visible frames are missed
   by them (on top of the occlusions);
4. wrong positions on ``outlier_frac`` of the remaining detections, in runs of ``outlier_run`` frames,
   each run ``outlier_px`` pixels off: a fixed offset (a blob beside the ball), stuck (a reflection: one
   position for the whole run) or lagging (the position of 2–6 frames earlier, pushed off);
5. the pipeline's smoother (:func:`inference.detection.smooth.smooth_track`) with probability ``p_smooth``.

A clip is left as annotated with probability ``p_clean`` (keeps the clean-input accuracy), or degraded by
``alternative`` (another tracker's look) with probability ``p_alternative``. Lengths are in seconds so the
model is the same at 25–60 fps.

Example:
    >>> cfg = DegradeConfig()
    >>> out = degrade(sim_clip, np.random.default_rng(0), cfg)
    >>> out.track, out.occluded.sum(), out.outlier.sum()
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from inference.clipio import BallTrack

from training.events.data.parallel import clip_rngs, map_clips
from training.events.synthetic.simulate import SimClip, every_frame


def _pair(name: str, v, lo: float = 0.0) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in v)
    except (TypeError, ValueError):
        raise ValueError(f"DegradeConfig.{name} must be a [min, max] pair, got {v!r}") from None
    if not (np.isfinite(a) and np.isfinite(b)) or a < lo or b < a:
        raise ValueError(f"DegradeConfig.{name} must be [min, max] with {lo} <= min <= max, got {v!r}")
    return a, b


@dataclass(frozen=True)
class DegradeConfig:
    """Parameters of :func:`degrade` (see the module docstring); ``enabled: false`` keeps clean tracks.

    Attributes:
        enabled: degrade the training (and tuning) tracks at all.
        p_clean: probability that a clip is left as annotated.
        p_occlude_near, p_occlude_far: probability that a near / far player's hit is hidden.
        occlude_s: [min, max] length (s) of the gap around a near hit (far hits: half).
        p_gap_event, event_gap_s: probability and [min, max] length (s) of a gap around any other event.
        miss_frac: fraction of the visible frames missed by random runs; miss_run_s: their length (s).
        outlier_frac: fraction of the detections with a wrong position; outlier_run: run length (frames);
        outlier_px: [min, max] offset (pixels).
        jitter_px: [min, max] of the per-clip jitter σ (pixels).
        p_smooth: probability that the pipeline's RTS smoother is applied.
        every_epoch: draw new degradations each training epoch (else once).
        val_copies: degraded copies of each validation clip used for checkpointing, temperature and
            decoder tuning (beside the clean clip).
        integer_px: round the detections to whole pixels (trackers that report a heatmap's argmax).
        far_miss: probability that a detection above ``far_y`` (normalised image height: the far end,
            where the ball is a few pixels) is missed; top_crop: the image's top ``top_crop`` is out of the
            frame (lobs leaving it). All three are off by default (the default draws are unchanged).
        occlude_far_s: [min, max] length (s) of the gap around a far hit (None: half of ``occlude_s``); a
            real broadcast tracker loses the far player's hits for longer than the near one's
            (``training.events.stats.real_stats``).
        p_serve_gap_far: probability that the far player's serve (the hit at ``SimClip.rally[0]``) hides in a
            gap of ``serve_gap_s`` seconds of which a share drawn in ``serve_before`` lies before the contact:
            a broadcast tracker loses the far server's toss against the crowd (off by default).
        alternative: another degradation (the same fields) that a clip gets instead with probability
            ``p_alternative``: one model trained on two trackers' looks (e.g. a real broadcast tracker's and
            the project's own detector's, ``conf/data/degrade/detector_measured.yaml``).
    """

    enabled: bool = True
    p_clean: float = 0.2
    p_occlude_near: float = 0.8
    p_occlude_far: float = 0.3
    occlude_s: tuple[float, float] = (5 / 30, 15 / 30)
    p_gap_event: float = 0.5
    event_gap_s: tuple[float, float] = (3 / 30, 8 / 30)
    miss_frac: float = 0.2
    miss_run_s: tuple[float, float] = (3 / 30, 10 / 30)
    outlier_frac: float = 0.12
    outlier_run: tuple[float, float] = (1, 4)
    outlier_px: tuple[float, float] = (15.0, 150.0)
    jitter_px: tuple[float, float] = (1.0, 3.0)
    p_smooth: float = 0.8
    every_epoch: bool = True
    val_copies: int = 1
    integer_px: bool = False
    far_miss: float = 0.0
    far_y: float = 0.45
    top_crop: float = 0.0
    miss_by_diameter: tuple = ()
    occlude_far_s: tuple | None = None
    p_serve_gap_far: float = 0.0
    serve_gap_s: tuple[float, float] = (0.2, 0.65)
    serve_before: tuple[float, float] = (0.65, 0.95)
    alternative: dict | None = None
    p_alternative: float = 0.0

    def __post_init__(self) -> None:
        for name in ("p_clean", "p_occlude_near", "p_occlude_far", "p_gap_event", "miss_frac", "outlier_frac", "p_smooth",
                     "far_miss", "far_y", "top_crop", "p_serve_gap_far", "p_alternative"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"DegradeConfig.{name} must be a probability/fraction in [0, 1], got {v!r}")
        if self.miss_frac >= 0.95 or self.outlier_frac >= 0.95:
            raise ValueError("DegradeConfig.miss_frac and outlier_frac must be below 0.95 (nothing would be left)")
        for name in ("occlude_s", "event_gap_s", "miss_run_s", "outlier_px", "jitter_px", "serve_gap_s",
                     "serve_before"):
            object.__setattr__(self, name, _pair(name, getattr(self, name)))
        if self.serve_before[1] > 1.0:
            raise ValueError(f"DegradeConfig.serve_before is a share of the gap in [0, 1], got {self.serve_before!r}")
        if self.alternative is not None:  # validated now, so a bad nested key fails at start-up, not mid-epoch
            alt = DegradeConfig.from_dict(self.alternative)
            if alt.alternative is not None:
                raise ValueError("DegradeConfig.alternative cannot have an alternative of its own")
            object.__setattr__(self, "alternative", alt)
        elif self.p_alternative > 0:
            raise ValueError("DegradeConfig.p_alternative > 0 needs an alternative setting")
        if self.occlude_far_s is not None:
            object.__setattr__(self, "occlude_far_s", _pair("occlude_far_s", self.occlude_far_s))
        run = _pair("outlier_run", self.outlier_run, lo=1)
        object.__setattr__(self, "outlier_run", (int(run[0]), int(run[1])))
        if self.miss_run_s[0] <= 0:
            raise ValueError(f"DegradeConfig.miss_run_s must be positive, got {self.miss_run_s}")
        pairs = tuple(tuple(float(v) for v in row) for row in (self.miss_by_diameter or ()))
        if any(len(r) != 2 or r[0] < 0 or not 0 <= r[1] <= 1 for r in pairs):
            raise ValueError("DegradeConfig.miss_by_diameter must be [[diameter_px >= 0, miss rate in [0, 1]], ...], "
                             f"got {self.miss_by_diameter!r}")
        object.__setattr__(self, "miss_by_diameter", tuple(sorted(pairs)))
        if int(self.val_copies) < 0:
            raise ValueError(f"DegradeConfig.val_copies must be >= 0, got {self.val_copies}")

    @classmethod
    def from_dict(cls, d) -> DegradeConfig:
        if d is not None and not isinstance(d, cls):
            # "measured": the figures a measured setting was derived from (bench_track_stats.py)
            d = {k: v for k, v in dict(d).items() if k != "measured"}
            if d.get("alternative") is not None and not isinstance(d["alternative"], cls):
                d["alternative"] = dict(d["alternative"])  # an OmegaConf node → a plain mapping
        return config_from_dict(cls, d, "data.degrade")

    def pick(self, rng: np.random.Generator) -> DegradeConfig:
        """The setting one clip gets: :attr:`alternative` with probability :attr:`p_alternative`, else this."""
        if self.alternative is not None and self.p_alternative > 0 and rng.random() < self.p_alternative:
            return self.alternative
        return self


def config_from_dict(cls, d, key: str):
    """``cls`` from a config mapping (None: ``enabled: false``); unknown keys are an error naming ``key``."""
    if isinstance(d, cls):
        return d
    d = dict(d or {"enabled": False})
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"unknown {key} keys {unknown}; known: {sorted(known)}")
    return cls(**d)


@dataclass
class Degraded:
    """A degraded track and what was done to it (masks over the clip's frames, before smoothing).

    Attributes:
        track: the track as the pipeline's ``ball.csv`` would hold it.
        occluded: ``(T,)`` frames hidden around hits; missed: ``(T,)`` frames missed by random runs;
        outlier: ``(T,)`` detections given a wrong position; smoothed: whether the smoother ran.
    """

    track: BallTrack
    occluded: np.ndarray
    missed: np.ndarray
    outlier: np.ndarray
    smoothed: bool


def _frames(seconds: float, fps: float) -> int:
    return max(1, int(round(seconds * fps)))


def occlusion_mask(sim: SimClip, rng: np.random.Generator, cfg: DegradeConfig) -> np.ndarray:
    """``(T,)`` frames hidden around the events: the players' hits (the body in front of the ball) and the
    other events (the track lost at the direction change)."""
    n = sim.n_frames
    mask = np.zeros(n, bool)
    far = (cfg.occlude_far_s, 1.0) if cfg.occlude_far_s is not None else (cfg.occlude_s, 0.5)
    hits = {"player_near": (cfg.p_occlude_near, cfg.occlude_s, 1.0), "player_far": (cfg.p_occlude_far, *far)}
    serve = sim.rally[0] if sim.rally is not None else None
    for f, label in zip(sim.events.frame, sim.events.event):
        if cfg.p_serve_gap_far > 0 and str(label) == "player_far" and serve is not None and int(f) == int(serve):
            if rng.random() < cfg.p_serve_gap_far:  # the far serve: its toss lost against the crowd
                length = _frames(rng.uniform(*cfg.serve_gap_s), sim.fps)
                start = int(f) - int(round(rng.uniform(*cfg.serve_before) * length))
                mask[max(start, 0):max(start + length, 0)] = True
            continue
        p, span, scale = hits.get(str(label), (cfg.p_gap_event, cfg.event_gap_s, 1.0))
        if p <= 0 or rng.random() >= p:
            continue
        length = _frames(scale * rng.uniform(*span), sim.fps)
        start = int(f) - int(rng.integers(0, length))  # the hit somewhere inside the gap
        mask[max(start, 0):max(start + length, 0)] = True
    return mask


def ball_diameter_px(sim: SimClip, height_m: float = 1.0, radius_m: float = 0.033) -> np.ndarray:
    """``(T,)`` the ball's image diameter (pixels) estimated from the camera: the line of sight through the
    2D ball meets the plane ``z = height_m`` there; NaN where the ball is missing or the ray misses it."""
    cam = sim.camera
    xy = every_frame(sim.ball, sim.n_frames).xy
    out = np.full(len(xy), np.nan)
    ok = np.flatnonzero(np.isfinite(xy).all(axis=1))
    if cam is None or not len(ok):
        return out
    o, v = cam.rays_normalized(xy[ok])
    o, v = np.broadcast_to(np.asarray(o, float), v.shape), np.asarray(v, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (height_m - o[:, 2]) / v[:, 2]
    X = o + t[:, None] * v
    good = np.isfinite(t) & (t > 0)
    depth = cam.depth(X[good])
    out[ok[good]] = 2.0 * radius_m * float(cam.K[0, 0]) / np.maximum(depth, 1e-6)
    return out


def miss_runs(visible: np.ndarray, already: np.ndarray, fps: float, rng: np.random.Generator,
              cfg: DegradeConfig, weight: np.ndarray | None = None) -> np.ndarray:
    """``(T,)`` runs of misses added until ``miss_frac`` of the visible frames are missed by them; a run
    starts at a visible frame drawn in proportion to ``weight`` (default: uniform)."""
    n = len(visible)
    target = int(round(cfg.miss_frac * visible.sum()))
    mask = np.zeros(n, bool)
    idx = np.flatnonzero(visible)
    prob = None
    if weight is not None and len(idx):
        w = np.nan_to_num(np.asarray(weight, float)[idx], nan=0.0)
        prob = w / w.sum() if w.sum() > 0 else None
    tries = 0
    while (mask & visible).sum() < target and len(idx) and tries < 10_000:
        tries += 1
        length = _frames(rng.uniform(*cfg.miss_run_s), fps)
        a = int(idx[rng.integers(0, len(idx))] if prob is None else rng.choice(idx, p=prob))
        run = np.zeros(n, bool)
        run[a:a + length] = True
        need = target - (mask & visible).sum()
        gain = run & visible & ~mask
        if gain.sum() > need:  # trim the last run so the rate is met exactly
            keep = np.flatnonzero(gain)[:need]
            run[:] = False
            run[keep] = True
        mask |= run
    return mask & ~already


def outlier_positions(xy_px: np.ndarray, detected: np.ndarray, rng: np.random.Generator,
                      cfg: DegradeConfig) -> np.ndarray:
    """Replace ``outlier_frac`` of the detected positions (pixels, in place) by wrong ones; returns the mask."""
    n = len(detected)
    target = int(round(cfg.outlier_frac * detected.sum()))
    mask = np.zeros(n, bool)
    idx = np.flatnonzero(detected)
    truth = xy_px.copy()
    tries = 0
    while mask.sum() < target and len(idx) and tries < 10_000:
        tries += 1
        a = int(idx[rng.integers(0, len(idx))])
        length = min(int(rng.integers(cfg.outlier_run[0], cfg.outlier_run[1] + 1)), target - int(mask.sum()))
        run = [k for k in range(a, min(a + length, n)) if detected[k] and not mask[k]]
        if not run:
            continue
        ang = rng.uniform(0, 2 * np.pi)
        off = rng.uniform(*cfg.outlier_px) * np.array([np.cos(ang), np.sin(ang)])
        kind = rng.integers(0, 3)
        for k in run:
            if kind == 0:    # a blob beside the ball, moving with it
                xy_px[k] = truth[k] + off
            elif kind == 1:  # stuck on a reflection
                xy_px[k] = truth[run[0]] + off
            else:            # lagging behind, pushed off
                lag = int(rng.integers(2, 7))
                src = truth[max(k - lag, 0)]
                xy_px[k] = (src if np.isfinite(src).all() else truth[k]) + off
            mask[k] = True
    return mask


def degrade(sim: SimClip, rng: np.random.Generator, cfg: DegradeConfig = DegradeConfig(),
            track: BallTrack | None = None) -> Degraded:
    """The clip's ball (``track``, default ``sim.ball``) as the detection pipeline would write it. The result
    has one row per frame; missed frames, and frames the input has no row for (a real tracker's missing
    rows, an annotator's gaps), get visibility 0 and NaN positions."""
    from inference.detection.smooth import smooth_track

    n = sim.n_frames
    ball = every_frame(track if track is not None else sim.ball, n)
    none = np.zeros(n, bool)
    cfg = cfg.pick(rng) if cfg.enabled else cfg
    if not cfg.enabled or rng.random() < cfg.p_clean:
        return Degraded(ball, none, none.copy(), none.copy(), False)
    size = np.array([sim.width, sim.height], float)
    visible = (ball.visibility > 0) & np.isfinite(ball.xy).all(axis=1)
    xy = ball.xy * size
    xy[visible] += rng.normal(0.0, rng.uniform(*cfg.jitter_px), (int(visible.sum()), 2))
    occluded = occlusion_mask(sim, rng, cfg) & visible
    weight = None
    if cfg.miss_by_diameter:  # misses where the ball is small, as the detector's measured rates say
        d, r = np.array(cfg.miss_by_diameter).T
        weight = np.interp(ball_diameter_px(sim), d, r) + 1e-3
    missed = miss_runs(visible, occluded, sim.fps, rng, cfg, weight)
    detected = visible & ~occluded & ~missed
    if cfg.far_miss > 0:  # the far end: a small ball, lost more often
        far = detected & (ball.xy[:, 1] < cfg.far_y)
        missed |= far & (rng.random(n) < cfg.far_miss)
        detected &= ~missed
    if cfg.top_crop > 0:  # lobs leave the frame
        missed |= detected & (ball.xy[:, 1] < cfg.top_crop)
        detected &= ~missed
    outlier = outlier_positions(xy, detected, rng, cfg)
    xy = np.clip(xy, 0.0, size)
    if cfg.integer_px:
        xy = np.round(xy)
    vis = detected.astype(np.int8)
    xy[~detected] = np.nan
    out = BallTrack(np.arange(n), vis, xy / size)
    smoothed = bool(rng.random() < cfg.p_smooth) and detected.sum() > 0
    if smoothed:
        out = smooth_track(out, sim.width, sim.height, sim.fps).track
    return Degraded(out, occluded, missed, outlier, smoothed)


def degrade_all(clips: list[SimClip], seed: int, cfg: DegradeConfig, workers: int = 0) -> list[BallTrack]:
    """Degraded tracks of many clips; the same seed gives the same tracks (``workers``: forked processes,
    :func:`~training.events.data.parallel.map_clips`)."""
    rngs = clip_rngs(seed, len(clips))
    return map_clips(lambda k: degrade(clips[k], rngs[k], cfg).track, len(clips), workers)
