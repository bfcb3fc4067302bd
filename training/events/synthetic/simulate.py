"""Training data for the ball-only event models without rendering: simulated rallies seen through
random cameras, as the clip files would hold them (per-frame 2D ball, visibility, fine-grained events).

Each rally draws its camera exactly like ``rally3d synth`` (preset randomised: position, resolution,
fps, distortion) and its rally from the same simulator, so the 2D tracks have the distribution of the
rendered clips. A held-out set is a different seed. ``perturb`` makes a track look like a detector's
output (misses, jitter, false positives) for end-to-end figures.

Example:
    >>> clips = simulate_clips("padel", 100, seed=1)
    >>> clips[0].ball, clips[0].events, clips[0].fps
"""
from __future__ import annotations

import hashlib
import json
import logging
import pickle
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from inference.camera import Camera
from inference.clipio import BallTrack, HitEvents, PlayerTracks, private_temp_path
from inference.court import load_court
from inference.players.skeleton import COCO17
from synth.cameras import CameraSpec
from synth.generate import DEFAULT_CAMERA
from synth.groundtruth import event_table, inside_image
from synth.rally import REAL_AROUND, default_config, simulate_rally

from training.events.data.parallel import can_fork, map_clips

log = logging.getLogger(__name__)

SIM_VERSION = 3  # in the cache key: raise it when the simulated rallies change


@dataclass
class SimClip:
    """One simulated clip: ``ball`` (every frame a row), ``events`` (fine labels), ``fps``, image size,
    ``camera`` (ground truth) and ``name``; ``rally``: (serve frame, dead-ball frame) when known;
    ``players``: the players as ``players.csv`` would hold them (exact 2D keypoints), when simulated."""

    name: str
    fps: float
    width: int
    height: int
    n_frames: int
    ball: BallTrack
    events: HitEvents
    camera: Camera
    rally: tuple[int, int] | None = None
    players: PlayerTracks | None = None


def project_players(poses, camera: Camera) -> PlayerTracks:
    """The articulated players (:func:`synth.bodies.articulate`) seen by ``camera``, as
    ``gt/players.csv`` holds them: normalised 2D keypoints (score 1 inside the image and in front of the
    camera, else missing), boxes of the projected joints, court position under the ankles' midpoint, team."""
    size = np.asarray(camera.image_size, float)
    ankles = [COCO17.index("left_ankle"), COCO17.index("right_ankle")]
    cols = {k: [] for k in ("frame", "pid", "team", "bbox", "kp", "court")}
    for pose in poses:
        n = pose.n_frames
        j = pose.joints.reshape(-1, 3)
        uv = (camera.project(j) / size).reshape(n, 17, 2)
        ok = (camera.depth(j) > 0.1).reshape(n, 17) & (uv >= 0).all(axis=2) & (uv <= 1).all(axis=2)
        uv[~ok] = np.nan
        lo, hi = np.nanmin(np.where(ok[..., None], uv, np.inf), axis=1), np.nanmax(np.where(ok[..., None], uv, -np.inf), axis=1)
        box = np.concatenate([lo, hi], axis=1)
        box[~ok.any(axis=1)] = np.nan
        cols["frame"].append(np.arange(n))
        cols["pid"].append(np.full(n, pose.player_id))
        cols["team"] += [pose.team] * n
        cols["bbox"].append(box)
        cols["kp"].append(np.concatenate([uv, np.where(ok, 1.0, np.nan)[..., None]], axis=2))
        cols["court"].append(pose.joints[:, ankles, :2].mean(axis=1))
    frame = np.concatenate(cols["frame"])
    order = np.lexsort((np.concatenate(cols["pid"]), frame))
    cat = lambda k: np.concatenate(cols[k])[order]  # noqa: E731
    return PlayerTracks(frame[order], cat("pid"), [cols["team"][i] for i in order], np.ones(len(frame)),
                        cat("bbox"), cat("kp"), cat("court"))


