"""What the project's own ball detector does to a track: statistics of a detected ``ball.csv`` against the
clip's ground truth, and the degradation settings (:class:`~training.events.synthetic.degrade.DegradeConfig`) that
reproduce them.

Measured per frame where the true ball is in the image: a *hit* is a detection within ``tau_px`` (pixels
at 1280 px width, scaled to the clip) of the truth, a *miss* is any other frame, a *false* detection one
that is farther than ``tau_px`` or where no ball is in the image. Reported: the miss rate by the ball's
image diameter (``2 r f / depth``) and by its distance from the camera, near the contacts (within
``contact_s`` of a near hit, a far hit, another event) and away from them; the lengths of the runs of
misses (the gaps, seconds); the false-detection rate and how far those lie from the ball; the jitter of
the hits (robust σ per axis, px) and whether positions are whole pixels.

Example:
    >>> stats = measure_clips([(clip, detected_track)])
    >>> degrade_settings(stats)        # → data.degrade fields
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.clipio import BallTrack, HitEvents

SIZE_BINS_PX = (0.0, 4.0, 6.0, 9.0, 14.0, np.inf)
DIST_BINS_M = (0.0, 10.0, 15.0, 20.0, 30.0, np.inf)
QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)


@dataclass
class ClipTruth:
    """What the statistics need of one clip: the true 2D ball (every frame a row), its image diameter and
    distance from the camera per frame (NaN where unknown), the true events, frame size and rate."""

    name: str
    fps: float
    width: int
    height: int
    ball: BallTrack
    diameter_px: np.ndarray
    distance_m: np.ndarray
    events: HitEvents

    @classmethod
    def from_clip(cls, clip) -> ClipTruth:
        """From a clip folder with ground truth (``rally3d synth``: ``ball.csv`` is the true 2D ball,
        ``gt/ball_3d.csv``, ``gt/camera.yaml``, ``gt/events.csv``)."""
        info = clip.info
        n = clip.n_frames
        ball = clip.read_ball().dense(n)
        cam = clip.read_camera(gt=True)
        b3 = clip.read_ball_3d(gt=True)
        diameter, distance = np.full(n, np.nan), np.full(n, np.nan)
        ok = b3.frame < n
        X = b3.xyz[ok]
        if len(X):
            depth = cam.depth(X)
            radius = _ball_radius(info.sport)
            diameter[b3.frame[ok]] = 2.0 * radius * float(cam.K[0, 0]) / np.maximum(depth, 1e-6)
            distance[b3.frame[ok]] = np.linalg.norm(X - np.asarray(cam.centre, float), axis=1)
        return cls(clip.root.name, float(info.fps), int(info.width), int(info.height), ball, diameter, distance,
                   clip.read_events(gt=True, missing_ok=True))


def _ball_radius(sport: str | None) -> float:
    from inference.court import load_court

    try:
        return float(load_court(sport).ball.radius)
    except Exception:  # noqa: BLE001 — an unknown sport: a tennis/padel ball
        return 0.033


def run_lengths(mask: np.ndarray) -> list[int]:
    """Lengths of the runs of True in ``mask``."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)).tolist()


def frame_outcomes(truth: ClipTruth, detected: BallTrack, tau_px: float = 10.0) -> dict[str, np.ndarray]:
    """Per frame: ``visible`` (the true ball is in the image), ``hit``, ``miss``, ``false`` and ``err_px``
    (distance of the detection from the truth, NaN where either is missing)."""
    n = len(truth.ball.xy)
    det = detected.dense(n)
    size = np.array([truth.width, truth.height], float)
    tau = tau_px * truth.width / 1280.0
    vis = (truth.ball.visibility > 0) & np.isfinite(truth.ball.xy).all(axis=1)
    seen = (det.visibility > 0) & np.isfinite(det.xy).all(axis=1)
    err = np.linalg.norm((det.xy - truth.ball.xy) * size, axis=1)
    err[~(vis & seen)] = np.nan
    hit = vis & seen & (err <= tau)
    return {"visible": vis, "hit": hit, "miss": vis & ~hit, "false": seen & ~hit, "err_px": err,
            "det_px": np.where(seen[:, None], det.xy * size, np.nan)}


def _rate(miss: np.ndarray, where: np.ndarray) -> tuple[float, int]:
    n = int(where.sum())
    return (float(miss[where].mean()) if n else float("nan")), n


def _quant(x) -> list[float]:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return [round(float(q), 4) for q in np.quantile(x, QUANTILES)] if len(x) else []


