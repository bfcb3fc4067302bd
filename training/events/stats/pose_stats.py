"""What a pose backend and the players stage do to the players: statistics of a ``players.csv`` written by
``rally3d players`` (or ``infer``) against the clip's ground truth, and the pose-noise settings
(:class:`~training.events.synthetic.pose_noise.PoseNoiseConfig`) that reproduce them.

Rows are matched per frame by court position (:func:`inference.players.evaluate.match_frames`, ≤ 1.5 m).
Per side (near, far — the true player's team): the fraction of the true player-frames without a matched row
(*missed*, per clip and player) and the lengths of those runs (seconds); the keypoint error of matched rows
(pixels of the clip's frame, joints scored ≥ ``min_score`` as the event features read them) as a robust σ
per axis, for the body and for the wrists, and the share of *outliers* (farther than ``outlier_frac`` of the
true player's height); the share of matched rows without a wrist; runs where left and right are swapped
(per second and their length); rows whose team is wrong; the court-position error (robust σ per axis, m).

Example:
    >>> stats = measure_players([PoseClipTruth.from_clip(clip, predicted)])
    >>> pose_noise_settings(stats)        # → data.pose_noise fields
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.clipio import PlayerTracks
from inference.players.evaluate import match_frames

from training.events.stats.track_stats import run_lengths

SIDES = ("near", "far")
_WRISTS = (9, 10)
_PAIRS = ((5, 6), (7, 8), (9, 10), (11, 12), (13, 14), (15, 16))  # left/right pairs that can be swapped


@dataclass
class PoseClipTruth:
    """One clip's true and predicted players, with the frame size (px) and rate."""

    name: str
    fps: float
    width: int
    height: int
    gt: PlayerTracks
    pred: PlayerTracks
    raw: object = None   # the backend's PoseSequence before the players stage (None: bridged rows not counted)

    @classmethod
    def from_clip(cls, clip, pred: PlayerTracks, raw=None) -> PoseClipTruth:
        """``clip``: an :class:`inference.clipio.Clip` with ``gt/players.csv``; ``raw``: the backend's poses."""
        return cls(clip.root.name, float(clip.info.fps), int(clip.info.width), int(clip.info.height),
                   clip.read_players(gt=True), pred, raw)


def bridged_rows(c: PoseClipTruth, tol_px: float = 3.0) -> np.ndarray:
    """``(len(c.pred),)`` True where the players stage filled the row (no raw detection holds its pose)."""
    wh = np.array([c.width, c.height], float)
    out = np.zeros(len(c.pred), bool)
    for i, f in enumerate(c.pred.frame):
        persons = c.raw.frames[int(f)] if int(f) < len(c.raw.frames) else None
        if persons is None or not len(persons):
            out[i] = True
            continue
        kp = c.pred.keypoints[i, :, :2] * wh
        with np.errstate(invalid="ignore"):
            d = np.nanmean(np.linalg.norm(persons.keypoints - kp[None], axis=2), axis=1)
        out[i] = not (np.nanmin(d) <= tol_px) if np.isfinite(d).any() else True
    return out


def _robust_sigma(x: np.ndarray) -> float:
    """1.4826 × the median absolute deviation (NaN when empty)."""
    x = np.asarray(x, float).ravel()
    x = x[np.isfinite(x)]
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if len(x) else float("nan")


def _visible(gt_kp: np.ndarray) -> np.ndarray:
    """``(n, 17)`` joints the truth places in the image (score > 0, finite)."""
    return np.isfinite(gt_kp[..., :2]).all(axis=-1) & (np.nan_to_num(gt_kp[..., 2], nan=1.0) > 0)