def project_track(rally, camera: Camera) -> BallTrack:
    """The ball of every frame projected by ``camera``: visibility 1 inside the image, 0 elsewhere or
    while the ball does not exist yet (the 2D labels of a rendered clip, without player occlusion)."""
    n = rally.n_frames
    t = rally.frame_times
    vis = np.zeros(n, np.int8)
    xy = np.full((n, 2), np.nan)
    live = (t >= rally.ball.t[0]) & (t <= rally.ball.t[-1])
    if live.any():
        X = rally.ball.sample(t[live])
        px = camera.project(X)
        front = camera.depth(X) > 0.1
        ok = inside_image(px, camera.image_size) & front
        idx = np.flatnonzero(live)[ok]
        vis[idx] = 1
        xy[idx] = px[ok] / np.asarray(camera.image_size, float)
    return BallTrack(np.arange(n), vis, np.clip(xy, 0, 1))


def simulate_clip(sport: str, seed: int, court=None, around: bool = False, fps: float | None = None,
                  players: bool = False, camera: str | None = None, pace: str = "club") -> SimClip:
    """One rally with a randomised camera; the same seed gives the same clip. ``around``: add the
    server's bounces before the serve and the ball after the point (not events; ``rally`` marks the
    point); ``fps``: fix the frame rate; ``players``: articulate the players (they swing at their hits)
    and keep their exact 2D poses in ``SimClip.players`` (own random stream: the rest is unchanged);
    ``camera``: the camera preset (default the sport's, :data:`DEFAULT_CAMERA`; ``padel_broadcast`` for
    the broadcast view, whose picture high lobs leave through the top); ``pace``: ``club`` (default) or
    ``tour`` (tennis at a men's final's pace, :data:`synth.rally.TENNIS_TOUR`)."""
    court = court or load_court(sport)
    r_cam, r_rally = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    spec = CameraSpec.preset(camera or DEFAULT_CAMERA[sport]).randomised(r_cam)
    if fps is not None:
        spec = replace(spec, fps=float(fps))
    camera = spec.build(court)
    config = default_config(sport, pace)
    if around:
        config = replace(config, around=REAL_AROUND)
    rally = simulate_rally(court, spec.fps, r_rally, sport=sport, config=config)
    tracks = None
    if players:
        from synth.bodies import articulate

        r_body = np.random.default_rng([seed, 31])
        tracks = project_players([articulate(p, spec.fps, r_body, sport=sport) for p in rally.players], camera)
    return SimClip(f"{sport}_{seed}", spec.fps, spec.width, spec.height, rally.n_frames,
                   project_track(rally, camera), event_table(rally), camera, rally.rally_frames(), tracks)


def simulate_clips(sport: str, n: int, seed: int, cache_dir: str | Path | None = None,
                   progress: bool = True, around: bool = False, fps: float | None = None,
                   players: bool = False, workers: int = 0, camera: str | None = None,
                   pace: str = "club") -> list[SimClip]:
    """``n`` clips with seeds ``seed * 1_000_003 + k``; cached as a pickle under ``cache_dir``
    (``around``, ``fps``, ``players``, ``camera``, ``pace``: see :func:`simulate_clip`); ``workers > 1``:
    simulated in that many forked processes (the same clips, :mod:`.parallel`)."""
    if n <= 0:
        raise ValueError(f"need at least one clip, got n={n}")
    default_config(sport, pace)  # an unknown pace fails here, before any work
    cache = None
    if cache_dir is not None:
        parts = [sport, n, seed, SIM_VERSION] + ([around, fps] if around or fps else []) \
            + (["players"] if players else []) + ([camera] if camera else []) + ([pace] if pace != "club" else [])
        key = hashlib.sha1(json.dumps(parts).encode()).hexdigest()[:10]
        cache = Path(cache_dir) / f"sim_{sport}_{n}_{seed}_{key}.pkl"
        if cache.is_file():
            try:
                with open(cache, "rb") as fh:
                    return pickle.load(fh)
            except (ModuleNotFoundError, AttributeError, EOFError, pickle.UnpicklingError) as e:
                # written by another version of the code (a class since moved) or cut short: simulate again
                log.info("cache %s cannot be read (%s: %s): simulating again", cache, type(e).__name__, e)
    court = load_court(sport)

    def one(k: int) -> SimClip:
        return simulate_clip(sport, seed * 1_000_003 + k, court, around, fps, players, camera, pace)

    if workers and workers > 1 and can_fork():
        log.info("simulating %d %s rallies in %d processes", n, sport, workers)
        clips = map_clips(one, n, workers)
    else:
        clips = [one(k) for k in tqdm(range(n), desc=f"simulating {sport} rallies", disable=not progress)]
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = private_temp_path(cache)  # DDP ranks may simulate the same set at once
        try:
            with open(tmp, "wb") as fh:
                pickle.dump(clips, fh)
            tmp.replace(cache)
        finally:
            tmp.unlink(missing_ok=True)
    return clips


