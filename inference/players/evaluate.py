"""Evaluating the player pipeline against ground truth (gt/players.csv of synthetic clips).

:func:`simulate_detections` turns the true 2D keypoints into what a pose model would give: keypoint
noise, dropped detections (single frames and runs), spurious people off court (spectators, an umpire)
and people walking on court briefly (a ball kid); the result goes through the importer path as MMPose
JSON. :func:`score` matches the pipeline's players to the true ones frame by frame and counts identity
switches and court-position errors.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from inference.clipio import PlayerTracks

from .types import J, Persons, PoseSequence


@dataclass(frozen=True)
class DetectionNoise:
    """How far simulated detections are from the truth."""

    keypoint_px: float = 3.0        # σ of Gaussian keypoint noise
    drop_prob: float = 0.05         # a person missing in a frame
    drop_run_prob: float = 0.01     # a run of missed frames starts (occlusion)
    drop_run_frames: int = 12
    spectators: int = 3             # people standing off court
    score_noise: float = 0.15


def simulate_detections(gt: PlayerTracks, n_frames: int, image_size: tuple[int, int], rng: np.random.Generator,
                        noise: DetectionNoise = DetectionNoise()) -> PoseSequence:
    """A :class:`PoseSequence` of noisy detections of the true players plus spurious people."""
    wh = np.asarray(image_size, float)
    frames: list[list] = [[] for _ in range(n_frames)]
    for pid in gt.ids():
        rows = gt.of_player(pid)
        missing_until = -1
        for k, f in enumerate(rows.frame.tolist()):
            if f >= n_frames:
                continue
            if f <= missing_until or rng.random() < noise.drop_prob:
                continue
            if rng.random() < noise.drop_run_prob:
                missing_until = f + noise.drop_run_frames
            kp = rows.keypoints[k, :, :2] * wh + rng.normal(0, noise.keypoint_px, (J, 2))
            vis = rows.keypoints[k, :, 2]
            sc = np.clip(np.where(vis > 0, 0.9, 0.0) - rng.uniform(0, noise.score_noise, J), 0, 1)
            kp[vis <= 0] = np.nan
            if np.isfinite(kp).all(axis=1).sum() < 4:
                continue
            frames[f].append((kp, sc, float(np.clip(0.9 - rng.uniform(0, noise.score_noise), 0, 1))))
    _add_spectators(frames, gt, wh, rng, noise)
    out = []
    for people in frames:
        if not people:
            out.append(Persons.empty())
            continue
        kp = np.stack([p[0] for p in people])
        out.append(Persons(np.full((len(people), 4), np.nan), kp, np.stack([p[1] for p in people]),
                           np.array([p[2] for p in people])))
    return PoseSequence(out, "simulated")


def _add_spectators(frames: list[list], gt: PlayerTracks, wh: np.ndarray, rng: np.random.Generator,
                    noise: DetectionNoise) -> None:
    """Copies of a true player's pose shifted to fixed places at the image sides (standing still)."""
    if not len(gt):
        return
    template = gt.keypoints[0, :, :2] * wh
    template = template - np.nanmean(template, axis=0)
    for s in range(noise.spectators):
        anchor = np.array([rng.uniform(0.02, 0.12) if s % 2 == 0 else rng.uniform(0.88, 0.98),
                           rng.uniform(0.3, 0.9)]) * wh
        scale = rng.uniform(0.5, 1.0)
        for people in frames:
            kp = anchor + scale * template + rng.normal(0, 1.0, (J, 2))
            people.append((kp, np.full(J, 0.8), 0.8))


def match_frames(pred: PlayerTracks, gt: PlayerTracks, max_dist: float = 1.5) -> dict[int, list[tuple[int, int]]]:
    """Per frame, the (gt id, predicted id) pairs matched by court position (Hungarian, ≤ max_dist m)."""
    out: dict[int, list[tuple[int, int]]] = {}
    for f in np.intersect1d(np.unique(pred.frame), np.unique(gt.frame)):
        g = np.flatnonzero(gt.frame == f)
        p = np.flatnonzero((pred.frame == f) & np.isfinite(pred.court_xy).all(axis=1))
        if not len(g) or not len(p):
            continue
        cost = np.linalg.norm(gt.court_xy[g][:, None] - pred.court_xy[p][None], axis=2)
        r, c = linear_sum_assignment(cost)
        out[int(f)] = [(int(gt.player_id[g[i]]), int(pred.player_id[p[j]])) for i, j in zip(r, c)
                       if cost[i, j] <= max_dist]
    return out


@dataclass
class PlayerScores:
    """Identity switches per player per minute, court-position errors (m), coverage of the true rows."""

    switches_per_player_minute: float
    switches: int
    median_error_m: float
    mean_error_m: float
    p90_error_m: float
    coverage: float


def score(pred: PlayerTracks, gt: PlayerTracks, fps: float) -> PlayerScores:
    """Compare the pipeline's players with the truth (see :func:`match_frames`)."""
    matches = match_frames(pred, gt)
    last: dict[int, int] = {}
    switches = 0
    errors = []
    pred_pos = {(int(f), int(i)): xy for f, i, xy in zip(pred.frame, pred.player_id, pred.court_xy)}
    gt_pos = {(int(f), int(i)): xy for f, i, xy in zip(gt.frame, gt.player_id, gt.court_xy)}
    for f in sorted(matches):
        for g, p in matches[f]:
            if g in last and last[g] != p:
                switches += 1
            last[g] = p
            errors.append(float(np.linalg.norm(pred_pos[(f, p)] - gt_pos[(f, g)])))
    minutes = len(np.unique(gt.frame)) / fps / 60.0
    n_players = max(len(gt.ids()), 1)
    e = np.array(errors) if errors else np.array([np.nan])
    return PlayerScores(switches / n_players / max(minutes, 1e-9), switches, float(np.median(e)), float(np.mean(e)),
                        float(np.percentile(e, 90)), len(errors) / max(len(gt), 1))
