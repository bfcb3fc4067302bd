"""What a ball track does around its events, measured the same way on real tracks (a real tracker's output
with hand-made event labels) and on simulated degraded ones, and the degradation settings
(:class:`~training.events.synthetic.degrade.DegradeConfig`) that reproduce the real figures.

Per event class: the share of events whose frame (±1) has no ball (*hidden*), the lengths of those gaps
(seconds) and where the event lies in them, the image row where the picture shows it (a share of the
height, 10 / 50 / 90 %: the camera's framing) and, for a hit, how fast the ball leaves it in the picture
(px per 1/50 s on a 1080-row picture: the lens and the pace); elsewhere: the runs of misses (count per second, lengths) and
the share of the visible frames they take; the positions more than :data:`OUTLIER_PX` off their neighbours'
quadratic (wrong positions); the jitter (robust σ of each point's distance from a quadratic
through its neighbours, px) and whether positions are whole pixels; the share of gaps the ball leaves and
re-enters through the top of the picture (lobs); the serve's flight (serve → its bounce, s: the serve's speed,
which the simulator's tennis serves were fitted to). Only the labelled stretch counts (from the first to the
last event, ±``margin_s``): the server's bounces before the serve are not labelled. A clip's first event,
when it is the far player's hit, is a far serve and counts apart (``serve_far``): a real broadcast tracker
loses the far server's toss against the crowd, so the far serve hides in a long gap that lies mostly
before the contact (RG2025: 79 % of the far serves, median 0.47 s, 82 % of it before the hit); the near
server's toss stays in view (its serve counts with the near hits).

Example:
    >>> stats = measure([(track, events, fps, width, height), ...])
    >>> degrade_from(stats)         # → data.degrade fields
"""
from __future__ import annotations

import numpy as np

from inference.clipio import BallTrack, HitEvents

