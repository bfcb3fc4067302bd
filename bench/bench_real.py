"""The real-first loop (issue 38): the SHIPPED pipeline on every item of ``../shared/real``, one table.

Real footage and labels made outside the project, read in place (measurement only: nothing of it is
copied into the repository; run folders go under ``runs/bench_real/``, which git ignores). The folder is
``../shared/real`` beside the repository, or ``$RALLY3D_REAL``; without it the bench prints one line and
exits 0.

    .venv/bin/python bench/bench_real.py [--only tennis_points,padel_track,tennis_clips,padel_still]
        [--limit N] [--json PATH] [--reuse] [--device cpu]

Parts (each timed: CPU = this process's ``time.process_time``, every thread included, and wall):

- ``tennis_points``: ``tennis_events_rg2025_dev``, 250 points of a real final (a real tracker's
  ``ball.csv``, hand labels, no video, 50 fps). The shipped tennis event model as ``rally3d events`` runs
  it (``choose_weights``, no players, no camera, every event kept); F1 per class at ±2 frames, only events
  inside ``tracked_window``; all points, the last 50 (the ``held-out`` line), and two diagnostics (the
  model's own rally segmentation; only the predictions inside the labelled stretch: the labels start at
  the serve and stop at the point's end, the server's bounces before it are not labelled). A point whose
  labels all lie outside its ``tracked_window`` (numbered from 0 while its track starts frames later: not
  aligned with the track) is not scored, and named; the row "every point" scores them too (as before).
- ``padel_track``: ``padel_tracks_wpt2022_dev``, a hand-annotated ball on a real padel broadcast. The CSV's
  rows are one frame apart in time and 25 fps fits the ball's fall (``source_frame``'s skips are a
  numbering artefact, see :func:`padel_grid`); the README's reading (source_frame grid, 30 fps) is scored
  too. One track per point (a serve window to the stroke that ends the point), the shipped padel model,
  racket hits against the players' stroke windows (side by upper/lower team), and every event against the
  55 hand-labelled impacts (``bounce_frame`` counts rows, see :func:`padel_bounces`).
- ``tennis_clips``: ``rally3d infer`` (shipped WASB, MoveNet, event tagger, joint 3D, ``--court-points
  auto``) on the three 1080p broadcast clips: calibration, players, events, flights, the RMS of every
  written flight, the racket contacts' positions and the plausibility that the pipeline wrote.
- ``padel_still``: the Qatar broadcast frame as a short video clip and the automatic court fit (what
  ``rally3d calibrate CLIP --auto --dry-run`` runs).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("tennis_points", "padel_track", "tennis_clips", "padel_still")
#: matching tolerance of the event scores, frames (±2 at 50 fps for tennis; ±2 rows on the padel grid)
TOL = 2
HELD_OUT = 50
RUNS = ROOT / "runs" / "bench_real"


def real_root() -> Path:
    """``$RALLY3D_REAL`` or ``../shared/real`` beside the repository."""
    env = os.environ.get("RALLY3D_REAL")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "real"


# --------------------------------------------------------------------------------------------------- table
@dataclass
class Table:
    """One Markdown table for the whole run: part, row, precision, recall, F1, and the rest as text."""

    rows: list[tuple[str, str, str, str, str, str]] = field(default_factory=list)

    def add(self, part: str, row: str, p=None, r=None, f1=None, more: str = "") -> None:
        fmt = lambda v: "" if v is None else ("–" if v != v else f"{v:.3f}")  # noqa: E731
        self.rows.append((part, row, fmt(p), fmt(r), fmt(f1), more))

    def render(self) -> str:
        lines = ["| part | row | P | R | F1 | figures |", "|---|---|---|---|---|---|"]
        last = None
        for part, *rest in self.rows:
            lines.append("| " + " | ".join([part if part != last else "", *rest]) + " |")
            last = part
        return "\n".join(lines)


def prf(tp: int, n_gt: int, n_pred: int) -> tuple[float, float, float]:
    p = tp / n_pred if n_pred else float("nan")
    r = tp / n_gt if n_gt else float("nan")
    f = 2 * tp / (n_gt + n_pred) if n_gt + n_pred else float("nan")
    return p, r, f


def log(msg: str) -> None:
    print(msg, flush=True)


# --------------------------------------------------------------------------------------- tennis points
#: far-hit gap bins (frames missing around the contact): name → (shortest, longest)
FAR_GAP_BINS = {"0": (0, 0), "1-3": (1, 3), "4-12": (4, 12), "13-20": (13, 20), "21+": (21, 10 ** 9)}


def far_gaps(seen: np.ndarray, labels: np.ndarray, found: np.ndarray, bins: dict) -> None:
    """Count labelled far hits ``labels (K,)`` and those with a far-hit prediction in ``found (M,)`` within ±TOL,
    by the length of the track's gap (``seen (T,) bool``) at or within ±2 frames of the contact, into ``bins``."""
    from inference.events.gaps import gap_around

    for f in labels:
        g = gap_around(seen, int(f), reach=2)
        n = 0 if g is None else g[1] - g[0] + 1
        key = next(k for k, (lo, hi) in FAR_GAP_BINS.items() if lo <= n <= hi)
        bins[key][1] += 1
        bins[key][0] += int(np.any(np.abs(found - f) <= TOL))


