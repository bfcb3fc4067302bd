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

from .degrade import _pair, config_from_dict


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

    def __post_init__(self) -> None:
        for name in ("p_no_players", "p_no_poses", "p_joint_miss", "p_wrist_miss", "p_swap_sides"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"PoseNoiseConfig.{name} must be a probability in [0, 1], got {v!r}")
        if not (isinstance(self.p_flip_lr, (int, float)) and self.p_flip_lr >= 0):
            raise ValueError(f"PoseNoiseConfig.p_flip_lr must be a rate >= 0 per second, got {self.p_flip_lr!r}")
        for name in ("miss_near", "miss_far"):
            a, b = _pair(name, getattr(self, name))
            if b >= 1.0:
                raise ValueError(f"PoseNoiseConfig.{name} must stay below 1 (nothing would be left), got {(a, b)}")
            object.__setattr__(self, name, (a, b))
        for name in ("miss_run_s", "jitter_px", "flip_s", "swap_s", "court_sigma_m"):
            object.__setattr__(self, name, _pair(name, getattr(self, name)))

    @classmethod
    def from_dict(cls, d) -> PoseNoiseConfig:
        return config_from_dict(cls, d, "data.pose_noise")


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


def noisy_players(sim, rng: np.random.Generator, cfg: PoseNoiseConfig = PoseNoiseConfig()) -> PlayerTracks | None:
    """``sim.players`` (exact) as a pose backend and the players stage would give them (None: no players).

    ``sim``: a :class:`~training.events.simulate.SimClip` (``players``, ``fps``, ``width``, ``height``)."""
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
    swap = np.zeros(n_frames, bool)
    if rng.random() < cfg.p_swap_sides:
        a = int(rng.integers(0, n_frames))
        swap[a:a + frames(rng.uniform(*cfg.swap_s))] = True
    for pid in players.ids():
        rows = np.flatnonzero(players.player_id == pid)
        f = players.frame[rows]
        frac = rng.uniform(*(cfg.miss_far if players.team[rows[0]] == "far" else cfg.miss_near))
        missed = _runs(n_frames, frac, run, rng)
        keep[rows[missed[f]]] = False
        flip = np.zeros(n_frames, bool)
        for _ in range(rng.poisson(cfg.p_flip_lr * n_frames / fps)):
            a = int(rng.integers(0, n_frames))
            flip[a:a + frames(rng.uniform(*cfg.flip_s))] = True
        k = kp[rows]
        k[flip[f]] = k[flip[f]][:, _LR]
        k[:, :, :2] += rng.normal(0.0, sigma, (len(rows), 17, 2)) / size
        lost = rng.random((len(rows), 17)) < cfg.p_joint_miss
        lost[:, _WRISTS] |= rng.random((len(rows), 2)) < cfg.p_wrist_miss
        k[lost] = np.nan
        kp[rows] = k
        court[rows] += rng.normal(0.0, court_sigma, (len(rows), 2))
        s = swap[f]
        team[rows[s]] = np.where(team[rows[s]] == "near", "far", np.where(team[rows[s]] == "far", "near", ""))
    if no_poses:
        kp[:] = np.nan
    return PlayerTracks(players.frame[keep], players.player_id[keep], list(team[keep]), players.score[keep],
                        players.bbox[keep], kp[keep], court[keep])


def noisy_all(clips, seed: int, cfg: PoseNoiseConfig) -> list[PlayerTracks | None]:
    """Noisy players of many clips; the same seed gives the same players."""
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(len(clips))]
    return [noisy_players(c, r, cfg) for c, r in zip(clips, rngs)]
