"""The runtime hit-event detector: a ball track (and optionally camera, players) → events.csv rows.

Example:
    >>> det = EventDetector.from_checkpoint(None, sport="padel")   # the shipped default
    >>> result = det.predict(clip.read_ball(), fps, width, height, camera=clip.read_camera())
    >>> write_events_csv(clip.events_path, result.events)

A model file (``*.pth.tar``, loaded with ``weights_only=True``) is a dict:
``format = "rally3d-events"``, ``kind`` (``hitnet`` | ``physics`` | ``crop``), ``class_set`` (dict), ``features``
(dict), ``window``, ``last_k``, ``lookahead`` (frames after the label block, default 0), ``net`` (HitNet
hyper-parameters), ``state_dict``, ``decode`` (the tuned decoder) and ``physics`` (parameters of the physics detector), plus ``meta`` (training data, metrics).
A ``crop`` model (:mod:`.crop`) also stores ``crop`` (its :class:`~.crop.CropConfig`) and needs the clip's
frames: ``predict(..., frames=clip.frames())``.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from inference.clipio import BallTrack, HitEvents, PlayerTracks
from inference.court import load_court

from .classes import ClassSet
from .decode import DecodeParams, decode, event_spread
from .features import (
    FeatureConfig,
    check_label_block,
    clip_features,
    dense_xy,
    from_ref_frames,
    make_windows,
    probs_to_clip,
    resample_xy,
    window_probs_to_frames,
)
from .gaps import BridgeParams, bridge_events
from .network import EventTagger, HitNet
from .physics import PhysicsParams, physics_probs
from .rally import CourtSides, RallyParams, RallySegment, segment_rally

log = logging.getLogger(__name__)

FORMAT = "rally3d-events"
WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
DEFAULT_WEIGHTS = {"padel": "hitnet_padel.pth.tar", "tennis": "hitnet_tennis.pth.tar"}
#: Player-aware models (``features.poses``; the event taggers, docs/events.md#event-tagger), used by default when
#: the clip has players; shipped only where they beat the ball-only model: a sport without a file here falls back
#: to the ball-only one.
PLAYER_WEIGHTS = {"padel": "tagger_padel_players.pth.tar", "tennis": "tagger_tennis_players.pth.tar"}
#: Sports whose player-aware model also beats the ball-only one on clips without players (it was trained with
#: 10 % of its clips without any): their player-aware model is the default either way (docs/events.md).
PLAYERS_OPTIONAL = frozenset({"tennis", "padel"})
KINDS = ("hitnet", "physics", "crop", "tagger")


#: events whose class probability on their frame is below this are reported for a check (:meth:`EventResult.unsure`)
UNSURE_BELOW = 0.5


@dataclass
class EventResult:
    """Output of :meth:`EventDetector.predict`.

    Attributes:
        events: fine-grained events (docs/formats.md), ready for ``write_events_csv``.
        probs: ``(T, C)`` per-frame class probabilities at the clip's frame rate.
        classes: the C class names (``probs`` columns).
        coarse: ``(N,)`` class name of each event (before resolving to a fine label).
        rally: the point's start/end (:mod:`.rally`); None when not segmented.
        outside: events judged outside the point (warm-up bounces, the ball after it); ``events`` holds
            them too unless ``predict(..., keep_all=False)``.
        uncertainty: ``(N,)`` per event of ``events``, frames at the clip's rate: the timing's standard deviation —
            the spread of the model's probability around the event (:func:`~.decode.event_spread`), or for a racket
            hit timed from the flights on both sides of a gap (``predict(..., bridge_gaps=True)``, :mod:`.gaps`)
            the flights' uncertainty. NaN where unknown.
        confidence: ``(N,)`` the model's probability of the event's class on its frame (NaN where unknown).
    """

    events: HitEvents
    probs: np.ndarray
    classes: tuple[str, ...]
    coarse: tuple[str, ...] = ()
    rally: RallySegment | None = None
    outside: HitEvents = field(default_factory=HitEvents.empty)
    uncertainty: np.ndarray = field(default_factory=lambda: np.zeros(0))
    confidence: np.ndarray = field(default_factory=lambda: np.zeros(0))
    quiet: tuple[tuple[int, int], ...] = ()

    def events_with_timing(self) -> HitEvents:
        """``events`` with two more columns for ``events.csv`` (docs/formats.md §9): ``confidence`` and
        ``sigma_frames`` (:attr:`confidence`, :attr:`uncertainty`; empty where unknown)."""
        n = len(self.events)
        extra = dict(self.events.extra)
        for name, v in (("confidence", self.confidence), ("sigma_frames", self.uncertainty)):
            v = np.asarray(v, np.float64)
            if len(v) == n:
                extra[name] = np.array(["" if not np.isfinite(x) else f"{x:.2f}" for x in v], dtype=object)
        return HitEvents(self.events.frame, self.events.event, extra)

    def unsure(self, below: float = UNSURE_BELOW) -> str:
        """``"2 events below 0.5 confidence: ground 46 (0.41), player_far 60 (0.38)"`` — the events a reviewer
        should check, reported rather than hidden ("" when none or the model gives no confidence)."""
        c = np.asarray(self.confidence, np.float64)
        if len(c) != len(self.events):
            return ""
        low = np.flatnonzero(np.isfinite(c) & (c < below))
        if not len(low):
            return ""
        items = ", ".join(f"{self.events.event[k]} {int(self.events.frame[k])} ({c[k]:.2f})" for k in low[:8])
        more = f", +{len(low) - 8} more" if len(low) > 8 else ""
        return f"{len(low)} event{'s' if len(low) > 1 else ''} below {below:g} confidence: {items}{more}"

    def unsure_all(self, fps: float, below: float = UNSURE_BELOW) -> str:
        """:meth:`unsure` and the :attr:`quiet` stretches: ``"no event for 3.1 s between frames 40 and 133
        while the ball was seen (a missed hit or bounce?)"`` ("" when nothing to check)."""
        parts = [self.unsure(below)] + [
            f"no event for {(b - a) / fps:.1f} s between frames {a} and {b} while the ball was seen (a missed hit "
            "or bounce?)" for a, b in self.quiet]
        return "; ".join(p for p in parts if p)