@dataclass
class _Side:
    """What is gathered for one side (near or far) over every clip and true player."""

    miss_frac: list = field(default_factory=list)        # per (clip, player)
    miss_runs_s: list = field(default_factory=list)
    seconds: float = 0.0
    matched: int = 0
    team_wrong: int = 0
    height_px: list = field(default_factory=list)
    court_err: list = field(default_factory=list)        # (2,) m per matched row
    body_err: list = field(default_factory=list)         # (2,) px per body joint
    wrist_err: list = field(default_factory=list)        # (2,) px per wrist
    body_dist_rel: list = field(default_factory=list)    # body-joint error / player height
    wrist_off_rel: list = field(default_factory=list)    # distance to the nearer true wrist / player height
    body_step: list = field(default_factory=list)        # frame-to-frame change of the error / √2, px
    wrist_step: list = field(default_factory=list)
    lag_pairs: list = field(default_factory=list)        # (error at f, error at f + lag) of body joints
    jitter_per_clip: list = field(default_factory=list)  # body-joint offset σ per clip, px
    wrist_rows: int = 0
    wrist_missing: int = 0
    joint_rows: int = 0
    joint_missing: int = 0
    flip_checked: int = 0
    flip_frames: int = 0
    flip_runs_s: list = field(default_factory=list)
    outlier_runs_s: list = field(default_factory=list)
    bridged: list = field(default_factory=list)          # per (clip, player): share of rows the stage filled
    bridged_runs_s: list = field(default_factory=list)


@dataclass
class _RowError:
    """One matched row against the truth (pixels of the frame): ``err`` (17, 2); masks (17,) of joints the
    truth shows (``vis``), the prediction has (``have``), body joints and wrists both have (``body``,
    ``wrist``); the player's ``height`` px; ``off`` (2,) each wrist's distance to the nearer true wrist;
    ``flipped``: left and right swapped (None: too few pairs to tell)."""

    err: np.ndarray
    vis: np.ndarray
    have: np.ndarray
    body: np.ndarray
    wrist: np.ndarray
    height: float
    off: np.ndarray
    flipped: bool | None


def _row_error(g: np.ndarray, p: np.ndarray, wh: np.ndarray, min_score: float) -> _RowError:
    """``g``, ``p``: (17, 3) true and predicted keypoints (normalised x, y, score)."""
    vis = _visible(g[None])[0]
    ys = g[vis, 1] * wh[1]
    height = float(ys.max() - ys.min()) if vis.sum() >= 2 else np.nan
    have = np.isfinite(p[:, :2]).all(axis=1) & (np.nan_to_num(p[:, 2], nan=1.0) >= min_score)
    err = (p[:, :2] - g[:, :2]) * wh
    use = have & vis
    wrists = np.zeros(17, bool)
    wrists[list(_WRISTS)] = True
    off = np.minimum(np.linalg.norm(err[list(_WRISTS)], axis=1),
                     np.linalg.norm((p[list(_WRISTS), :2] - g[list(_WRISTS[::-1]), :2]) * wh, axis=1))
    pairs = [(a, b) for a, b in _PAIRS if use[a] and use[b]]
    flipped = None
    if len(pairs) >= 2:
        direct = sum(np.linalg.norm(err[a]) + np.linalg.norm(err[b]) for a, b in pairs)
        swapped = sum(np.linalg.norm((p[b, :2] - g[a, :2]) * wh) + np.linalg.norm((p[a, :2] - g[b, :2]) * wh)
                      for a, b in pairs)
        flipped = bool(swapped < 0.5 * direct)
    return _RowError(err, vis, have, use & ~wrists, use & wrists, height, off, flipped)