CLASSES = ("player_near", "player_far", "ground", "serve_far")
QUANTILES = (0.25, 0.5, 0.75, 0.9)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` runs of True."""
    m = np.r_[0, np.asarray(mask, int), 0]
    e = np.flatnonzero(np.diff(m))
    return list(zip(e[::2].tolist(), e[1::2].tolist()))


def _residuals_px(xy: np.ndarray, half: int = 3) -> np.ndarray:
    """``(M, 2)`` offsets (px) of every fully seen window's centre from a quadratic through the window, scaled
    to the centre's own noise (÷ √(1 − h), so that a σ of jitter reads as σ)."""
    t = np.arange(-half, half + 1, dtype=float)
    A = np.stack([np.ones_like(t), t, t * t], 1)
    H = A @ np.linalg.pinv(A)
    ok = np.convolve(np.isfinite(xy).all(axis=1).astype(int), np.ones(2 * half + 1, int), "valid") == 2 * half + 1
    out = [(xy[s:s + 2 * half + 1] - H @ xy[s:s + 2 * half + 1])[half] for s in np.flatnonzero(ok)]
    return np.array(out).reshape(-1, 2) / np.sqrt(1.0 - H[half, half])


def _jitter_px(xy: np.ndarray, half: int = 3) -> list[float]:
    """Distances (px, both axes pooled) of every fully seen window's centre from a quadratic through it."""
    return _residuals_px(xy, half).ravel().tolist()


#: a position this far (px on a 1080-row picture) off the quadratic through its neighbours is a wrong one (an
#: outlier: the tracker on something else), not jitter; windows within 5 frames of an event are not counted (a
#: contact's kink is no outlier)
OUTLIER_PX = 15.0


def clip_stats(track: BallTrack, events: HitEvents, fps: float, width: int, height: int,
               margin_s: float = 0.2, top: float = 0.06) -> dict:
    """The raw figures of one clip (lists, pooled by :func:`measure`)."""
    n = int(max(track.frame.max() + 1 if len(track) else 0, events.frame.max() + 1 if len(events) else 0))
    out = {"hidden": {c: [] for c in CLASSES}, "gap_s": {c: [] for c in CLASSES}, "where": {c: [] for c in CLASSES},
           "row": {c: [] for c in CLASSES}, "speed_after": {c: [] for c in CLASSES},
           "other_runs_s": [], "seconds": 0.0, "visible": 0, "missed_other": 0, "jitter": [], "integer": [],
           "gaps": 0, "top_gaps": 0, "top_gap_s": [], "serve_flight_s": [], "shot_flight_s": [], "outliers": 0,
           "windows": 0}
    if not len(events) or not n:
        return out
    dense = track.dense(n)
    xy = np.where(dense.visibility[:, None] > 0, dense.xy, np.nan) * np.array([width, height], float)
    seen = np.isfinite(xy).all(axis=1)
    a = max(0, int(events.frame[0] - margin_s * fps))
    b = min(n, int(events.frame[-1] + margin_s * fps) + 1)
    near_event = np.zeros(n, bool)
    ev = [str(c) for c in events.event]
    if len(ev) > 1 and ev[0] in ("player_near", "player_far") and ev[1] == "ground":  # the serve's own flight
        out["serve_flight_s"].append(float(events.frame[1] - events.frame[0]) / fps)
    hits = [k for k, c in enumerate(ev) if c in ("player_near", "player_far")]
    for k in hits[1:]:  # the rally's shots (not the serve): the hit to the bounce that follows it
        if k + 1 < len(ev) and ev[k + 1] == "ground":
            out["shot_flight_s"].append(float(events.frame[k + 1] - events.frame[k]) / fps)
    runs = [(s + a, e + a) for s, e in _runs(~seen[a:b])]
    step = max(1, int(round(0.16 * fps)))  # the flight after a hit: 0.16 s (8 frames at 50 fps)
    for k, (f, c) in enumerate(zip(events.frame.tolist(), events.event.tolist())):
        if k == 0 and c == "player_far":
            c = "serve_far"  # the clip's first event, the far player's hit: a far serve
        if c not in CLASSES:
            continue
        near_seen = [g for g in (f, f - 1, f + 1, f - 2, f + 2) if 0 <= g < n and seen[g]]
        if near_seen:  # where the picture shows the event, and how fast the ball leaves a hit
            out["row"][c].append(float(xy[near_seen[0], 1] / height))
        if c in ("player_near", "player_far"):
            d = np.hypot(*np.diff(xy[f + 1:f + 1 + step], axis=0).T)
            d = d[np.isfinite(d)]
            if len(d) >= 3:
                out["speed_after"][c].append(float(np.median(d)) * (1080.0 / height) * (fps / 50.0))
        hidden = not seen[max(0, f - 1):f + 2].any()
        out["hidden"][c].append(hidden)
        # a serve's gap is taken whole: its toss lies before the labelled stretch (a clip's first gap, which
        # may be the clip's unseen start, is not a gap the tracker made)
        for s, e in (runs if c != "serve_far" else [r for r in _runs(~seen) if r[0] > 0]):
            if s - 1 <= f <= e:
                out["gap_s"][c].append((e - s) / fps)
                out["where"][c].append((f - s + 0.5) / max(e - s, 1))
                near_event[s:e] = True
                break
    out["top_frames"] = 0
    for s, e in runs:
        if s > 0 and e < n:
            out["gaps"] += 1
            above = xy[s - 1, 1] < top * height and xy[e, 1] < top * height
            out["top_gaps"] += int(above)
            out["top_frames"] += (e - s) * int(above)
            if above:
                out["top_gap_s"].append((e - s) / fps)
        if not near_event[s:e].any():
            out["other_runs_s"].append((e - s) / fps)
            out["missed_other"] += e - s
    out["seconds"] = (b - a) / fps
    out["visible"] = int(seen[a:b].sum())
    out["jitter"] = _jitter_px(xy[a:b])
    away = seen.copy()  # the positions away from the events (a contact's kink is not an outlier)
    for f in events.frame.tolist():
        away[max(0, f - 5):f + 6] = False
    res = _residuals_px(np.where(away[:, None], xy, np.nan)[a:b])
    out["outliers"] = int(np.sum(np.hypot(*res.T) > OUTLIER_PX * height / 1080.0)) if len(res) else 0
    out["windows"] = len(res)
    p = xy[a:b][seen[a:b]]
    out["integer"] = [bool(np.allclose(p, np.round(p), atol=1e-3))] if len(p) else []
    return out


def measure(clips, margin_s: float = 0.2) -> dict:
    """Pooled figures of ``clips`` (``(track, events, fps, width, height)`` each): per class the hidden share
    and gap quantiles (s), the other miss runs per second and their quantiles, the share of the visible
    frames they take, the jitter (robust σ, px), whole pixels, the share of gaps above the picture."""
    pool = [clip_stats(*c, margin_s=margin_s) for c in clips]
    out: dict = {"clips": len(pool)}
    for c in CLASSES:
        hidden = [h for s in pool for h in s["hidden"][c]]
        gaps = np.array([g for s in pool for g in s["gap_s"][c]])
        where = np.array([w for s in pool for w in s["where"][c]])
        out[c] = {"events": len(hidden), "hidden": round(float(np.mean(hidden)), 3) if hidden else None,
                  "gap_s": [round(float(q), 3) for q in np.quantile(gaps, QUANTILES)] if len(gaps) else None,
                  "where": round(float(np.median(where)), 2) if len(where) else None,
                  "where_iqr": [round(float(q), 2) for q in np.quantile(where, (0.25, 0.75))] if len(where) else None}
        rows = [v for s in pool for v in s.get("row", {}).get(c, [])]
        speed = [v for s in pool for v in s.get("speed_after", {}).get(c, [])]
        out[c]["row"] = [round(float(q), 3) for q in np.quantile(rows, (0.1, 0.5, 0.9))] if rows else None
        out[c]["speed_after"] = round(float(np.median(speed)), 1) if speed else None
    runs = np.array([r for s in pool for r in s["other_runs_s"]])
    seconds = sum(s["seconds"] for s in pool)
    visible = sum(s["visible"] for s in pool)
    missed = sum(s["missed_other"] for s in pool)
    jit = np.array([j for s in pool for j in s["jitter"]])
    out["other_runs_per_s"] = round(len(runs) / seconds, 3) if seconds else None
    out["other_runs_s"] = [round(float(q), 3) for q in np.quantile(runs, QUANTILES)] if len(runs) else None
    out["other_miss_share"] = round(missed / max(visible + missed, 1), 3)
    out["jitter_px"] = round(float(1.4826 * np.median(np.abs(jit - np.median(jit)))), 2) if len(jit) else None
    windows = sum(s.get("windows", 0) for s in pool)
    out["outlier_share"] = round(sum(s.get("outliers", 0) for s in pool) / windows, 4) if windows else None
    out["integer_px"] = bool(all(i for s in pool for i in s["integer"])) if any(s["integer"] for s in pool) else None
    gaps = sum(s["gaps"] for s in pool)
    out["top_gap_share"] = round(sum(s["top_gaps"] for s in pool) / gaps, 3) if gaps else None
    frames = sum(s["visible"] + s["missed_other"] for s in pool)
    out["top_frame_share"] = round(sum(s.get("top_frames", 0) for s in pool) / max(frames, 1), 4)
    flights = [g for s in pool for g in s.get("serve_flight_s", [])]
    out["serve_flight_s"] = [round(float(q), 3) for q in np.quantile(flights, (0.1, 0.5, 0.9))] if flights else None
    shots = [g for s in pool for g in s.get("shot_flight_s", [])]
    out["shot_flight_s"] = [round(float(q), 3) for q in np.quantile(shots, (0.1, 0.5, 0.9))] if shots else None
    top_s = [g for s in pool for g in s["top_gap_s"]]
    out["top_gap_s"] = round(float(np.median(top_s)), 2) if top_s else None
    return out


def degrade_from(stats: dict, base: dict | None = None, top_crop: float | None = None,
                 smoothed: bool | None = None) -> dict:
    """``data.degrade`` fields that reproduce ``stats`` (from :func:`measure` on real tracks), on top of
    ``base`` (the fields this cannot measure: clean clips, and smoothing unless ``smoothed`` says whether the
    real tracks were smoothed: False sets ``p_smooth`` 0). Gap lengths take the
    measured 25–75 % range (a gap that holds a contact can run on for seconds: the point's start, a lob);
    probabilities are divided by the share of degraded clips (``1 − p_clean``) so that the pooled figure
    matches; the jitter's σ ± 30 %; the wrong positions' share (``outlier_frac``) from the positions more
    than :data:`OUTLIER_PX` off their neighbours' quadratic; ``top_crop`` as given (:func:`top_crop_for`)."""
    out = dict(base or {})
    degraded = 1.0 - float(out.get("p_clean", 0.2))

    def span(q, cap=None):
        hi = q[2] if cap is None else min(q[2], cap)
        return [round(max(q[0], 0.02), 3), round(max(hi, q[0] + 0.02), 3)]

    def prob(p):
        return round(min(1.0, p / max(degraded, 1e-6)), 3)

    near, far, ground = stats["player_near"], stats["player_far"], stats["ground"]
    for d, p_key, s_key in ((near, "p_occlude_near", "occlude_s"), (far, "p_occlude_far", "occlude_far_s"),
                            (ground, "p_gap_event", "event_gap_s")):
        if d["events"]:
            out[p_key] = prob(d["hidden"]) if d["gap_s"] else 0.0
            if d["gap_s"]:
                out[s_key] = span(d["gap_s"], cap=1.0)
    serve = stats.get("serve_far") or {}
    if serve.get("events"):  # the far serve: its toss lost against the crowd
        out["p_serve_gap_far"] = prob(serve["hidden"]) if serve["gap_s"] else 0.0
        if serve["gap_s"]:
            out["serve_gap_s"] = span(serve["gap_s"], cap=1.5)
            lo, hi = (float(np.clip(q, 0.0, 1.0)) for q in serve["where_iqr"])
            out["serve_before"] = [round(lo, 2), round(max(hi, lo), 2)]
    if stats["other_runs_s"]:
        out.update(miss_frac=prob(stats["other_miss_share"]), miss_run_s=span(stats["other_runs_s"]))
    if top_crop is not None:
        out["top_crop"] = round(float(top_crop), 3)
    if stats["jitter_px"]:
        j = stats["jitter_px"]
        out["jitter_px"] = [round(0.7 * j, 2), round(1.3 * j, 2)]
    if stats["integer_px"] is not None:
        out["integer_px"] = bool(stats["integer_px"])
    if stats.get("outlier_share") is not None:
        out["outlier_frac"] = round(min(0.5, stats["outlier_share"] / max(degraded, 1e-6)), 4)
    if smoothed is not None:
        out["p_smooth"] = float(out.get("p_smooth", 0.8)) if smoothed else 0.0
    return out


def top_crop_for(tracks, share: float, height: int | None = None) -> float:
    """The image-top share to cut off simulated tracks (``data.degrade.top_crop``) so that as large a share
    of their frames lies above it as the real tracks have in gaps above the picture (lobs leaving the top):
    tracks ``(N,)`` of :class:`BallTrack` (normalised positions)."""
    v = np.concatenate([t.xy[t.visibility > 0, 1] for t in tracks]) if tracks else np.zeros(0)
    if not len(v) or share <= 0:
        return 0.0
    return float(np.clip(np.quantile(v, share), 0.0, 0.3))
