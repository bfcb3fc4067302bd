"""Pose-estimator noise for the player-aware hit-event models: make exact simulated players (or ground-truth
``players.csv``) look like what a pose backend and the players stage write on broadcast video.

What real pose tracks show (MoveNet on the generator's rendered clips finds 77 % of the padel and 60 % of
the tennis player-frames, the far players least: docs/players.md): whole players missed for runs of
frames, the far side more often; per-joint jitter of a few pixels and single joints lost (wrists most:
small, fast, blurred); left and right confused for a few frames; now and then the near and far players
swapped (a tracking or team error); court positions off by 0.1–0.3 m; clips without any players (no
pose backend, ``--pose none``) or with positions only (a foreign ``players.csv``). :func:`noisy_players`
applies these with the probabilities of :class:`PoseNoiseConfig`; lengths are in seconds.

Example:
    >>> cfg = PoseNoiseConfig()
    >>> noisy = noisy_players(sim_clip, np.random.default_rng(0), cfg)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import PlayerTracks

from training.events.synthetic.degrade import _pair, config_from_dict
from training.events.data.parallel import clip_rngs, map_clips


@dataclass(frozen=True)
class PoseNoiseConfig:
    """Parameters of :func:`noisy_players` (``enabled: false`` keeps the players exact).

    Attributes:
        p_no_players: probability that a clip has no players at all.
        p_no_poses: probability that a clip's players have positions but no keypoints.
        miss_near, miss_far: [min, max] of the per-clip fraction of a near / far player's frames missed,
            in runs of ``miss_run_s`` seconds.
        jitter_px: [min, max] of the per-clip keypoint σ (pixels of the clip's frame).
        p_joint_miss, p_wrist_miss: probability that a single joint / a wrist is missing in a frame.
        p_flip_lr: per second, the rate of runs (``flip_s`` long) where left and right joints are swapped.
        p_swap_sides: probability that a clip has one run (``swap_s`` long) with the near and far
            players' teams swapped.
        court_sigma_m: [min, max] of the per-clip court-position σ (metres).
        p_flip_lr_far: the flip rate of far players (None: ``p_flip_lr``; seen from behind, the near
            players' left and right are confused more often).
        drop_near, drop_far: [min, max] of the per-clip fraction of frames dropped in short runs of
            ``drop_run_s`` seconds (single missed detections, which the players stage bridges).
        fill_gap_s: gaps up to this long are filled by linear interpolation at half the score, as the
            players stage does (``TrackingConfig.max_gap_s``); 0 leaves them empty.
        bias_rel: [min, max] of the per-clip σ of a slowly drifting offset of every joint, as a fraction
            of the player's image height (a pose model's joints sit a little off the true ones, for
            seconds); the wrists' σ is ``wrist_bias_scale`` times that; ``bias_s``: its time constant.
        wrist_outlier_near, wrist_outlier_far: fraction of a wrist's frames placed on something else (the
            racket, the other arm, the background), in runs of ``wrist_outlier_s`` seconds, moved by
            ``wrist_outlier_rel`` × the player's height in one direction per run.

    ``conf/data/pose_noise/movenet_measured.yaml`` holds these as measured for MoveNet and the players
    stage on rendered clips (``bench/bench_pose_stats.py``); the new kinds default to off.
    """

    enabled: bool = True
    p_no_players: float = 0.1
    p_no_poses: float = 0.1
    miss_near: tuple[float, float] = (0.02, 0.25)
    miss_far: tuple[float, float] = (0.05, 0.5)
    miss_run_s: tuple[float, float] = (0.04, 0.6)
    jitter_px: tuple[float, float] = (1.0, 5.0)
    p_joint_miss: float = 0.05
    p_wrist_miss: float = 0.15
    p_flip_lr: float = 0.2
    flip_s: tuple[float, float] = (0.04, 0.3)
    p_swap_sides: float = 0.05
    swap_s: tuple[float, float] = (0.2, 1.5)
    court_sigma_m: tuple[float, float] = (0.05, 0.3)
    p_flip_lr_far: float | None = None
    drop_near: tuple[float, float] = (0.0, 0.0)
    drop_far: tuple[float, float] = (0.0, 0.0)
    drop_run_s: tuple[float, float] = (0.02, 0.3)
    fill_gap_s: float = 0.0
    bias_rel: tuple[float, float] = (0.0, 0.0)
    wrist_bias_scale: float = 2.0
    bias_s: float = 1.0
    wrist_outlier_near: float = 0.0
    wrist_outlier_far: float = 0.0
    wrist_outlier_s: tuple[float, float] = (0.02, 0.25)
    wrist_outlier_rel: tuple[float, float] = (0.25, 0.6)

    def __post_init__(self) -> None:
        for name in ("p_no_players", "p_no_poses", "p_joint_miss", "p_wrist_miss", "p_swap_sides",
                     "wrist_outlier_near", "wrist_outlier_far"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"PoseNoiseConfig.{name} must be a probability in [0, 1], got {v!r}")
        for name in ("p_flip_lr", "p_flip_lr_far", "fill_gap_s", "wrist_bias_scale"):
            v = getattr(self, name)
            if v is None and name == "p_flip_lr_far":
                continue
            if not (isinstance(v, (int, float)) and v >= 0):
                raise ValueError(f"PoseNoiseConfig.{name} must be a number >= 0, got {v!r}")
        if not (isinstance(self.bias_s, (int, float)) and self.bias_s > 0):
            raise ValueError(f"PoseNoiseConfig.bias_s must be a time > 0 in seconds, got {self.bias_s!r}")
        for name in ("miss_near", "miss_far", "drop_near", "drop_far"):
            a, b = _pair(name, getattr(self, name))
            if b >= 1.0:
                raise ValueError(f"PoseNoiseConfig.{name} must stay below 1 (nothing would be left), got {(a, b)}")
            object.__setattr__(self, name, (a, b))
        for name in ("miss_run_s", "jitter_px", "flip_s", "swap_s", "court_sigma_m", "drop_run_s", "bias_rel",
                     "wrist_outlier_s", "wrist_outlier_rel"):
            object.__setattr__(self, name, _pair(name, getattr(self, name)))

    @classmethod
    def from_dict(cls, d) -> PoseNoiseConfig:
        if d is not None and not isinstance(d, cls):
            # "measured": the figures a measured setting was derived from (bench_pose_stats.py)
            d = {k: v for k, v in dict(d).items() if k != "measured"}
        return config_from_dict(cls, d, "data.pose_noise")

    @classmethod
    def from_file(cls, path) -> PoseNoiseConfig:
        """Settings from a YAML file such as ``conf/data/pose_noise/movenet_measured.yaml``."""
        import yaml
        from pathlib import Path

        return cls.from_dict(yaml.safe_load(Path(path).read_text()))


_LR = np.array([0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15])  # COCO-17 left ↔ right
_WRISTS = [9, 10]


def _runs(n: int, frac: float, run: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """``(n,)`` mask of runs (lengths in ``run`` frames) covering about ``frac`` of the frames."""
    mask = np.zeros(n, bool)
    target = int(round(frac * n))
    tries = 0
    while mask.sum() < target and tries < 1000:
        tries += 1
        a = int(rng.integers(0, n))
        mask[a:a + int(rng.integers(run[0], run[1] + 1))] = True
    return mask


def _drift(n: int, shape: tuple[int, ...], fps: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """``(n, *shape)`` unit-variance AR(1) noise with time constant ``tau_s`` (stationary from frame 0)."""
    from scipy.signal import lfilter

    rho = float(np.exp(-1.0 / max(tau_s * fps, 1e-6)))
    k = np.sqrt(1.0 - rho * rho)
    e = rng.normal(0.0, 1.0, (n,) + shape)
    e[0] /= k                                  # y[0] = e[0]: the stationary distribution from the start
    return lfilter([k], [1.0, -rho], e, axis=0)


def _heights_px(kp: np.ndarray, size: np.ndarray) -> np.ndarray:
    """``(n,)`` image height (px) of each row's skeleton: the y-span of its joints (NaN if < 2 joints)."""
    y = kp[:, :, 1] * size[1]
    ok = np.isfinite(y).sum(axis=1) >= 2
    h = np.full(len(kp), np.nan)
    h[ok] = np.nanmax(y[ok], axis=1) - np.nanmin(y[ok], axis=1)
    return h