def measure_clips(pairs: list[tuple[ClipTruth, BallTrack]], tau_px: float = 10.0, contact_s: float = 0.1) -> dict:
    """The statistics (a plain dict, ready for YAML) over ``(truth, detected track)`` pairs."""
    vis_s = 0.0
    acc = {k: [] for k in ("miss", "vis", "diam", "dist", "near", "far", "other", "gap_s", "false", "seen",
                           "far_px", "dx", "dy", "integer")}
    for truth, det in pairs:
        o = frame_outcomes(truth, det, tau_px)
        n = len(o["visible"])
        k = max(1, int(round(contact_s * truth.fps)))
        near = {"near": np.zeros(n, bool), "far": np.zeros(n, bool), "other": np.zeros(n, bool)}
        for f, e in zip(truth.events.frame, truth.events.event):
            key = "near" if str(e) == "player_near" else "far" if str(e) == "player_far" else "other"
            near[key][max(int(f) - k, 0):int(f) + k + 1] = True
        vis_s += float(o["visible"].sum()) / truth.fps
        acc["miss"].append(o["miss"])
        acc["vis"].append(o["visible"])
        acc["diam"].append(truth.diameter_px)
        acc["dist"].append(truth.distance_m)
        for key in ("near", "far", "other"):
            acc[key].append(near[key])
        # gaps: runs of misses while the ball is in the image (a run ends where the ball leaves the image)
        gap_mask = o["miss"].copy()
        acc["gap_s"] += [r / truth.fps for r in run_lengths(gap_mask)]
        acc["false"].append(o["false"])
        acc["seen"].append(o["false"] | o["hit"])
        acc["far_px"].append(np.where(o["false"] & o["visible"], o["err_px"], np.nan) * 1280.0 / truth.width)
        d = (o["det_px"] - truth.ball.xy * np.array([truth.width, truth.height], float))[o["hit"]]
        acc["dx"].append(d[:, 0])
        acc["dy"].append(d[:, 1])
        px = o["det_px"][np.isfinite(o["det_px"]).all(axis=1)]
        acc["integer"].append(np.all(np.abs(px - np.round(px)) < 1e-3, axis=1))
    cat = {k: np.concatenate(v) if v and isinstance(v[0], np.ndarray) else np.asarray(v) for k, v in acc.items()}
    vis, miss = cat["vis"], cat["miss"]
    contact = cat["near"] | cat["far"] | cat["other"]

    def by_bins(values, bins) -> list[dict]:
        out = []
        for lo, hi in zip(bins[:-1], bins[1:]):
            where = vis & (values >= lo) & (values < hi)
            rate, count = _rate(miss, where)
            if count:
                out.append({"from": float(lo), "to": None if not np.isfinite(hi) else float(hi),
                            "miss": round(rate, 4), "frames": count})
        return out

    mad = lambda x: float(1.4826 * np.median(np.abs(x - np.median(x)))) if len(x) else float("nan")  # noqa: E731
    gaps = np.asarray(cat["gap_s"], float)
    seen_n = int(cat["seen"].sum())
    return {
        "clips": len(pairs), "frames_ball_in_image": int(vis.sum()), "tau_px_at_1280": tau_px,
        "recall": round(float(1 - miss[vis].mean()), 4) if vis.any() else float("nan"),
        "miss_by_diameter_px": by_bins(cat["diam"], SIZE_BINS_PX),
        "miss_by_distance_m": by_bins(cat["dist"], DIST_BINS_M),
        "miss_near_contacts": {key: dict(zip(("miss", "frames"), (round(r, 4), c))) for key in ("near", "far", "other")
                               for r, c in [_rate(miss, vis & cat[key])]},
        "miss_away_from_contacts": round(_rate(miss, vis & ~contact)[0], 4),
        "contact_window_s": contact_s,
        "gap_s": {"count": int(len(gaps)), "per_second_in_image": round(len(gaps) / max(vis_s, 1e-9), 4),
                  "mean": round(float(gaps.mean()), 4) if len(gaps) else None,
                  "quantiles": dict(zip((str(q) for q in QUANTILES), _quant(gaps)))},
        "false_rate": round(float(cat["false"].sum() / max(seen_n, 1)), 4),
        "false_distance_px_at_1280": dict(zip((str(q) for q in QUANTILES), _quant(cat["far_px"]))),
        "jitter_px": {"x": round(mad(np.concatenate(acc["dx"])), 3), "y": round(mad(np.concatenate(acc["dy"])), 3)},
        "whole_pixels": round(float(np.mean(cat["integer"])), 4) if len(cat["integer"]) else float("nan"),
    }


def degrade_settings(stats: dict) -> dict:
    """``data.degrade`` fields (:class:`~training.events.synthetic.degrade.DegradeConfig`) that draw tracks with the
    measured figures: gaps at contacts with the measured rates, miss runs with the measured lengths and
    rate away from contacts, misses by the ball's image diameter, outliers at the measured rate and
    distances, the measured jitter and whole pixels."""
    q = stats["gap_s"]["quantiles"]
    lo, hi = (float(q["0.25"]), float(q["0.75"])) if q else (0.1, 0.33)
    near = stats["miss_near_contacts"]
    far_q = stats["false_distance_px_at_1280"]
    jit = float(np.nanmean([stats["jitter_px"]["x"], stats["jitter_px"]["y"]]))

    def p(x, default):
        return default if x is None or not np.isfinite(x) else float(np.clip(x, 0.0, 1.0))

    return {
        "enabled": True, "p_clean": 0.2,
        "p_occlude_near": round(p(near["near"]["miss"], 0.8), 3),
        "p_occlude_far": round(p(near["far"]["miss"], 0.3), 3),
        "occlude_s": [round(max(lo, 1 / 30), 3), round(max(hi, lo, 1 / 30), 3)],
        "p_gap_event": round(p(near["other"]["miss"], 0.5), 3),
        "event_gap_s": [round(max(lo, 1 / 30), 3), round(max(hi, lo, 1 / 30), 3)],
        "miss_frac": round(min(p(stats["miss_away_from_contacts"], 0.2), 0.9), 3),
        "miss_run_s": [round(max(lo, 1 / 30), 3), round(max(hi, lo, 1 / 30), 3)],
        "outlier_frac": round(min(p(stats["false_rate"], 0.12), 0.9), 3),
        "outlier_px": [round(float(far_q.get("0.1", 15.0)), 1), round(float(far_q.get("0.9", 150.0)), 1)]
        if far_q else [15.0, 150.0],
        "jitter_px": [round(max(0.3, 0.7 * jit), 2), round(max(0.5, 1.3 * jit), 2)] if np.isfinite(jit) else [1.0, 3.0],
        "integer_px": bool(stats["whole_pixels"] > 0.5),
        "miss_by_diameter": [[b["from"], b["miss"]] for b in stats["miss_by_diameter_px"]],
    }