#: two consecutive events further apart than this while the ball is seen: a stretch to check (the longest
#: flights, a padel lob or a tennis lob with its bounce, take about 2.5 s)
QUIET_S = 2.5


def quiet_stretches(frames: np.ndarray, seen: np.ndarray, fps: float, longest_s: float = QUIET_S,
                    min_seen: float = 0.5) -> tuple[tuple[int, int], ...]:
    """``(a, b)`` pairs of consecutive event frames more than ``longest_s`` apart with the ball seen in at least
    ``min_seen`` of the frames between them: a hit or a bounce the model missed, most likely."""
    f = np.sort(np.asarray(frames, np.int64))
    out = []
    for a, b in zip(f[:-1], f[1:]):
        if (b - a) / fps > longest_s and np.mean(seen[a + 1:b]) >= min_seen:
            out.append((int(a), int(b)))
    return tuple(out)


def ball_only_weights(sport: str) -> Path:
    """The shipped ball-only model (HitNet) of ``sport``: the baseline, and the default where no player-aware
    model is shipped (:func:`choose_weights` answers which file is the default)."""
    if sport not in DEFAULT_WEIGHTS:
        raise KeyError(f"no shipped hit-event model for sport {sport!r}; known: {sorted(DEFAULT_WEIGHTS)}. "
                       "Pass a model file (train one with python train.py +experiment=hitnet_<sport>).")
    return WEIGHTS_DIR / DEFAULT_WEIGHTS[sport]


def has_players(players: PlayerTracks | None) -> bool:
    """Whether a players table holds anything a player-aware model can read."""
    return players is not None and len(players) > 0


def choose_weights(path: str | Path | None, sport: str, players: PlayerTracks | None = None) -> Path:
    """The model file to use: ``path`` when given; else the shipped player-aware model of ``sport`` when
    ``players`` has rows (or the sport is in :data:`PLAYERS_OPTIONAL`) and such a model is shipped; else the
    shipped ball-only model."""
    if path is not None:
        return Path(path)
    wanted = has_players(players) or sport in PLAYERS_OPTIONAL
    if wanted and sport in PLAYER_WEIGHTS and (WEIGHTS_DIR / PLAYER_WEIGHTS[sport]).is_file():
        return WEIGHTS_DIR / PLAYER_WEIGHTS[sport]
    return ball_only_weights(sport)


def model_wants_players(path: str | Path) -> bool:
    """Whether the model file reads players (``features.poses``); False for files that cannot be read."""
    try:
        return bool(load_model_file(path)["features"].get("poses", False))
    except (FileNotFoundError, ValueError, KeyError, TypeError):
        return False


