"""Benchmark the default `joint` reconstruction on held-out synthetic rallies: accuracy (with exact and
jittered events), contact errors of near and far racket hits, coverage, calibration of the reported
covariance per clip, the court plausibility figures, and frames per CPU-second. Prints Markdown.

    .venv/bin/python bench/bench_joint.py [--clips 6] [--data runs/bench_3d] [--shift 0,2]

The clips are those of bench/bench_reconstruct.py (seeds 100+ padel, 200+ tennis; generated once). Inputs:
ground-truth 2D ball + Gaussian noise σ = 2 px, ground-truth events (optionally each moved by a random
integer in ±k frames), ground-truth camera, players' court positions from gt/players.csv.

Coverage: share of the frames whose 2D ball is in the image (between the first and the last such frame)
that have a reconstructed 3D position. σ coverage: share of frames whose error lies inside the 1-σ / 2-σ
ellipsoid of the reported 3×3 covariance; for a 3D Gaussian 19.9 % / 73.9 %.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.bench_reconstruct import dataset  # noqa: E402
from inference.reconstruct.evaluate import Setting, prepare  # noqa: E402
from inference.reconstruct.joint import fit_joint  # noqa: E402
from inference.reconstruct.plausibility import penetration  # noqa: E402

#: P(|x|² ≤ k²) of a 3D standard normal for k = 1, 2
GAUSS_3D = (0.1987, 0.7385)


def clip_figures(clip, setting: Setting) -> dict:
    """One clip: errors, contact errors, coverage, σ coverage, plausibility, CPU time."""
    obs, gt_frames, gt_xyz = prepare(clip, setting)
    true_events = clip.read_events()
    c0 = time.process_time()
    fit = fit_joint(obs)
    cpu = time.process_time() - c0
    b = fit.ball_3d()
    i = np.clip(np.searchsorted(gt_frames, b.frame), 0, len(gt_frames) - 1)
    has = gt_frames[i] == b.frame
    d = b.xyz[has] - gt_xyz[i[has]]
    err = np.linalg.norm(d, axis=1)
    _, cov = fit.covariances()
    cov = cov[has]
    good = np.isfinite(cov).all(axis=(1, 2))
    m2 = np.full(len(d), np.nan)
    if good.any():
        m2[good] = np.einsum("ni,nij,nj->n", d[good], np.linalg.inv(cov[good]), d[good])
    seen = np.flatnonzero(np.isfinite(obs.uv).all(axis=1))
    span = np.arange(seen[0], seen[-1] + 1) if len(seen) else np.zeros(0, int)
    in_image = span[np.isfinite(obs.uv[span]).all(axis=1)]
    covered = float(np.isin(in_image, b.frame).mean()) if len(in_image) else float("nan")
    contact = {"player_near": [], "player_far": []}
    pos = dict(zip(b.frame.tolist(), b.xyz))
    gpos = dict(zip(gt_frames.tolist(), gt_xyz))
    for f, lab in zip(true_events.frame.tolist(), true_events.event.tolist()):
        if lab in contact and f in pos and f in gpos:
            contact[lab].append(float(np.linalg.norm(pos[f] - gpos[f])))
    depth, _ = penetration(obs.court, b.xyz) if len(b) else (np.zeros(0), [])
    limit = 4.0 * 2.0
    pl = fit.extra["plausibility"]
    return {
        "name": clip.root.name, "err": err, "m2": m2[np.isfinite(m2)], "coverage": covered, "cpu": cpu,
        "frames": len(b), "near": contact["player_near"], "far": contact["player_far"],
        "inside": float(np.mean(depth <= 0.02)) if len(depth) else float("nan"),
        "below": pl["contacts_below_floor"],
        "over_rms": sum(s.ok and s.reproj_rms_px > limit for s in fit.segments),
        "failed": [s.reason for s in fit.segments if not s.ok],
        "refits": len(fit.extra.get("refits", [])),
    }


def table(rows: list[dict], title: str) -> str:
    """Per-clip rows and the pooled line, Markdown."""
    out = [title, "", "| clip | frames | MedAE m | MAE m | near hit m | far hit m | coverage | 1σ | 2σ | "
           "inside | failed | refits | frames/CPU-s |", "|" + "---|" * 13]

    def fmt(a, f=np.median):
        return f"{f(a):.3f}" if len(a) else "–"

    for r in rows:
        c1 = float(np.mean(r["m2"] <= 1)) if len(r["m2"]) else float("nan")
        c2 = float(np.mean(r["m2"] <= 4)) if len(r["m2"]) else float("nan")
        r["c1"], r["c2"] = c1, c2
        out.append(f"| {r['name']} | {r['frames']} | {fmt(r['err'])} | {fmt(r['err'], np.mean)} | {fmt(r['near'])} | "
                   f"{fmt(r['far'])} | {r['coverage']:.3f} | {c1:.2f} | {c2:.2f} | {r['inside']:.3f} | "
                   f"{len(r['failed'])} | {r['refits']} | {r['frames'] / max(r['cpu'], 1e-9):.0f} |")
    e = np.concatenate([r["err"] for r in rows])
    m2 = np.concatenate([r["m2"] for r in rows])
    near = sum((r["near"] for r in rows), [])
    far = sum((r["far"] for r in rows), [])
    frames = sum(r["frames"] for r in rows)
    cpu = sum(r["cpu"] for r in rows)
    cov = np.array([r["coverage"] for r in rows])
    out.append(f"| **all** | {frames} | **{fmt(e)}** | {fmt(e, np.mean)} | {fmt(near)} | {fmt(far)} | "
               f"{cov.min():.3f} (min) | {np.mean(m2 <= 1):.2f} | {np.mean(m2 <= 4):.2f} | "
               f"{min(r['inside'] for r in rows):.3f} (min) | {sum(len(r['failed']) for r in rows)} | "
               f"{sum(r['refits'] for r in rows)} | **{frames / cpu:.0f}** |")
    worst = max(max(abs(r["c1"] - GAUSS_3D[0]), abs(r["c2"] - GAUSS_3D[1])) for r in rows)
    out += ["", f"σ coverage per clip: worst distance from the Gaussian figures ({GAUSS_3D[0]:.0%} / "
            f"{GAUSS_3D[1]:.0%}) {worst * 100:.0f} points. Contacts below the floor: "
            f"{sum(r['below'] for r in rows)}; reconstructed flights with RMS > 4 × σ: "
            f"{sum(r['over_rms'] for r in rows)}."]
    reasons = [f"{r['name']}: {x}" for r in rows for x in r["failed"]]
    if reasons:
        out += ["", "Failed flights:", *[f"- {x}" for x in reasons]]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=6, help="clips per sport (default 6)")
    ap.add_argument("--data", type=Path, default=Path("runs/bench_3d"))
    ap.add_argument("--shift", default="0,2", help="event jitter ±k frames to run (default 0,2)")
    ap.add_argument("--sports", default="padel,tennis")
    args = ap.parse_args()
    for sport in args.sports.split(","):
        clips = dataset(args.data, sport, args.clips)
        for k in (int(x) for x in args.shift.split(",")):
            setting = Setting(noise_px=2.0, players="gt", event_shift=k, seed=1)
            rows = [clip_figures(c, setting) for c in clips]
            print(table(rows, f"\n## {sport}: {len(clips)} held-out clips, {setting.label()}\n"), flush=True)


if __name__ == "__main__":
    main()