def tennis_points(real: Path, table: Table, args) -> dict:
    """The shipped tennis event model on the RG2025 points' real tracker tracks, against the hand labels."""
    import torch

    from inference.clipio import Clip
    from inference.events import EventDetector
    from inference.events.detector import choose_weights
    from inference.events.metrics import EventCounts

    folder = real / "tennis_events_rg2025_dev"
    points = sorted((p for p in folder.iterdir() if (p / "clip.yaml").is_file()), key=lambda p: p.name)
    if args.limit:
        points = points[:args.limit]
    torch.set_num_threads(1)
    # as `rally3d events` on a clip without players.csv, or a candidate's file (--tennis-weights)
    weights = Path(args.tennis_weights) if args.tennis_weights else choose_weights(None, "tennis", None)
    det = EventDetector.from_checkpoint(weights, sport="tennis")
    cs = det.class_set
    held = {p.name for p in points[-HELD_OUT:]}
    keys = ("all", "held_out", "rally_only", "labelled_span", "every_point")
    counts = {k: EventCounts(cs.classes) for k in keys}
    per_point_fp_before = 0
    unaligned: list[str] = []
    serves = {"player_near": [0, 0], "player_far": [0, 0]}  # found, labelled: the point's first event, a hit
    far_by_gap = {k: [0, 0] for k in FAR_GAP_BINS}   # found, labelled: far hits by the track's gap at the contact
    for i, d in enumerate(points):
        clip = Clip(d)
        info = clip.info
        a, b = (int(v) for v in info.extra["tracked_window"])
        ball, truth = clip.read_ball(), clip.read_events()
        res = det.predict(ball, info.fps, info.width, info.height, n_frames=info.n_frames, keep_all=True)
        gm = (truth.frame >= a) & (truth.frame <= b)
        gf = truth.frame[gm]
        gc = np.array([cs.encode_label(str(e)) for e in truth.event[gm]], np.int64)
        pf = res.events.frame
        pc = np.array([cs.index(c) for c in res.coarse], np.int64)
        pm = (pf >= a) & (pf <= b)
        counts["every_point"].add(gf, gc, pf[pm], pc[pm], TOL)
        if not len(gf) and len(truth.frame):
            # every label outside the tracked window (numbered from 0, the track thousands of frames later):
            # the source's labels are not aligned with this clip, its events cannot be scored
            unaligned.append(d.name)
            continue
        counts["all"].add(gf, gc, pf[pm], pc[pm], TOL)
        if d.name in held:
            counts["held_out"].add(gf, gc, pf[pm], pc[pm], TOL)
        k = pm & res.rally.inside
        counts["rally_only"].add(gf, gc, pf[k], pc[k], TOL)
        span = pm & (pf >= gf.min() - TOL) & (pf <= gf.max() + TOL) if len(gf) else np.zeros(len(pf), bool)
        counts["labelled_span"].add(gf, gc, pf[span], pc[span], TOL)
        per_point_fp_before += int(np.sum(pm & (pf < (gf.min() - TOL if len(gf) else b + 1))))
        far_gaps(ball.dense(info.n_frames).visibility > 0, gf[gc == cs.index("player_far")],
                 pf[pm & (pc == cs.index("player_far"))], far_by_gap)
        if len(gf) and cs.classes[gc[0]] in serves:
            hit = serves[cs.classes[gc[0]]]
            hit[1] += 1
            hit[0] += int(np.any((np.abs(pf - gf[0]) <= TOL) & (pc == gc[0])))
        if (i + 1) % 50 == 0 or i + 1 == len(points):
            log(f"[tennis_points] {i + 1}/{len(points)} points")
    part = "tennis points (RG2025, real tracker)"
    out: dict = {"points": len(points), "weights": weights.name,
                 "events_before_first_label": per_point_fp_before, "unaligned_points": unaligned}
    c = counts["all"]
    for ci, name in [(None, "all events"), *[(j, n) for j, n in enumerate(cs.classes) if j]]:
        s = c.scores(ci)
        table.add(part, name, s["prec"], s["recall"], s["f1"], f"{s['n_gt']} labelled, {s['n_pred']} found")
        out[name.replace(" events", "")] = s
    for key, what in (("held_out", f"held-out: last {min(HELD_OUT, len(points))} points"),
                      ("rally_only", "diagnostic: only the model's rally (--rally-only)"),
                      ("labelled_span", "diagnostic: only inside the labelled stretch ±2"),
                      ("every_point", f"every point, the {len(unaligned)} with no label in their window too")):
        s, far = counts[key].scores(), counts[key].scores(cs.index("player_far"))
        table.add(part, what, s["prec"], s["recall"], s["f1"], f"far hits F1 {far['f1']:.3f}")
        out[key] = {"all": s, "far": far}
    for side, (found, n) in serves.items():
        table.add(part, f"serves, {side.split('_')[1]} server", r=found / n if n else float("nan"),
                  more=f"{found} of {n} found (recall; the point's first label)")
        out[f"serves_{side.split('_')[1]}"] = {"found": found, "labelled": n}
    table.add(part, "far hits by the gap at the contact", more="; ".join(
        f"{k} frames {found}/{n} found" for k, (found, n) in far_by_gap.items()) + " (missing frames within ±2 of the label)")
    out["far_by_gap"] = {k: {"found": f, "labelled": n} for k, (f, n) in far_by_gap.items()}
    table.add(part, "model / tolerance", more=f"{weights.name}, ball only (no players, no camera), "
              f"every event kept; ±{TOL} frames at 50 fps; {len(points) - len(unaligned)} of {len(points)} points "
              f"scored ({len(unaligned)} have every label outside their tracked_window, not aligned with the "
              f"track: {', '.join(unaligned) or 'none'}); {per_point_fp_before} events found before the first "
              "label (pre-serve bounces: unlabelled)")
    return out