def _outlier_shift(n_frames: int, f: np.ndarray, height: np.ndarray, frac: float, run: tuple[int, int],
                   rel: tuple[float, float], rng: np.random.Generator) -> np.ndarray:
    """``(len(f), 2)`` pixel shifts of one joint placed on something else: runs (``run`` frames) covering
    about ``frac`` of the clip's ``n_frames``, each moved ``rel`` × the player's ``height`` (px, per row) in
    one direction; zero outside the runs. ``f``: the rows' frames."""
    wrong = _runs(n_frames, frac, run, rng)
    starts = np.flatnonzero(np.diff(np.r_[0, wrong.astype(np.int8)]) == 1)
    run_id = np.cumsum(np.isin(np.arange(n_frames), starts)) - 1
    ang = rng.uniform(0.0, 2 * np.pi, max(len(starts), 1))
    mag = rng.uniform(*rel, max(len(starts), 1))
    shift = np.zeros((len(f), 2))
    sel = wrong[f]
    r = run_id[f][sel]
    shift[sel] = np.stack([np.cos(ang[r]), np.sin(ang[r])], axis=1) * (mag[r] * height[sel])[:, None]
    return shift


def _fill_gaps(p: PlayerTracks, fps: float, max_gap_s: float) -> PlayerTracks:
    """Each player's gaps up to ``max_gap_s`` filled by linear interpolation, as the players stage does
    (:func:`inference.players.tracking.interpolate`: every per-frame array, interpolated rows at half score)."""
    from inference.players.tracking import Track, TrackingConfig, interpolate

    cfg = TrackingConfig(max_gap_s=max_gap_s)
    parts = []
    for pid in p.ids():
        rows = np.flatnonzero(p.player_id == pid)
        t = Track(p.frame[rows], p.bbox[rows], p.keypoints[rows, :, :2], p.keypoints[rows, :, 2], p.score[rows],
                  p.court_xy[rows])
        t = interpolate(t, fps, cfg) if len(rows) > 1 else t
        src = np.searchsorted(p.frame[rows], t.frames, side="right") - 1   # team of the last kept row
        parts.append((t, np.full(len(t.frames), pid), p.team[rows][np.clip(src, 0, len(rows) - 1)]))
    if not parts:
        return p
    frame = np.concatenate([t.frames for t, _, _ in parts]).astype(np.int64)
    order = np.lexsort((np.concatenate([i for _, i, _ in parts]), frame))
    cat = lambda get: np.concatenate([get(t) for t, _, _ in parts])[order]  # noqa: E731
    kp = np.concatenate([cat(lambda t: t.keypoints), cat(lambda t: t.kp_scores)[..., None]], axis=2)
    return PlayerTracks(frame[order], np.concatenate([i for _, i, _ in parts])[order],
                        list(np.concatenate([tm for _, _, tm in parts])[order]), cat(lambda t: t.scores),
                        cat(lambda t: t.boxes), kp, cat(lambda t: t.court))