@dataclass(frozen=True)
class DetectorNoise:
    """How a ball detector's output differs from the annotation.

    Attributes:
        jitter_px: Gaussian position noise (pixels, per axis).
        p_miss: independent missed frames; bursts: mean number of miss bursts per second,
            burst_len: their length range (frames).
        p_false: frames whose position is replaced by a false positive (a reflection or a random spot).
    """

    jitter_px: float = 1.5
    p_miss: float = 0.05
    bursts: float = 0.3
    burst_len: tuple[int, int] = (3, 12)
    p_false: float = 0.02


def every_frame(track: BallTrack, n_frames: int) -> BallTrack:
    """``track`` with one row per frame ``0..n_frames-1``: frames without a row (a real tracker's missing
    rows, an annotator's gaps) become visibility 0. Rows at or past ``n_frames`` are dropped."""
    if len(track) == n_frames and np.array_equal(track.frame, np.arange(n_frames)):
        return track
    keep = track.frame < n_frames
    dense = BallTrack(track.frame[keep], track.visibility[keep], track.xy[keep]).dense(n_frames)
    vis = np.where(dense.labelled, dense.visibility, 0).astype(np.int8)
    xy = np.where((vis > 0)[:, None], dense.xy, np.nan)
    return BallTrack(np.arange(n_frames), vis, xy)


def perturb(clip: SimClip, rng: np.random.Generator, noise: DetectorNoise = DetectorNoise()) -> BallTrack:
    """The clip's ball track as a detector might return it (one row per frame; missing rows count as
    not seen)."""
    n = clip.n_frames
    ball = every_frame(clip.ball, n)
    vis = ball.visibility.copy()
    xy = ball.xy.copy()
    size = np.array([clip.width, clip.height], float)
    seen = vis > 0
    xy[seen] += rng.normal(0, noise.jitter_px, (seen.sum(), 2)) / size
    miss = rng.random(n) < noise.p_miss
    for _ in range(rng.poisson(noise.bursts * n / clip.fps)):
        a = int(rng.integers(0, n))
        miss[a:a + int(rng.integers(noise.burst_len[0], noise.burst_len[1] + 1))] = True
    false = rng.random(n) < noise.p_false
    for i in np.flatnonzero(false):
        if seen[i] and rng.random() < 0.5:  # a reflection: mirrored about a nearby vertical line
            xy[i] = [xy[i, 0], min(1.0, xy[i, 1] + rng.uniform(0.02, 0.15))]
        else:
            xy[i] = rng.uniform(0.05, 0.95, 2)
        vis[i] = 1
    vis[miss & ~false] = 0
    xy[vis == 0] = np.nan
    return BallTrack(ball.frame, vis, np.clip(xy, 0, 1))