def _add_row(st: _Side, r: _RowError, prev: _RowError | None, outlier_frac: float) -> np.ndarray:
    """Gather one matched row (``prev``: the same player's row on the frame before, if matched); returns
    the (2,) mask of its wrists placed on something else."""
    st.height_px.append(r.height)
    st.body_err += list(r.err[r.body])
    st.body_dist_rel += list(np.linalg.norm(r.err[r.body], axis=1) / r.height)
    st.wrist_err += list(r.err[r.wrist])
    w = r.wrist[list(_WRISTS)]
    st.wrist_off_rel += list(r.off[w] / r.height)
    if prev is not None:
        both = np.isfinite(prev.err).all(axis=1) & (prev.body | prev.wrist)
        step = (r.err - prev.err) / np.sqrt(2.0)
        st.body_step += list(step[both & r.body])
        st.wrist_step += list(step[both & r.wrist])
    others = np.ones(17, bool)
    others[list(_WRISTS)] = False
    st.wrist_rows += int(r.vis[list(_WRISTS)].sum())
    st.wrist_missing += int((r.vis & ~r.have)[list(_WRISTS)].sum())
    st.joint_rows += int(r.vis[others].sum())
    st.joint_missing += int((r.vis & ~r.have)[others].sum())
    st.flip_checked += int(r.flipped is not None)
    return w & (r.off / r.height > outlier_frac)


def _add_bridged(sides: dict[str, _Side], c: PoseClipTruth) -> None:
    bridged = bridged_rows(c)
    for pid in c.pred.ids():
        rows = np.flatnonzero(c.pred.player_id == pid)
        side = str(c.pred.team[rows[0]])
        if side in SIDES:
            sides[side].bridged.append(float(bridged[rows].mean()))
            sides[side].bridged_runs_s += [n / c.fps for n in run_lengths(bridged[rows])]


