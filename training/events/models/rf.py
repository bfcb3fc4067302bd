"""The thesis's random-forest baseline: a scikit-learn forest on flattened windows of the same features,
scored per frame like HitNet (mean of the windows whose last-K block covers the frame)."""
from __future__ import annotations

import numpy as np
import torch
from sklearn.ensemble import RandomForestClassifier

from inference.clipio import BallTrack
from inference.court import load_court
from inference.events.features import FeatureConfig, clip_features, make_windows, window_probs_to_frames

from training.events.data.datamodule import WindowSet
from training.events.synthetic.simulate import SimClip


def window_table(x: np.ndarray) -> np.ndarray:
    """``(N, W, F)`` windows → ``(N, W·F + 2·(W−1))`` rows: the flattened window and its position steps."""
    steps = np.diff(x[:, :, :2], axis=1).reshape(len(x), -1)
    return np.concatenate([x.reshape(len(x), -1), steps], axis=1)


class ForestScorer:
    """A random forest on balanced windows; ``__call__(sim, track)`` gives ``(T', C)`` probabilities."""

    def __init__(self, features: FeatureConfig, n_classes: int, window: int, last_k: int, sport: str,
                 n_estimators: int = 200, max_depth: int | None = 20, max_windows: int = 80_000, seed: int = 0):
        self.features, self.n_classes, self.window, self.last_k = features, n_classes, window, last_k
        self.court = load_court(sport)
        self.forest = RandomForestClassifier(n_estimators=n_estimators, max_depth=max_depth, n_jobs=1,
                                             random_state=seed, min_samples_leaf=2)
        self.max_windows, self.seed = max_windows, seed

    def fit(self, ds: WindowSet) -> ForestScorer:
        y = ds.y.numpy()
        rng = np.random.default_rng(self.seed)
        pos, neg = np.flatnonzero(y > 0), np.flatnonzero(y == 0)
        neg = rng.choice(neg, min(len(neg), len(pos)), replace=False)
        idx = np.concatenate([pos, neg])
        idx = rng.choice(idx, min(len(idx), self.max_windows), replace=False)
        self.forest.fit(window_table(ds.x[torch.as_tensor(idx)].numpy()), y[idx])
        return self

    def __call__(self, sim: SimClip, track: BallTrack) -> np.ndarray:
        feats = clip_features(track, sim.n_frames, sim.fps, self.features, camera=sim.camera, court=self.court)
        wins = make_windows(feats, self.window)
        p = np.zeros((len(wins), self.n_classes))
        p[:, self.forest.classes_] = self.forest.predict_proba(window_table(wins))
        return window_probs_to_frames(p, len(feats), self.window, self.last_k)