def load_model_file(path: str | Path) -> dict[str, Any]:
    """Read and validate an exported event-model file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"hit-event model {path} not found; train one with "
                                "`python train.py +experiment=hitnet_padel` or pass --weights PATH")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 — any unreadable file is the same user error
        raise ValueError(f"{path} is not a readable rally3d hit-event model ({type(e).__name__}: {e})") from None
    if not isinstance(blob, dict) or blob.get("format") != FORMAT:
        raise ValueError(f"{path} is not a rally3d hit-event model (no format={FORMAT!r}); a Lightning checkpoint "
                         "is exported with training.events.export.export_model")
    if blob.get("kind") not in KINDS:
        raise ValueError(f"{path}: unknown model kind {blob.get('kind')!r}; known: {KINDS}")
    return blob


class EventDetector:
    """Hit events from a ball track with a HitNet, an event tagger or the physics-aware detector, then the decoder.

    Args:
        kind: ``hitnet``, ``tagger``, ``crop`` or ``physics``.
        class_set, features, decode_params: see their classes.
        net: the HitNet (``kind == 'hitnet'``: window, last_k, lookahead are its window length, label block
            and the frames after the block, :func:`~.features.window_labels`) or the :class:`EventTagger`
            (``kind == 'tagger'``: the whole clip at once, no windows).
        physics: parameters of the physics detector.
        meta: free-form provenance (training data, metrics).
    """

    def __init__(self, kind: str, class_set: ClassSet, features: FeatureConfig, decode_params: DecodeParams, *,
                 net: HitNet | None = None, window: int = 12, last_k: int = 6,
                 lookahead: int = 0, physics: PhysicsParams | None = None, meta: dict | None = None, crop=None):
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        if kind in ("hitnet", "crop", "tagger") and net is None:
            raise ValueError(f"a {kind} detector needs its network")
        check_label_block(window, last_k, lookahead)
        self.kind, self.class_set, self.features, self.decode_params = kind, class_set, features, decode_params
        self.net = net.eval() if net is not None else None
        self.window, self.last_k, self.lookahead = int(window), int(last_k), int(lookahead)
        self.physics = physics or PhysicsParams()
        self.meta = meta or {}
        self.crop = crop  # CropConfig of a crop model
        self.court = load_court(class_set.sport) if class_set.sport else None

    # ------------------------------------------------------------------------------------ loading
    @classmethod
    def from_checkpoint(cls, path: str | Path | None, sport: str = "padel") -> EventDetector:
        """Load a model file; ``None`` loads the shipped default of ``sport``, the file ``rally3d events`` and
        ``infer`` use (:func:`choose_weights`: the event tagger where one is shipped)."""
        blob = load_model_file(choose_weights(path, sport))
        return cls.from_blob(blob)

    @classmethod
    def from_blob(cls, blob: dict[str, Any]) -> EventDetector:
        class_set = ClassSet.from_dict(blob["class_set"])
        features = FeatureConfig.from_model_file(blob["features"])
        net = None
        if blob["kind"] in ("hitnet", "tagger"):
            net = (HitNet if blob["kind"] == "hitnet" else EventTagger)(**blob["net"])
            net.load_state_dict(blob["state_dict"])
        crop = None
        if blob["kind"] == "crop":
            from .crop import CropConfig, CropHitNet

            net, crop = CropHitNet(**blob["net"]), CropConfig.from_dict(blob.get("crop"))
            net.load_state_dict(blob["state_dict"])
        return cls(blob["kind"], class_set, features, DecodeParams.from_dict(blob["decode"]), net=net,
                   window=int(blob.get("window", 12)), last_k=int(blob.get("last_k", 6)),
                   lookahead=int(blob.get("lookahead", 0)), physics=PhysicsParams(**blob.get("physics", {})),
                   meta=dict(blob.get("meta", {})), crop=crop)

    def to_blob(self) -> dict[str, Any]:
        return {"format": FORMAT, "kind": self.kind, "class_set": self.class_set.to_dict(),
                "features": self.features.to_dict(), "window": self.window, "last_k": self.last_k,
                "lookahead": self.lookahead, "net": dict(self.net.hparams) if self.net is not None else {},
                "state_dict": self.net.state_dict() if self.net is not None else {},
                "decode": self.decode_params.to_dict(), "physics": self.physics.to_dict(), "meta": self.meta,
                **({"crop": self.crop.to_dict()} if self.crop is not None else {})}

    def save(self, path: str | Path) -> Path:
        """Write the model file atomically."""
        import io

        from inference.clipio import atomic_write_bytes

        buf = io.BytesIO()
        torch.save(self.to_blob(), buf)
        return atomic_write_bytes(Path(path), buf.getvalue())

    # ---------------------------------------------------------------------------------- prediction
    @property
    def ref_fps(self) -> float | None:
        return self.features.ref_fps

    def rally_params(self) -> RallyParams:
        """The sport's rally-segmentation constants, told whether this model times its hits (the taggers)."""
        return replace(RallyParams.for_sport(self.class_set.sport), hits_timed=self.kind == "tagger")

    @property
    def wants_players(self) -> bool:
        """Whether the model reads the players (a player-aware HitNet); it still runs without them."""
        return bool(self.features.poses)

    def ref_probs(self, ball: BallTrack, n_frames: int, fps: float, *, camera=None,
                  players: PlayerTracks | None = None, frames=None) -> np.ndarray:
        """``(T', C)`` per-frame class probabilities at the reference rate (``frames``: crop models)."""
        if self.kind == "physics":
            xy = resample_xy(dense_xy(ball, n_frames), fps, self.ref_fps)
            return physics_probs(xy, self.class_set, self.physics, camera=camera, court=self.court)
        feats = clip_features(ball, n_frames, fps, self.features, camera=camera, court=self.court, players=players)
        if self.kind == "tagger":
            return self.net.probs(torch.from_numpy(feats)).numpy().astype(np.float64)
        if self.kind == "crop":
            from .crop import extract_crops

            if frames is None:
                raise ValueError("this hit-event model is a crop model: it needs the clip's frames — pass "
                                 "frames=clip.frames() to predict(), or use a ball-only model (hitnet_<sport>)")
            xy = resample_xy(dense_xy(ball, n_frames), fps, self.ref_fps)
            crops = extract_crops(frames, xy, fps, self.ref_fps, self.crop, n_frames)
            return window_probs_to_frames(self.net.clip_probs(feats, crops, self.window), len(feats), self.window,
                                          self.last_k, self.lookahead)
        wins = torch.from_numpy(make_windows(feats, self.window))
        win_probs = self.net.probs(wins).numpy().astype(np.float64)
        return window_probs_to_frames(win_probs, len(feats), self.window, self.last_k, self.lookahead)

    def predict(self, ball: BallTrack, fps: float, width: int, height: int, camera=None,
                players: PlayerTracks | None = None, frames=None, *, n_frames: int | None = None,
                keep_all: bool = True, rally: RallyParams | None = None, bridge_gaps: bool = True) -> EventResult:
        """Events of one clip.

        Args:
            ball: the 2D ball (annotated or detected), normalised coordinates.
            fps: the clip's frame rate; width, height: its image size (pixels).
            camera: resolves grouped classes to their surface (else their default label).
            players: ``players.csv`` (read by player-aware models, ``features.poses``; ignored by the others).
            frames: a ``FrameSource`` (needed by crop models, unused by the ball-only ones).
            n_frames: frames in the clip (default: the frame source's length or the track's last frame + 1).
            keep_all: keep the events judged outside the point (warm-up bounces, the ball after it) in
                ``events`` (the default: on detector tracks the segmentation is not reliable yet); False
                leaves them out. Either way ``outside`` lists them.
            rally: segmentation constants (default: the sport's).
            bridge_gaps: time the far player's hits inside the track's gaps from the clean flights on both
                sides (:mod:`.gaps`; on by default: on a real broadcast tracker's tennis points far hits F1
                0.482 → 0.589, at a cost of 0.03–0.04 on simulated ones; docs/events.md, "Contacts in the
                tracker's gaps"). False keeps the models' own timing.
        """
        if not fps or fps <= 0 or not np.isfinite(fps):
            raise ValueError(f"fps must be a positive number, got {fps}")
        if width <= 0 or height <= 0:
            raise ValueError(f"width and height must be positive, got {width}x{height}")
        if self.kind == "crop" and frames is None:
            raise ValueError("this hit-event model is a crop model: it needs the clip's frames — pass "
                             "frames=clip.frames() to predict(), or use a ball-only model (hitnet_<sport>)")
        if n_frames is None:
            n_frames = len(frames) if frames is not None and hasattr(frames, "__len__") else (
                int(ball.frame[-1]) + 1 if len(ball) else 0)
        if self.wants_players and not has_players(players):
            if self.class_set.sport in PLAYERS_OPTIONAL:
                log.info("no players given (players.csv): the player-aware model runs on the ball alone, as it "
                         "was trained to when players are missing (the shipped %s model beats the ball-only one so)",
                         self.class_set.sport)
            else:
                log.warning("this hit-event model reads the players but none were given (players.csv): it runs on "
                            "the ball alone, as it was trained to when players are missing; a ball-only model "
                            "(the default without players) may do better")
        C = self.class_set.n
        if n_frames == 0 or not np.any(ball.visibility > 0):
            warnings.warn("the ball track has no visible ball: no events can be detected", stacklevel=2)
            probs = np.zeros((n_frames, C))
            probs[:, 0] = 1.0
            return EventResult(HitEvents.empty(), probs, self.class_set.classes)
        p_ref = self.ref_probs(ball, n_frames, fps, camera=camera, players=players, frames=frames)
        f_ref, cls = decode(p_ref, self.ref_fps or fps, self.class_set, self.decode_params)
        spread, conf = event_spread(p_ref, f_ref, cls, self.decode_params.peak_radius)
        spread = spread * (fps / self.ref_fps if self.ref_fps else 1.0)  # reference frames → clip frames
        frames_out = np.clip(from_ref_frames(f_ref, fps, self.ref_fps), 0, n_frames - 1)
        xy = dense_xy(ball, n_frames)
        bp = BridgeParams()
        hit = np.isin(cls, [self.class_set.index(h) for h in self.class_set.rules.hits if h in bp.classes])
        bridged, sigma = bridge_events(xy, fps, frames_out, aspect=width / height, params=bp, which=hit) \
            if bridge_gaps else (frames_out, np.full(len(frames_out), np.nan))
        frames_out = bridged  # far hits in a gap: timed from both flights
        sigma = np.where(hit & np.isfinite(sigma), sigma, spread)  # else: the model's own spread
        order = np.argsort(frames_out, kind="stable")
        frames_out, cls, sigma, conf = frames_out[order], cls[order], sigma[order], conf[order]
        events, coarse = self._fine_events(frames_out, cls, ball, n_frames, camera)
        sigma, conf = sigma[:len(events)], conf[:len(events)]
        probs = probs_to_clip(p_ref, n_frames, fps, self.ref_fps)
        hits = self.class_set.rules.hits
        seg = segment_rally(xy, fps, events.frame, events.event, hits=hits, aspect=width / height,
                            params=rally or self.rally_params(),
                            hit_prob=probs[:, [self.class_set.index(h) for h in hits]].sum(axis=1), camera=camera,
                            sides=CourtSides.from_court(self.court) if self.court is not None else None)
        outside = HitEvents(events.frame[~seg.inside], events.event[~seg.inside])
        if not keep_all:
            events = HitEvents(events.frame[seg.inside], events.event[seg.inside])
            coarse = tuple(c for c, k in zip(coarse, seg.inside) if k)
            sigma, conf = sigma[seg.inside], conf[seg.inside]
        quiet = quiet_stretches(events.frame, np.isfinite(xy).all(axis=1), fps)
        return EventResult(events, probs, self.class_set.classes, coarse, seg, outside, sigma, conf, quiet)

    # ------------------------------------------------------------------------------ fine labels
    def _fine_events(self, frames: np.ndarray, cls: np.ndarray, ball: BallTrack, n_frames: int,
                     camera) -> tuple[HitEvents, tuple[str, ...]]:
        names = [self.class_set.classes[c] for c in cls]
        fine = [self.resolve(n, int(f), ball, n_frames, camera) for n, f in zip(names, frames)]
        out_f, out_l, out_c = [], [], []
        for f, label, name in sorted(zip(frames.tolist(), fine, names), key=lambda x: x[0]):
            f = max(f, out_f[-1] + 1) if out_f else f  # two events mapped onto one clip frame
            if f >= n_frames:
                break
            out_f.append(f)
            out_l.append(label)
            out_c.append(name)
        return HitEvents(np.array(out_f, np.int64), np.array(out_l, dtype=str)), tuple(out_c)

    def resolve(self, cls_name: str, frame: int, ball: BallTrack, n_frames: int, camera) -> str:
        """The fine label of a decoded class: a ray/plane test with the camera for grouped classes
        (the first plane of the group the line of sight reaches), else the class's default label."""
        group = self.class_set.resolve_with_camera.get(cls_name)
        if group and camera is not None and self.court is not None:
            xy = dense_xy(ball, n_frames)
            for d in (0, -1, 1, -2, 2):
                k = frame + d
                if 0 <= k < n_frames and np.isfinite(xy[k]).all():
                    from inference.court.geometry import intersect_event

                    o, v = camera.rays_normalized(xy[k][None])
                    hit = intersect_event(o, v, self.court, list(group), offset=self.court.ball.radius)
                    if hit.valid[0]:
                        return str(hit.planes[int(hit.plane_index[0])].event)
                    break
        return self.class_set.fine_label(cls_name)