def _lag_corr(pairs: list) -> float:
    """Correlation of the body-joint errors at ``f`` and ``f + lag``, pooled over joints and axes (the
    offset itself is what drifts, so no per-player mean is removed)."""
    if not pairs:
        return float("nan")
    a = np.stack(pairs)                   # (k, 2, 17, 2)
    x, y = a[:, 0].ravel(), a[:, 1].ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() <= 10 or np.std(x[ok]) == 0 or np.std(y[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(x[ok], y[ok])[0, 1])


def _measure_player(st: _Side, c: PoseClipTruth, gid: int, side: str, matches: dict, index: dict,
                    min_score: float, outlier_frac: float, lag: int) -> list:
    """Gather one true player of clip ``c``; returns its body-joint errors (for the clip's offset σ)."""
    gt, pred = c.gt, c.pred
    wh = np.array([c.width, c.height], float)
    rows = np.flatnonzero(gt.player_id == gid)
    frames = gt.frame[rows][_visible(gt.keypoints[rows]).sum(axis=1) >= 5]
    if not len(frames):
        return []
    found = np.array([any(g == gid for g, _ in matches.get(int(f), [])) for f in frames])
    st.miss_frac.append(float(1.0 - found.mean()))
    st.miss_runs_s += [n / c.fps for n in run_lengths(~found)]
    st.seconds += len(frames) / c.fps
    flipped = np.zeros(len(frames), bool)
    outlier = np.zeros((len(frames), 2), bool)
    body_by_frame: dict[int, np.ndarray] = {}
    errors: list = []
    prev, prev_f = None, None
    for k, f in enumerate(frames):
        pid = next((p for g, p in matches.get(int(f), []) if g == gid), None)
        if pid is None:
            continue
        gi, pi = index["gt"][(int(f), int(gid))], index["pred"][(int(f), int(pid))]
        st.matched += 1
        st.team_wrong += int(str(pred.team[pi]) != side)
        st.court_err.append(pred.court_xy[pi] - gt.court_xy[gi])
        r = _row_error(gt.keypoints[gi], pred.keypoints[pi], wh, min_score)
        outlier[k] = _add_row(st, r, prev if prev_f == f - 1 else None, outlier_frac)
        flipped[k] = bool(r.flipped)
        errors += list(r.err[r.body])
        body_by_frame[int(f)] = np.where(r.body[:, None], r.err, np.nan)
        prev, prev_f = r, f
    st.flip_frames += int(flipped.sum())
    st.flip_runs_s += [n / c.fps for n in run_lengths(flipped)]
    st.outlier_runs_s += [n / c.fps for j in range(2) for n in run_lengths(outlier[:, j])]
    st.lag_pairs += [np.stack([e, body_by_frame[f + lag]]) for f, e in body_by_frame.items() if f + lag in body_by_frame]
    return errors


def measure_players(clips: list[PoseClipTruth], min_score: float = 0.1, outlier_frac: float = 0.25,
                    lag_s: float = 0.2) -> dict:
    """Statistics of the predicted players of ``clips`` against the truth (see the module docstring); with
    the raw poses also the rows the players stage bridged (fraction per player, run lengths), and the
    body-joint error's correlation over ``lag_s`` (how slowly the offset drifts).

    Returns a plain dict (YAML-ready): per side ``near``/``far`` the figures, and ``clips``."""
    sides = {s: _Side() for s in SIDES}
    for c in clips:
        if c.raw is not None:
            _add_bridged(sides, c)
        matches = match_frames(c.pred, c.gt)
        index = {"pred": {(int(f), int(p)): i for i, (f, p) in enumerate(zip(c.pred.frame, c.pred.player_id))},
                 "gt": {(int(f), int(g)): i for i, (f, g) in enumerate(zip(c.gt.frame, c.gt.player_id))}}
        clip_err: dict[str, list] = {s: [] for s in SIDES}
        for gid in c.gt.ids():
            team = str(c.gt.team[np.flatnonzero(c.gt.player_id == gid)[0]])
            side = team if team in SIDES else "near"
            clip_err[side] += _measure_player(sides[side], c, gid, side, matches, index, min_score, outlier_frac,
                                              max(1, int(round(lag_s * c.fps))))
        for s in SIDES:
            if len(clip_err[s]) >= 20:
                sides[s].jitter_per_clip.append(_robust_sigma(np.asarray(clip_err[s])))
    return _summary(sides, [c.name for c in clips], lag_s, outlier_frac)


def _summary(sides: dict[str, _Side], names: list[str], lag_s: float, outlier_frac: float) -> dict:
    """The YAML-ready figures of :func:`measure_players`."""
    out: dict = {"clips": names, "lag_s": lag_s, "outlier_frac": outlier_frac}
    for s, st in sides.items():
        q = lambda v: [round(float(x), 3) for x in np.quantile(v, (0.1, 0.5, 0.9))] if len(v) else []  # noqa: E731
        body = np.asarray(st.body_err).reshape(-1, 2)
        wrist = np.asarray(st.wrist_err).reshape(-1, 2)
        court = np.asarray(st.court_err).reshape(-1, 2)
        court = court[np.isfinite(court).all(axis=1)]
        out[s] = {
            "players": len(st.miss_frac),
            "seconds": round(st.seconds, 1),
            "height_px": q([h for h in st.height_px if np.isfinite(h)]),
            "miss_frac": q(st.miss_frac),
            "miss_runs_s": q(st.miss_runs_s),
            "body_sigma_px": [round(_robust_sigma(body[:, 0]), 2), round(_robust_sigma(body[:, 1]), 2)],
            "wrist_sigma_px": [round(_robust_sigma(wrist[:, 0]), 2), round(_robust_sigma(wrist[:, 1]), 2)],
            "body_jitter_px": round(_robust_sigma(np.asarray(st.body_step)), 2),
            "wrist_jitter_px": round(_robust_sigma(np.asarray(st.wrist_step)), 2),
            "wrist_outlier_runs_s": q(st.outlier_runs_s),
            "wrist_outlier_rel": q([d for d in st.wrist_off_rel if d > outlier_frac]),
            "jitter_px_per_clip": [round(float(v), 2) for v in st.jitter_per_clip],
            "body_outlier_frac": round(float(np.mean(np.asarray(st.body_dist_rel) > outlier_frac)), 4)
            if st.body_dist_rel else float("nan"),
            "wrist_outlier_frac": round(float(np.mean(np.asarray(st.wrist_off_rel) > outlier_frac)), 4)
            if st.wrist_off_rel else float("nan"),
            "wrist_missing": round(st.wrist_missing / max(st.wrist_rows, 1), 4),
            "joint_missing": round(st.joint_missing / max(st.joint_rows, 1), 4),
            "flip_frac": round(st.flip_frames / max(st.flip_checked, 1), 4),
            "flip_runs_per_s": round(len(st.flip_runs_s) / max(st.seconds, 1e-9), 3),
            "flip_runs_s": q(st.flip_runs_s),
            "team_wrong": round(st.team_wrong / max(st.matched, 1), 4),
            "bridged_frac": q(st.bridged),
            "bridged_runs_s": q(st.bridged_runs_s),
            "lag_corr": round(_lag_corr(st.lag_pairs), 3),
            "court_sigma_m": [round(_robust_sigma(court[:, 0]), 3), round(_robust_sigma(court[:, 1]), 3)]
            if len(court) else [],
        }
    return out


def _span(values: list[float], lo: float = 0.0) -> list[float]:
    """``[min, max]`` of finite values, rounded (``[lo, lo]`` when none)."""
    v = [float(x) for x in values if x is not None and np.isfinite(x)]
    return [round(max(min(v), lo), 3), round(max(max(v), lo), 3)] if v else [lo, lo]


def pose_noise_settings(stats: dict, fill_gap_s: float | None = None) -> dict:
    """The :class:`~training.events.synthetic.pose_noise.PoseNoiseConfig` fields that reproduce ``stats``
    (:func:`measure_players`): ranges span the near and far sides' figures (per-clip ones where measured).

    ``fill_gap_s``: the players stage's gap filling (default: ``TrackingConfig.max_gap_s``); measured misses
    longer than it stay misses, shorter dropped detections are drawn as ``drop_*`` and bridged."""
    from inference.players.tracking import TrackingConfig

    fill = TrackingConfig().max_gap_s if fill_gap_s is None else float(fill_gap_s)
    near, far = stats["near"], stats["far"]
    both = (near, far)

    def rel(side: dict) -> list[float]:     # per-clip σ of the offset as a fraction of the median height
        h = side["height_px"][1] if side["height_px"] else float("nan")
        return [v / h for v in side["jitter_px_per_clip"]]

    ratio = [np.mean(s["wrist_sigma_px"]) / np.mean(s["body_sigma_px"]) for s in both if s["body_sigma_px"]]
    corr = [s["lag_corr"] for s in both if np.isfinite(s["lag_corr"]) and 0 < s["lag_corr"] < 1]
    tau = float(-stats["lag_s"] / np.log(np.mean(corr))) if corr else 1.0
    q = lambda side, key, i: side[key][i] if side[key] else 0.0  # noqa: E731
    runs = lambda key: [q(s, key, 0) for s in both] + [q(s, key, 2) for s in both]  # noqa: E731
    return {
        "enabled": True,
        # uniform draws with the measured median as their mean (per-player miss rates are skewed)
        "miss_near": [round(q(near, "miss_frac", 0), 3), round(min(2 * q(near, "miss_frac", 1) - q(near, "miss_frac", 0), 0.9), 3)],
        "miss_far": [round(q(far, "miss_frac", 0), 3), round(min(2 * q(far, "miss_frac", 1) - q(far, "miss_frac", 0), 0.9), 3)],
        "miss_run_s": [round(fill, 3), round(max(fill, *[q(s, "miss_runs_s", 2) for s in both]), 3)],
        "drop_near": [round(q(near, "bridged_frac", 0), 3), round(min(q(near, "bridged_frac", 2), 0.9), 3)],
        "drop_far": [round(q(far, "bridged_frac", 0), 3), round(min(q(far, "bridged_frac", 2), 0.9), 3)],
        "drop_run_s": _span(runs("bridged_runs_s"), 0.01),
        "fill_gap_s": round(fill, 3),
        "jitter_px": _span([s["body_jitter_px"] for s in both]),
        "bias_rel": _span(rel(near) + rel(far)),
        "wrist_bias_scale": round(float(np.mean(ratio)), 2) if ratio else 2.0,
        "bias_s": round(tau, 3),
        "p_joint_miss": round(max(s["joint_missing"] for s in both), 4),
        "p_wrist_miss": round(max(s["wrist_missing"] for s in both), 4),
        "wrist_outlier_near": round(float(near["wrist_outlier_frac"]), 4),
        "wrist_outlier_far": round(float(far["wrist_outlier_frac"]), 4),
        "wrist_outlier_s": _span(runs("wrist_outlier_runs_s"), 0.01),
        "wrist_outlier_rel": [stats["outlier_frac"], round(max(q(s, "wrist_outlier_rel", 2) for s in both), 3)],
        "p_flip_lr": round(float(near["flip_runs_per_s"]), 3),
        "p_flip_lr_far": round(float(far["flip_runs_per_s"]), 3),
        "flip_s": _span(runs("flip_runs_s"), 0.01),
        "p_swap_sides": round(max(s["team_wrong"] for s in both), 4),
        "court_sigma_m": _span([v for s in both for v in s["court_sigma_m"]]),
    }


def refine_settings(settings: dict, measured: dict, simulated: dict) -> dict:
    """One correction step: ``settings`` whose statistics (``simulated``: :func:`measure_players` of the true
    players through the noise model) differ from ``measured`` get the rates that are read back through
    matching and thresholds rescaled — misses, flips, wrists on something else, the offset's and the
    jitter's size by the ratio measured / simulated, the offset's time constant by the ratio of the log
    correlations. Applied a few times, it brings the model's statistics to the measured ones."""
    out = dict(settings)
    for side, key in (("near", "miss_near"), ("far", "miss_far")):
        m, s = measured[side]["miss_frac"], simulated[side]["miss_frac"]
        if m and s and s[1] > 0:
            k = m[1] / s[1]
            out[key] = [round(min(v * k, 0.9), 3) for v in settings[key]]
    for side, key in (("near", "p_flip_lr"), ("far", "p_flip_lr_far")):
        m, s = measured[side]["flip_runs_per_s"], simulated[side]["flip_runs_per_s"]
        if s > 0:
            out[key] = round(settings[key] * m / s, 3)
    for side, key in (("near", "wrist_outlier_near"), ("far", "wrist_outlier_far")):
        m, s = measured[side]["wrist_outlier_frac"], simulated[side]["wrist_outlier_frac"]
        if s > 0:
            out[key] = round(min(settings[key] * m / s, 0.9), 4)
    body = lambda st, key: float(np.mean([np.mean(st[x][key]) for x in SIDES]))  # noqa: E731
    if body(simulated, "body_sigma_px") > 0:
        k = body(measured, "body_sigma_px") / body(simulated, "body_sigma_px")
        out["bias_rel"] = [round(v * k, 4) for v in settings["bias_rel"]]
        k_w = (body(measured, "wrist_sigma_px") / body(measured, "body_sigma_px")) / (
            body(simulated, "wrist_sigma_px") / body(simulated, "body_sigma_px"))
        out["wrist_bias_scale"] = round(settings["wrist_bias_scale"] * k_w, 3)
    jm = np.mean([measured[x]["body_jitter_px"] for x in SIDES])
    js = np.mean([simulated[x]["body_jitter_px"] for x in SIDES])
    if js > 0:
        out["jitter_px"] = [round(v * jm / js, 3) for v in settings["jitter_px"]]
    cm = [measured[s]["lag_corr"] for s in SIDES]
    cs = [simulated[s]["lag_corr"] for s in SIDES]
    if all(0 < c < 1 for c in cm + cs):
        out["bias_s"] = round(settings["bias_s"] * float(np.log(np.mean(cs)) / np.log(np.mean(cm))), 3)
    return {k: ([float(x) for x in v] if isinstance(v, list) else float(v) if isinstance(v, np.floating) else v)
            for k, v in out.items()}