# ---------------------------------------------------------------------------------------- padel track
@dataclass
class Stroke:
    start: int          # first row of the window
    end: int            # last row
    team: str
    category: str
    result: str
    side: str           # near (the lower team hit) or far (the upper team)


def read_wpt(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def padel_strokes(rows: list[dict], merge_gap: int = 5) -> tuple[list[Stroke], list[Stroke]]:
    """Stroke windows from the per-row ``has_shot``/``team_shot``/``category`` (runs of rows), those of one
    team and category at most ``merge_gap`` rows apart merged (one stroke labelled in pieces); windows of one
    row are returned apart (label glitches: neither scored nor held against a prediction)."""
    runs: list[Stroke] = []
    for i, r in enumerate(rows):
        if r["has_shot"] != "1":
            continue
        team = r["team_shot"]
        side = "near" if team == r["lower_team"] else "far" if team == r["upper_team"] else "?"
        last = runs[-1] if runs else None
        if last and last.team == team and last.category == r["category"] and i - last.end <= merge_gap:
            last.end = i
            last.result = r["shot_result"] or last.result
        else:
            runs.append(Stroke(i, i, team, r["category"], r["shot_result"], side))
    good = [s for s in runs if s.end > s.start]
    return good, [s for s in runs if s.end == s.start]


def padel_points(rows: list[dict], strokes: list[Stroke], lead: int, tail: int, max_jump: int = 2):
    """Row ranges ``[start, stop)`` of one point each: from ``lead`` rows before a serve window to ``tail``
    rows after the stroke that ends it (``shot_result`` 0 error or 2 winner) or before the next serve; split
    where ``source_frame`` jumps by more than ``max_jump`` (a cut)."""
    serves = [s for s in strokes if s.category == "Serve"]
    spans = []
    for k, sv in enumerate(serves):
        nxt = serves[k + 1].start if k + 1 < len(serves) else len(rows)
        inside = [s for s in strokes if sv.start <= s.start < nxt]
        ends = [s for s in inside if s.result in ("0.0", "2.0")]
        stop = min(ends[0].end + 1 + tail, nxt - lead) if ends else nxt - lead
        start = max(sv.start - lead, spans[-1][1] if spans else 0)
        if stop > start:
            spans.append((start, stop))
    sf = np.array([int(r["source_frame"]) for r in rows])
    cuts = set(np.flatnonzero(np.diff(sf) > max_jump) + 1)
    out = []
    for a, b in spans:
        edges = [a, *sorted(c for c in cuts if a < c < b), b]
        out += [(x, y) for x, y in zip(edges, edges[1:]) if y - x > 10]
    return out


def padel_grid(rows: list[dict], grid: str) -> np.ndarray:
    """(N,) frame of each row on the clip's frame grid: ``rows`` (one row a frame, the default) or
    ``source`` (``source_frame``; its skipped numbers become frames without a ball).

    Measured on the hand-annotated ball: a quadratic through 7 consecutive visible rows that contain a
    source_frame step of 2 fits with a median RMS of 1.6 px on the row grid, 2.9 px on the source_frame
    grid, and the ball moves as far across a step of 2 as across a step of 1 (median ratio 0.99): the
    skips (about every 6th number) are not missing frames. The ball's vertical acceleration, scaled by the
    players' box heights, gives about 0.02 m/row² (g at ~21–25 rows/s; 30 rows/s would need 0.011):
    25 fps, a European broadcast, is the default (``--padel-fps``)."""
    if grid == "rows":
        return np.arange(len(rows))
    sf = np.array([int(r["source_frame"]) for r in rows])
    return sf - sf[0]


def match_windows(windows: list[tuple[int, int, str]], hits: list[tuple[int, str]], tol: int,
                  side: bool) -> tuple[int, list[int]]:
    """One-to-one matches of hits ``(frame, side)`` to stroke windows ``(first, last, side)``: a hit inside a
    window widened by ``tol`` (and of its side when ``side``), closest to the window (then to its middle)
    first. Returns the number matched and the indices of the hits matched."""
    pairs = []
    for wi, (a, b, ws) in enumerate(windows):
        for hi, (f, hs) in enumerate(hits):
            if a - tol <= f <= b + tol and (not side or hs == ws):
                pairs.append((max(a - f, 0, f - b), abs(f - (a + b) / 2), wi, hi))
    pairs.sort()
    used_w, used_h = set(), set()
    for _, _, wi, hi in pairs:
        if wi not in used_w and hi not in used_h:
            used_w.add(wi)
            used_h.add(hi)
    return len(used_w), sorted(used_h)


def match_frames(truth: np.ndarray, pred: np.ndarray, tol: int) -> int:
    from inference.events.metrics import match_events

    return match_events(truth, pred, tol)


def padel_run(rows, det, grid: str, fps: float, lead_s: float, tail_s: float) -> dict:
    """The shipped padel model on every point's track; racket hits against the stroke windows, every event
    against the hand-labelled impacts. Frames are rows of the CSV (both grids are mapped back to rows)."""
    from inference.clipio import BallTrack

    W, H = 1920, 1080
    strokes, glitches = padel_strokes(rows)
    points = padel_points(rows, strokes, int(round(lead_s * fps)), int(round(tail_s * fps)))
    gframe = padel_grid(rows, grid)
    x = np.array([float(r["ball_center_x"]) if r["ball_center_x"] else np.nan for r in rows])
    y = np.array([float(r["ball_center_y"]) if r["ball_center_y"] else np.nan for r in rows])
    hits, events, n_frames_total = [], [], 0
    for a, b in points:
        g0 = int(gframe[a])
        fr = gframe[a:b] - g0                      # this point's frames
        n = int(fr[-1]) + 1
        vis = np.isfinite(x[a:b])
        xy = np.full((n, 2), np.nan)
        xy[fr[vis], 0] = np.clip(x[a:b][vis] / W, 0, 1)
        xy[fr[vis], 1] = np.clip(y[a:b][vis] / H, 0, 1)
        seen = np.isfinite(xy[:, 0])
        track = BallTrack(np.arange(n), seen.astype(np.int8), xy)
        res = det.predict(track, fps, W, H, n_frames=n, keep_all=True)
        n_frames_total += n
        row_of = {int(f): a + i for i, f in enumerate(fr)}  # clip frame → CSV row (no row: the nearest)
        keys = np.array(sorted(row_of))
        for f, c in zip(res.events.frame.tolist(), res.coarse):
            r = row_of.get(int(f))
            if r is None:
                r = row_of[int(keys[np.argmin(np.abs(keys - f))])]
            events.append((r, c))
            if c in ("player_near", "player_far"):
                hits.append((r, "near" if c == "player_near" else "far"))
    inside = lambda r: any(a <= r < b for a, b in points)  # noqa: E731
    windows = [(s.start, s.end, s.side) for s in strokes if inside(s.start)]
    # hits inside a one-row glitch window (±tol) are neither right nor wrong
    ignored = {i for i, (f, _) in enumerate(hits) if any(g.start - TOL <= f <= g.end + TOL for g in glitches)}
    tp_side, matched = match_windows(windows, hits, TOL, side=True)
    tp_any, matched_any = match_windows(windows, hits, TOL, side=False)
    n_pred = len(hits) - len(ignored - set(matched_any))
    out = {"grid": grid, "fps": fps, "points": len(points), "frames": n_frames_total,
           "rows_in_points": int(sum(b - a for a, b in points)), "strokes": len(windows),
           "strokes_near": sum(w[2] == "near" for w in windows), "glitch_windows": len(glitches),
           "hits_found": len(hits), "hits_ignored": len(ignored - set(matched_any))}
    out["side"] = dict(zip(("prec", "recall", "f1"), prf(tp_side, len(windows), n_pred)))
    out["any_side"] = dict(zip(("prec", "recall", "f1"), prf(tp_any, len(windows), n_pred)))
    for s in ("near", "far"):
        w = [v for v in windows if v[2] == s]
        h = [v for v in hits if v[1] == s]
        tp, _ = match_windows(w, h, TOL, side=True)
        out[f"side_{s}"] = dict(zip(("prec", "recall", "f1"), prf(tp, len(w), len(h))))
    others = [c for _, c in events if c not in ("player_near", "player_far")]
    out["other_events"] = {c: others.count(c) for c in sorted(set(others))}
    out["other_per_point"] = len(others) / max(len(points), 1)
    out["events"] = events
    return out


def padel_bounces(rows, events, path: Path) -> dict:
    """Every found event (any class) against the 55 hand-labelled impacts (floor, glass, fence or racket)
    inside their range, one-to-one within ±TOL rows. ``bounce_frame`` counts CSV rows (0-based, as the
    ``time`` column), not source frames: read as rows the labels sit on the track's sharp turns (median turn
    72°, 64 % within a row of the sharpest turn near them), read as source frames on none (4°, the track's
    median)."""
    with open(path, newline="") as f:
        truth = np.array([int(r["bounce_frame"]) for r in csv.DictReader(f)])
    lo, hi = int(truth.min()), int(truth.max())
    pred = np.array(sorted(r for r, _ in events if lo - TOL <= r <= hi + TOL))
    tp = match_frames(truth, pred, TOL)
    p, r, f = prf(tp, len(truth), len(pred))
    return {"impacts": len(truth), "found": len(pred), "matched": tp, "prec": p, "recall": r, "f1": f,
            "rows": [lo, hi]}


def padel_track(real: Path, table: Table, args) -> dict:
    import torch

    from inference.events import EventDetector
    from inference.events.detector import choose_weights

    folder = real / "padel_tracks_wpt2022_dev"
    rows = read_wpt(folder / "wpt2022_master_final_women_frames_0-9999.csv")
    torch.set_num_threads(1)
    weights = Path(args.padel_weights) if args.padel_weights else choose_weights(None, "padel", None)
    det = EventDetector.from_checkpoint(weights, sport="padel")
    part = "padel track (WPT2022, hand-annotated ball)"
    out = {"rows": len(rows), "weights": weights.name}
    for grid, fps, label in (("rows", args.padel_fps, "rows"),
                             ("source", 30.0, "source_frame grid @ 30 fps (the README's reading)")):
        log(f"[padel_track] grid {grid}, {fps:g} fps")
        res = padel_run(rows, det, grid, fps, args.padel_lead, args.padel_tail)
        bounces = padel_bounces(rows, res.pop("events"), folder / "bounces_hand_labelled_frames_12-922.csv")
        res["impacts"] = bounces
        out[grid] = res
        name = f"rows @ {fps:g} fps" if grid == "rows" else label
        s, a = res["side"], res["any_side"]
        table.add(part, f"racket hits, side right ({name})", s["prec"], s["recall"], s["f1"],
                  f"{res['strokes']} strokes ({res['strokes_near']} near) in {res['points']} points, "
                  f"{res['hits_found']} hits found ({res['hits_ignored']} in glitch windows, not counted)")
        table.add(part, f"racket hits, any side ({name})", a["prec"], a["recall"], a["f1"],
                  f"near hits F1 {res['side_near']['f1']:.3f}, far hits F1 {res['side_far']['f1']:.3f}")
        b = bounces
        table.add(part, f"every event vs the {b['impacts']} hand-labelled impacts ({name})", b["prec"],
                  b["recall"], b["f1"], f"{b['found']} events found in rows {b['rows'][0]}–{b['rows'][1]} "
                  f"(bounce_frame counts rows); other events per point {res['other_per_point']:.1f} "
                  f"{res['other_events']}")
    table.add(part, "model / matching", more=f"{weights.name}, ball only; a hit is right inside a stroke "
              f"window ±{TOL} rows (one hit a window), near = team_shot is lower_team; points: a serve "
              f"window −{args.padel_lead:g} s to the stroke ending the point (shot_result 0/2) + "
              f"{args.padel_tail:g} s")
    return out


# ---------------------------------------------------------------------------------------- tennis clips
def rms_limit_px() -> float:
    from inference.reconstruct.joint import JointConfig

    cfg = JointConfig()
    return float(cfg.rms_fail_factor * cfg.pixel_sigma)


def clip_figures(clip, report) -> dict:
    """What a reviewer needs of one ``rally3d infer`` run, read from the clip folder it wrote."""
    from inference.clipio import FormatError

    stages = {s.name: s for s in report.stages}
    out: dict = {"frames": clip.n_frames, "stages": {k: [s.status, round(s.seconds, 2), s.note]
                                                      for k, s in stages.items()}}
    cam = stages.get("camera")
    out["calibration"] = {"accepted": bool(cam and cam.status in ("done", "cached")),
                          "note": cam.note if cam else "not run"}
    if clip.camera_path.is_file():
        from inference.camera import Camera

        c = Camera.load(clip.camera_path)
        out["calibration"]["centre_m"] = [round(float(v), 2) for v in c.centre]
        out["calibration"]["focal_px"] = round(float(c.K[0, 0]), 1)
    # players: frames with two players or more, and with a near and a far one
    if clip.players_path.is_file():
        try:
            pl = clip.read_players(missing_ok=True)
            frames = np.asarray(pl.frame)
            teams = np.asarray(pl.team).astype(str)
            per = {}
            for f, t in zip(frames.tolist(), teams.tolist()):
                per.setdefault(f, []).append(t)
            two = sum(len(v) >= 2 for v in per.values())
            both = sum(("near" in v) and ("far" in v) for v in per.values())
            out["players"] = {"tracks": len(pl.ids()), "share_2_players": two / clip.n_frames,
                              "share_near_and_far": both / clip.n_frames,
                              **{f"share_{t}": sum(t in v for v in per.values()) / clip.n_frames
                                 for t in ("near", "far")}}
        except (FormatError, ValueError, OSError, AttributeError) as e:
            out["players"] = {"error": str(e)}
    else:
        out["players"] = {"tracks": 0, "share_2_players": 0.0, "share_near_and_far": 0.0,
                          "note": stages["players"].note if "players" in stages else ""}
    ev = clip.read_events() if clip.events_path.is_file() else None
    out["events"] = {} if ev is None else {str(e): int(np.sum(ev.event == e))
                                           for e in sorted(set(ev.event.tolist()))}
    if ev is None or not len(ev) or not clip.segments_path.is_file():
        out["reconstruct"] = {"note": stages["reconstruct"].note if "reconstruct" in stages else "not run"}
        return out
    seg = json.loads(clip.segments_path.read_text())
    b3 = clip.read_ball_3d()
    limit = seg.get("plausibility", {}).get("rms_limit_px") or rms_limit_px()  # the clip's measured 2D noise
    by_index = {}
    for s in seg["segments"]:
        by_index.setdefault(int(s["index"]), []).append(s)
    written = sorted(set(np.asarray(b3.segment).tolist()))
    flights = []
    plausible_frames = set()
    for k in written:
        ss = by_index.get(int(k), [])
        frames_k = np.asarray(b3.frame)[np.asarray(b3.segment) == k]
        rms = [s.get("reprojection_rms_px") for s in ss if s.get("reconstructed")]
        rms_v = max((r for r in rms if r is not None), default=float("nan"))
        rec = any(s.get("reconstructed") for s in ss)
        flights.append({"index": int(k), "frames": [int(frames_k.min()), int(frames_k.max())],
                        "rows": len(frames_k),
                        "rms_px": None if rms_v != rms_v else round(float(rms_v), 2), "reconstructed": rec,
                        "over_limit": bool(rms_v == rms_v and rms_v > limit),
                        "speed_kmh": [s.get("launch_speed_kmh") for s in ss if s.get("reconstructed")]})
        if rec and rms_v == rms_v and rms_v <= limit:
            plausible_frames.update(int(f) for f in frames_k)
    out["hits"] = racket_contacts(seg, clip)
    # reconstructed flights without a row of 3D (a zero-length flight, or one left with no observations)
    seg_rows = np.asarray(b3.segment)
    empty = [{"index": int(s["index"]), "frames": [s["start_frame"], s["end_frame"]],
              "n_observed": s.get("n_observed")}
             for s in seg["segments"] if s.get("reconstructed") and not np.any(seg_rows == s["index"])]
    first, last = int(ev.frame.min()), int(ev.frame.max())
    span = last - first + 1
    covered = sum(first <= f <= last for f in plausible_frames)
    any_rows = len({int(f) for f in np.asarray(b3.frame).tolist() if first <= f <= last})
    pl = seg.get("plausibility", {})
    out["reconstruct"] = {
        "flights": pl.get("flights", len(seg["segments"])), "reconstructed": pl.get("reconstructed"),
        "failed": pl.get("failed"), "failure_reasons": pl.get("failure_reasons", {}),
        "event_span": [first, last], "share_plausible_3d": covered / span if span else float("nan"),
        "share_any_3d": any_rows / span if span else float("nan"), "rms_limit_px": limit,
        "written_flights": flights, "written_over_limit": sum(f["over_limit"] for f in flights),
        "written_not_reconstructed": sum(not f["reconstructed"] for f in flights),
        "reconstructed_without_rows": empty,
        "plausible": pl.get("plausible"), "not_plausible_because": pl.get("not_plausible_because", []),
        "frames_inside_court": pl.get("frames_inside_court"), "flags": pl.get("flags", []),
        "covered_share": pl.get("covered_share"),
    }
    out["review"] = review_calls(clip)
    return out


def review_calls(clip) -> dict:
    """What the review says of the clip: line calls made, how many come from a shot whose 3D failed (must be
    0), and the banner's first words."""
    try:
        from labeler.review.shots import analyse_clip
    except ImportError as e:  # the review is an optional room of the project
        return {"error": str(e)}
    try:
        a = analyse_clip(clip)
    except Exception as e:  # noqa: BLE001 - a figure of the bench, not a crash of it
        return {"error": f"{type(e).__name__}: {e}"}
    calls = [(s, b) for s in a.shots for b in s.bounces if b.call in ("in", "out", "fault")]
    return {"shots": len(a.shots), "calls": len(calls),
            "calls_from_failed_3d": sum(bool(getattr(s, "no_3d", "")) for s, _ in calls),
            "shots_without_3d": sum(bool(getattr(s, "no_3d", "")) for s in a.shots)}


def racket_contacts(seg: dict, clip) -> list[dict]:
    """The racket contacts of the reconstructed flights (court metres): how far outside the court's lines
    (behind a baseline or beside a sideline, 0 inside) and how high; a hit the 3D fit refitted as another
    event (``segments.json`` ``refits``: a hit at the floor fitted as a bounce) is not one."""
    from inference.court import load_court

    court = load_court(clip.court_path())
    floor = np.array([p for p in court.points.values() if abs(p[2]) < 1e-9])
    lo, hi = floor[:, :2].min(axis=0), floor[:, :2].max(axis=0)
    refitted = {int(f) for f, _ in seg.get("refits") or []}
    hits = {}
    for s in seg["segments"]:
        if not s.get("reconstructed"):
            continue
        for frame, event, point in ((s["start_frame"], s.get("start_event"), s.get("start_point_m")),
                                    (s["end_frame"], s.get("end_event"), s.get("end_point_m"))):
            if event and str(event).startswith("player") and point is not None and int(frame) not in refitted:
                x, y, z = point
                hits[int(frame)] = {"frame": int(frame), "event": event,
                                    "xyz_m": [round(v, 2) for v in point],
                                    "behind_m": round(float(max(lo[1] - y, y - hi[1], 0.0)), 2),
                                    "beside_m": round(float(max(lo[0] - x, x - hi[0], 0.0)), 2),
                                    "height_m": round(float(z), 2)}
    return [hits[k] for k in sorted(hits)]


def tennis_clips(real: Path, table: Table, args) -> dict:
    from inference.pipeline import PipelineConfig, prepare, run_pipeline

    folder = real / "tennis_broadcast_clips"
    videos = sorted(folder.glob("*.mp4"))
    if args.limit:
        videos = videos[:max(1, min(args.limit, len(videos)))]
    part = "tennis clips (1080p broadcasts, rally3d infer --court-points auto)"
    out = {}
    for v in videos:
        dest = RUNS / "tennis" / v.stem
        if dest.exists() and not args.reuse:
            shutil.rmtree(dest)
        log(f"[tennis_clips] {v.name} → {dest.relative_to(ROOT)}")
        t0, w0 = time.process_time(), time.perf_counter()
        prepared = prepare(v, dest, "tennis")
        cfg = PipelineConfig(auto_court=True, device=args.device, progress=False)
        report = run_pipeline(prepared.clip, cfg, log=lambda m: log(f"[tennis_clips]   {m}"))
        fig = clip_figures(prepared.clip, report)
        fig["cpu_s"], fig["wall_s"] = time.process_time() - t0, time.perf_counter() - w0
        out[v.stem] = fig
        for line in report.table().splitlines():
            log(f"[tennis_clips]   {line}")
        cal = fig["calibration"]
        why = cal["note"]
        cal_txt = ("accepted" if cal["accepted"] else "REFUSED") + f": {why}"
        if "centre_m" in cal:
            cal_txt += f"; centre {cal['centre_m']} m, focal {cal['focal_px']} px"
        table.add(part, f"{v.stem}: calibration", more=cal_txt)
        p = fig["players"]
        pct = lambda k: f"{100 * p.get(k, 0):.0f} %"  # noqa: E731
        ptxt = (f"{p.get('tracks', 0)} tracks; 2+ players in {pct('share_2_players')} of {fig['frames']} "
                f"frames, near and far in {pct('share_near_and_far')} (a near player in {pct('share_near')}, "
                f"a far one in {pct('share_far')})" if "error" not in p else p["error"])
        if p.get("note"):
            ptxt += f" ({p['note']})"
        table.add(part, f"{v.stem}: players", more=ptxt)
        table.add(part, f"{v.stem}: events", more=f"{sum(fig['events'].values())} {fig['events']}")
        rc = fig["reconstruct"]
        if "flights" not in rc:
            table.add(part, f"{v.stem}: 3D", more=f"none: {rc.get('note', '')}")
            continue
        empty = "".join(f"; #{e['index']} (frames {e['frames'][0]}–{e['frames'][1]}, {e['n_observed']} "
                        "observed) counts as reconstructed but has no row of 3D"
                        for e in rc["reconstructed_without_rows"])
        table.add(part, f"{v.stem}: 3D flights", more=f"{rc['reconstructed']}/{rc['flights']} reconstructed, "
                  f"{rc['failed']} failed {rc['failure_reasons']}{empty}")
        over = [f for f in rc["written_flights"] if f["over_limit"]]
        rms = ", ".join(f"#{f['index']} {f['rms_px']}" + (" OVER" if f["over_limit"] else "") +
                        "".join(f" ({v:.0f} km/h)" for v in f["speed_kmh"] if v is not None) +
                        ("" if f["reconstructed"] else " (not reconstructed!)")
                        for f in rc["written_flights"])
        table.add(part, f"{v.stem}: RMS of written flights (px)",
                  more=f"{rms or 'none written'}; limit {rc['rms_limit_px']:g} px; "
                  f"{len(over)} written over the limit")
        hits = fig.get("hits", [])
        table.add(part, f"{v.stem}: racket contacts of 3D flights", more="; ".join(
            f"f{h['frame']} {h['event'].replace('player_', '')}: {h['behind_m']:g} m behind, "
            f"{h['beside_m']:g} m beside, {h['height_m']:g} m high" for h in hits) or "none")
        why = "; ".join(rc["not_plausible_because"])
        verdict = "plausible" if rc["plausible"] else f"NOT plausible ({why})"
        table.add(part, f"{v.stem}: plausibility", more=f"{100 * rc['share_plausible_3d']:.0f} % of frames "
                  f"{rc['event_span'][0]}–{rc['event_span'][1]} (first to last event) with plausible 3D "
                  f"({100 * rc['share_any_3d']:.0f} % with any row); pipeline verdict: {verdict}; frames "
                  f"inside the court {rc['frames_inside_court']}")
        rv = fig.get("review", {})
        table.add(part, f"{v.stem}: review", more=rv.get("error") or (
            f"{rv['shots']} shots, {rv['shots_without_3d']} without 3D; {rv['calls']} line calls, "
            f"{rv['calls_from_failed_3d']} from a shot without plausible 3D"))
    return out


# ----------------------------------------------------------------------------------------- padel still
def padel_still(real: Path, table: Table, args) -> dict:
    import cv2

    from inference.clipio import Clip, ClipInfo
    from inference.court import load_court
    from inference.courtfit import fit_court

    png = real / "padel_broadcast_still" / "qatar_major_2023.png"
    img = cv2.imread(str(png))
    if img is None:
        raise FileNotFoundError(f"{png}: cannot be read")
    h, w = img.shape[:2]
    dest = RUNS / "padel_still"
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    n = 5  # a short clip of the still (the fit takes the median of frames spread over the clip)
    writer = cv2.VideoWriter(str(dest / "video.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (w, h))
    for _ in range(n):
        writer.write(img)
    writer.release()
    info = ClipInfo(sport="padel", fps=25.0, width=w, height=h, video="video.mp4", n_frames=n,
                    source=f"{png.name} (bench_real: one still as a {n}-frame clip)")
    clip = Clip.create(dest, info)
    log(f"[padel_still] {png.name} {w}×{h} → {dest.relative_to(ROOT)}; automatic court fit")
    fit = fit_court(clip, load_court("padel"))
    out = {"accepted": fit.accepted, "reason": fit.reason, "summary": fit.summary(),
           "confidence": fit.confidence, "coverage": fit.coverage, "line_rms_px": fit.line_rms_px}
    part = "padel still (Qatar 2023, rally3d calibrate --auto)"
    txt = fit.summary()
    if fit.camera is not None:
        out["centre_m"] = [round(float(v), 2) for v in fit.camera.centre]
        out["focal_px"] = round(float(fit.camera.K[0, 0]), 1)
        txt += f"; camera centre {out['centre_m']} m, focal {out['focal_px']} px"
    table.add(part, "accepted" if fit.accepted else "REFUSED", more=txt)
    return out


# ------------------------------------------------------------------------------------------------ main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(PARTS), help=f"comma-separated parts ({', '.join(PARTS)})")
    ap.add_argument("--limit", type=int, default=0,
                    help="quick run: only the first N tennis points (and N clips)")
    ap.add_argument("--json", type=Path, help="also write the figures here (JSON)")
    ap.add_argument("--reuse", action="store_true", help="tennis clips: keep runs/bench_real/tennis/* and "
                    "let the pipeline reuse its cached stages (default: a fresh run)")
    ap.add_argument("--device", default="cpu", help="tennis clips: detector device")
    ap.add_argument("--tennis-weights", default=None,
                    help="tennis points: score this event model file instead of the shipped one `rally3d events` picks")
    ap.add_argument("--padel-weights", default=None,
                    help="padel track: score this event model file instead of the shipped one `rally3d events` picks")
    ap.add_argument("--padel-fps", type=float, default=25.0,
                    help="frame rate of the WPT rows (default 25: measured from the ball's fall, see docs)")
    ap.add_argument("--padel-lead", type=float, default=0.4, help="seconds of track before a serve window")
    ap.add_argument("--padel-tail", type=float, default=1.0,
                    help="seconds of track after a point's last stroke")
    args = ap.parse_args(argv)
    parts = [p.strip() for p in args.only.split(",") if p.strip()]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        ap.error(f"unknown parts {unknown}; choose from {', '.join(PARTS)}")
    real = real_root()
    if not real.is_dir():
        print(f"bench_real: skipped: no real material at {real} (set RALLY3D_REAL or put ../shared/real "
              "beside the repository)")
        return 0
    sys.path.insert(0, str(ROOT))
    os.chdir(ROOT)
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    table = Table()
    figures: dict = {"real": str(real), "commit": commit, "date": time.strftime("%Y-%m-%d"), "parts": {}}
    timing = []
    funcs = {"tennis_points": tennis_points, "padel_track": padel_track, "tennis_clips": tennis_clips,
             "padel_still": padel_still}
    for name in PARTS:
        if name not in parts:
            continue
        t0, w0 = time.process_time(), time.perf_counter()
        log(f"[{name}] start")
        try:
            figures["parts"][name] = funcs[name](real, table, args)
        except FileNotFoundError as e:
            table.add(name, "skipped", more=str(e))
            figures["parts"][name] = {"skipped": str(e)}
        cpu, wall = time.process_time() - t0, time.perf_counter() - w0
        timing.append((name, cpu, wall))
        figures["parts"].setdefault(name, {})["cpu_s"] = cpu
        figures["parts"][name]["wall_s"] = wall
        log(f"[{name}] done: CPU {cpu:.1f} s, wall {wall:.1f} s")
    print(f"\nbench_real on {real} (commit {commit}, {os.cpu_count()} CPU cores)\n")
    print(table.render())
    print("\n| part | CPU s | wall s |\n|---|---|---|")
    for name, cpu, wall in timing:
        print(f"| {name} | {cpu:.1f} | {wall:.1f} |")
    print(f"| total | {sum(t[1] for t in timing):.1f} | {sum(t[2] for t in timing):.1f} |")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=1, default=float) + "\n")
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