def noisy_players(sim, rng: np.random.Generator, cfg: PoseNoiseConfig = PoseNoiseConfig()) -> PlayerTracks | None:
    """``sim.players`` (exact) as a pose backend and the players stage would give them (None: no players).

    ``sim``: a :class:`~training.events.synthetic.simulate.SimClip` (``players``, ``fps``, ``width``, ``height``).
    The kinds that default to off draw random numbers only when on, so older settings give the same players."""
    players = sim.players
    if players is None or len(players) == 0:
        return players
    if not cfg.enabled:
        return players
    if rng.random() < cfg.p_no_players:
        return None
    fps = float(sim.fps)
    frames = lambda s: max(1, int(round(s * fps)))  # noqa: E731
    run = (frames(cfg.miss_run_s[0]), frames(cfg.miss_run_s[1]))
    n_frames = int(players.frame.max()) + 1
    keep = np.ones(len(players), bool)
    kp = players.keypoints.copy()
    court = players.court_xy.copy()
    team = players.team.astype(object).copy()
    size = np.array([sim.width, sim.height], float)
    no_poses = rng.random() < cfg.p_no_poses
    sigma = rng.uniform(*cfg.jitter_px)
    court_sigma = rng.uniform(*cfg.court_sigma_m)
    bias = rng.uniform(*cfg.bias_rel) if cfg.bias_rel[1] > 0 else 0.0
    swap = np.zeros(n_frames, bool)
    if rng.random() < cfg.p_swap_sides:
        a = int(rng.integers(0, n_frames))
        swap[a:a + frames(rng.uniform(*cfg.swap_s))] = True
    for pid in players.ids():
        rows = np.flatnonzero(players.player_id == pid)
        f = players.frame[rows]
        far = players.team[rows[0]] == "far"
        frac = rng.uniform(*(cfg.miss_far if far else cfg.miss_near))
        missed = _runs(n_frames, frac, run, rng)
        drop = cfg.drop_far if far else cfg.drop_near
        if drop[1] > 0:
            missed |= _runs(n_frames, rng.uniform(*drop), (frames(cfg.drop_run_s[0]), frames(cfg.drop_run_s[1])), rng)
        keep[rows[missed[f]]] = False
        flip = np.zeros(n_frames, bool)
        rate = cfg.p_flip_lr_far if far and cfg.p_flip_lr_far is not None else cfg.p_flip_lr
        for _ in range(rng.poisson(rate * n_frames / fps)):
            a = int(rng.integers(0, n_frames))
            flip[a:a + frames(rng.uniform(*cfg.flip_s))] = True
        k = kp[rows]
        height = _heights_px(k, size)
        height = np.where(np.isfinite(height), height, np.nanmedian(height) if np.isfinite(height).any() else 0.0)
        k[flip[f]] = k[flip[f]][:, _LR]
        if bias > 0:
            scale = np.ones(17)
            scale[_WRISTS] = cfg.wrist_bias_scale
            drift = _drift(n_frames, (17, 2), fps, cfg.bias_s, rng)[f]
            k[:, :, :2] += drift * (bias * height)[:, None, None] * scale[None, :, None] / size
        k[:, :, :2] += rng.normal(0.0, sigma, (len(rows), 17, 2)) / size
        p_out = cfg.wrist_outlier_far if far else cfg.wrist_outlier_near
        if p_out > 0:
            out_run = (frames(cfg.wrist_outlier_s[0]), frames(cfg.wrist_outlier_s[1]))
            for j in _WRISTS:
                k[:, j, :2] += _outlier_shift(n_frames, f, height, p_out, out_run, cfg.wrist_outlier_rel, rng) / size
        lost = rng.random((len(rows), 17)) < cfg.p_joint_miss
        lost[:, _WRISTS] |= rng.random((len(rows), 2)) < cfg.p_wrist_miss
        k[lost] = np.nan
        kp[rows] = k
        court[rows] += rng.normal(0.0, court_sigma, (len(rows), 2))
        s = swap[f]
        team[rows[s]] = np.where(team[rows[s]] == "near", "far", np.where(team[rows[s]] == "far", "near", ""))
    if no_poses:
        kp[:] = np.nan
    out = PlayerTracks(players.frame[keep], players.player_id[keep], list(team[keep]), players.score[keep],
                       players.bbox[keep], kp[keep], court[keep])
    return _fill_gaps(out, fps, cfg.fill_gap_s) if cfg.fill_gap_s > 0 and len(out) else out


def noisy_all(clips, seed: int, cfg: PoseNoiseConfig, workers: int = 0) -> list[PlayerTracks | None]:
    """Noisy players of many clips; the same seed gives the same players (``workers``: forked processes,
    :func:`~training.events.data.parallel.map_clips`)."""
    rngs = clip_rngs(seed, len(clips))
    return map_clips(lambda k: noisy_players(clips[k], rngs[k], cfg), len(clips), workers)
