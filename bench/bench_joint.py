"""Benchmark the default `joint` reconstruction on held-out synthetic rallies: accuracy (with exact and
jittered events), contact errors of near and far racket hits, coverage, calibration of the reported
covariance per clip, the court plausibility figures, and frames per CPU-second. Prints Markdown.

    .venv/bin/python bench/bench_joint.py [--clips 6] [--data runs/bench_3d] [--shift 0,2]
    .venv/bin/python bench/bench_joint.py --calibrate [--clips 16] [--draws 2] [--data runs/calib_3d]
    .venv/bin/python bench/bench_joint.py --draws 8      # each clip's σ coverage over 8 noise draws
    .venv/bin/python bench/bench_joint.py --draws 4 --camera clicked   # ... with a camera from noisy clicks

The clips are those of bench/bench_reconstruct.py (seeds 100+ padel, 200+ tennis; generated once). Inputs:
ground-truth 2D ball + Gaussian noise σ = 2 px, ground-truth events (optionally each moved by a random
integer in ±k frames), ground-truth camera, players' court positions from gt/players.csv.

Coverage: share of the frames whose 2D ball is in the image (between the first and the last such frame)
that have a reconstructed 3D position. σ coverage: share of frames whose error lies inside the 1-σ / 2-σ
ellipsoid of the reported 3×3 covariance; for a 3D Gaussian 19.9 % / 73.9 %. Oracle: the 5–95 % band of a
clip's σ coverage when its errors are drawn from the fit's own joint error model (frames of one flight
share their draw), i.e. what a perfectly calibrated covariance would show on that clip.

Per direction: the share of errors within 1 σ / 2 σ of the covariance's marginal σ along each frame's line
of sight and across it (68.3 % / 95.4 % for a Gaussian in either direction): an ellipsoid coverage near the
Gaussian figures can hide a σ too wide along the ray and too narrow across it.

``--calibrate`` fits the court YAML's ``uncertainty`` (scale, width along the ray apart from across it,
along-ray model error between contacts and on free ends, floor, per-flight residual inflation) per sport on
clips of other seeds (300+ padel, 400+ tennis: never the benchmark's; ``--clips 16 --draws 2`` for the shipped
values), by the distance of the ellipsoid and per-direction coverage, over all frames, from the Gaussian
figures in the worse of the two event settings, and prints the values to put in conf/court/*.yaml.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.bench_reconstruct import dataset  # noqa: E402
from inference.court import load_court  # noqa: E402
from inference.reconstruct.evaluate import GAUSS_1D, Setting, direction_coverage, prepare  # noqa: E402
from inference.reconstruct.joint import JointConfig, fit_joint  # noqa: E402
from inference.reconstruct.plausibility import penetration  # noqa: E402
from inference.reconstruct.shooting import Uncertainty  # noqa: E402

#: P(|x|² ≤ k²) of a 3D standard normal for k = 1, 2
GAUSS_3D = (0.1987, 0.7385)


#: calibration clips' seeds (the benchmark's are 100 / 200)
CALIBRATION_SEEDS = {"padel": 300, "tennis": 400}
#: error draws per clip of the oracle check (0: none)
ORACLE_DRAWS = 400
#: the raw Gauss-Newton covariance (what --calibrate scales)
RAW = Uncertainty(scale=1.0, model_m_per_s=0.0, floor_m=0.0)


def clip_figures(clip, setting: Setting, uncertainty: Uncertainty | None = None, oracle: int = ORACLE_DRAWS) -> dict:
    """One clip: errors, contact errors, coverage, σ coverage and its oracle band, plausibility, CPU time (and,
    for calibration, the error vectors, covariances, lines of sight and times from the nearest event)."""
    obs, gt_frames, gt_xyz = prepare(clip, setting)
    true_events = clip.read_events()
    c0 = time.process_time()
    fit = fit_joint(obs, JointConfig(uncertainty=uncertainty))
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
    band = oracle_band(fit.error_model, b.frame[has][good], cov[good], oracle) if oracle else None
    depth, _ = penetration(obs.court, b.xyz) if len(b) else (np.zeros(0), [])
    limit = 4.0 * 2.0
    pl = fit.extra["plausibility"]
    return {
        "name": clip.root.name, "shift": setting.event_shift, "err": err, "m2": m2[np.isfinite(m2)],
        "coverage": covered, "cpu": cpu,
        "frames": len(b), "near": contact["player_near"], "far": contact["player_far"],
        "inside": float(np.mean(depth <= 0.02)) if len(depth) else float("nan"),
        "below": pl["contacts_below_floor"],
        "over_rms": sum(s.ok and s.reproj_rms_px > limit for s in fit.segments),
        "failed": [s.reason for s in fit.segments if not s.ok],
        "refits": len(fit.extra.get("refits", [])), "band": band,
        "d": d[good], "cov": cov[good], **_frame_terms(fit.error_model, b.frame[has][good]),
    }


def oracle_band(em, frames: np.ndarray, cov: np.ndarray, n: int, seed: int = 0) -> np.ndarray | None:
    """(3, 2): the 5 % and 95 % quantiles (rows 0, 1) of the 1-σ / 2-σ coverage (columns) of ``frames``, and
    (row 2, both columns) the share of draws within 10 points of the Gaussian figures, when the errors are drawn from the fit's own joint error model (:class:`~inference.reconstruct.shooting.FrameErrorModel`:
    frames of one flight share their draw of θ and of the model error), i.e. what a perfectly calibrated
    covariance with this correlation structure gives on this clip. ``cov``: the reported (F, 3, 3)."""
    if em is None or not len(frames):
        return None
    draws = em.draw(n, np.random.default_rng(seed))[:, frames - em.frames[0]]     # (n, F, 3)
    m2 = np.einsum("sni,nij,snj->sn", draws, np.linalg.inv(cov), draws)
    c = np.stack([np.mean(m2 <= 1, axis=1), np.mean(m2 <= 4, axis=1)], axis=1)    # (n, 2)
    within = np.mean(np.abs(c - np.array(GAUSS_3D)).max(axis=1) <= 0.10)
    return np.vstack([np.quantile(c, [0.05, 0.95], axis=0), [within, within]])


def _frame_terms(em, frames: np.ndarray) -> dict:
    """The calibration's per-frame inputs at ``frames``: line of sight, time from the nearest contact, free end."""
    if em is None:
        z = np.zeros(len(frames))
        return {"ray": np.zeros((len(frames), 3)), "dt": z, "free": z.astype(bool), "own": z.astype(int), "chi2": z + 1}
    k = frames - em.frames[0]
    return {"ray": em.ray[k], "dt": em.dt[k], "free": em.free[k], "own": em.own[k], "chi2": em.flight_chi2[em.own[k]]}


#: the Gaussian figures of :func:`coverage_per_clip`'s columns
GAUSS_ALL = np.array([*GAUSS_3D, *GAUSS_1D, *GAUSS_1D])


def calibrated(r: dict, u: Uncertainty) -> np.ndarray:
    """(F, 3, 3) a clip's raw covariances (``r`` from :func:`clip_figures` with :data:`RAW`) calibrated by ``u``
    as :func:`inference.reconstruct.shooting.frame_error_model` calibrates them."""
    rr = np.einsum("ni,nj->nij", r["ray"], r["ray"])
    model = ((u.along_ray_rate(r["free"]) * r["dt"]) ** 2)[:, None, None] * rr
    k = u.flight_factor(r["chi2"])[:, None, None]
    S = u.shape(r["ray"])
    return k * (u.scale**2 * S @ r["cov"] @ S + model) + u.floor_m**2 * np.eye(3)


def coverage_figures(d: np.ndarray, C: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """(6,) of errors ``d`` (F, 3) against covariances ``C`` (F, 3, 3): the 1-σ and 2-σ ellipsoid coverage, and
    the 1-σ and 2-σ marginal coverage along the lines of sight ``ray`` (F, 3) and across them (:data:`GAUSS_ALL`
    when calibrated)."""
    m2 = np.einsum("ni,nij,nj->n", d, np.linalg.inv(C), d)
    c = direction_coverage(d, C, ray)
    return np.array([np.mean(m2 <= 1), np.mean(m2 <= 4), *c["along"], *c["across"]])


def coverage_per_clip(rows: list[dict], u: Uncertainty) -> np.ndarray:
    """(clips, 6) :func:`coverage_figures` of each clip's covariances calibrated by ``u`` (:func:`calibrated`)."""
    return np.array([coverage_figures(r["d"], calibrated(r, u), r["ray"]) for r in rows])


def pooled_coverage(rows: list[dict], u: Uncertainty) -> np.ndarray:
    """(6,) as :func:`coverage_per_clip`, over the frames of all ``rows`` together."""
    return coverage_figures(np.concatenate([r["d"] for r in rows]), np.concatenate([calibrated(r, u) for r in rows]),
                            np.concatenate([r["ray"] for r in rows]))


def calibrate(rows: list[dict]) -> tuple[Uncertainty, float]:
    """The :class:`Uncertainty` on a grid (scale, along_scale, model_m_per_s, free_end_m_per_s ≥ it,
    residual_power; then floor_m) whose figures — the 1-σ / 2-σ ellipsoid coverage and the 1-σ / 2-σ
    coverage along and across the line of sight, over the frames of all clips — lie closest to the Gaussian
    ones in the worst event setting (``rows``' ``shift``: exact and jittered events alike); and that
    distance."""
    groups = [[r for r in rows if r["shift"] == k] for k in sorted({r["shift"] for r in rows})]

    def score(u: Uncertainty) -> float:
        return max(float(np.abs(pooled_coverage(g, u) - GAUSS_ALL).max()) for g in groups)

    best = (np.inf, Uncertainty())
    rates = (0.0, 0.1, 0.2, 0.3, 0.5)
    for scale in (0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0):
        for along in (0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0):
            for model in rates:
                for free in (x for x in rates + (1.0, 2.0, 5.0) if x >= model):   # a free end: one end pinned
                    for power in (0.0, 1.0, 2.0):
                        u = Uncertainty(scale, model, 0.001, free, power, along)
                        best = min(best, (score(u), u), key=lambda b: b[0])
    for floor in (0.0, 0.003):
        u = replace(best[1], floor_m=floor)
        best = min(best, (score(u), u), key=lambda b: b[0])
    return best[1], best[0]


def table(rows: list[dict], title: str) -> str:
    """Per-clip rows and the pooled line, Markdown."""
    out = [title, "", "| clip | frames | MedAE m | MAE m | near hit m | far hit m | coverage | 1σ | 2σ | "
           "1σ oracle 5–95 % | 2σ oracle 5–95 % | P(oracle ≤ 10 pt) | inside | failed | refits | frames/CPU-s |", "|" + "---|" * 16]

    def fmt(a, f=np.median):
        return f"{f(a):.3f}" if len(a) else "–"

    for r in rows:
        c1 = float(np.mean(r["m2"] <= 1)) if len(r["m2"]) else float("nan")
        c2 = float(np.mean(r["m2"] <= 4)) if len(r["m2"]) else float("nan")
        r["c1"], r["c2"] = c1, c2
        bd = r.get("band")
        o1, o2 = (f"{bd[0, k]:.2f}–{bd[1, k]:.2f}" if bd is not None else "–" for k in (0, 1))
        p10 = f"{bd[2, 0]:.2f}" if bd is not None else "–"
        out.append(f"| {r['name']} | {r['frames']} | {fmt(r['err'])} | {fmt(r['err'], np.mean)} | {fmt(r['near'])} | "
                   f"{fmt(r['far'])} | {r['coverage']:.3f} | {c1:.2f} | {c2:.2f} | {o1} | {o2} | {p10} | {r['inside']:.3f} | "
                   f"{len(r['failed'])} | {r['refits']} | {r['frames'] / max(r['cpu'], 1e-9):.0f} |")
    e = np.concatenate([r["err"] for r in rows])
    m2 = np.concatenate([r["m2"] for r in rows])
    near = sum((r["near"] for r in rows), [])
    far = sum((r["far"] for r in rows), [])
    frames = sum(r["frames"] for r in rows)
    cpu = sum(r["cpu"] for r in rows)
    cov = np.array([r["coverage"] for r in rows])
    out.append(f"| **all** | {frames} | **{fmt(e)}** | {fmt(e, np.mean)} | {fmt(near)} | {fmt(far)} | "
               f"{cov.min():.3f} (min) | {np.mean(m2 <= 1):.2f} | {np.mean(m2 <= 4):.2f} | | | | "
               f"{min(r['inside'] for r in rows):.3f} (min) | {sum(len(r['failed']) for r in rows)} | "
               f"{sum(r['refits'] for r in rows)} | **{frames / cpu:.0f}** |")
    dist = [max(abs(r["c1"] - GAUSS_3D[0]), abs(r["c2"] - GAUSS_3D[1])) for r in rows]
    worst = max(dist)
    banded = [r for r in rows if r.get("band") is not None]
    outside = [r["name"] for r in banded
               if not all(r["band"][0, k] - 0.005 <= r[c] <= r["band"][1, k] + 0.005 for k, c in ((0, "c1"), (1, "c2")))]
    expected = sum(r["band"][2, 0] for r in banded)
    out += ["", f"σ coverage per clip: worst distance from the Gaussian figures ({GAUSS_3D[0]:.0%} / "
            f"{GAUSS_3D[1]:.0%}) {worst * 100:.0f} points; within 10 points: {sum(x <= 0.10 for x in dist)} / "
            f"{len(rows)} clips (a perfectly calibrated covariance: {expected:.1f} expected); outside their oracle "
            f"5–95 % band: {len(outside)} / {len(banded)}"
            f"{' (' + ', '.join(outside) + ')' if outside else ''}. Contacts below the floor: "
            f"{sum(r['below'] for r in rows)}; reconstructed flights with RMS > 4 × σ: "
            f"{sum(r['over_rms'] for r in rows)}."]
    out += ["", direction_table(rows)]
    reasons = [f"{r['name']}: {x}" for r in rows for x in r["failed"]]
    if reasons:
        out += ["", "Failed flights:", *[f"- {x}" for x in reasons]]
    return "\n".join(out)


def direction_table(rows: list[dict]) -> str:
    """Per clip and over every frame of the clips: the share of errors within the 1-σ / 2-σ ellipsoid of the
    reported covariance, and within 1 σ / 2 σ of its marginal σ along the line of sight and across it (a
    calibrated covariance: 19.9 % / 73.9 %, and 68.3 % / 95.4 % in either direction), Markdown."""
    out = [f"Ellipsoid (Gaussian {GAUSS_3D[0]:.1%} / {GAUSS_3D[1]:.1%}) and per direction (marginal σ; Gaussian "
           f"{GAUSS_1D[0]:.1%} / {GAUSS_1D[1]:.1%}):", "",
           "| clip | ellipsoid 1σ | ellipsoid 2σ | along 1σ | along 2σ | across 1σ | across 2σ | worst points off |",
           "|---|---|---|---|---|---|---|---|"]
    for name, d, cov, ray in [(r["name"], r["d"], r["cov"], r["ray"]) for r in rows] + [
            ("**all frames**", *(np.concatenate([r[k] for r in rows]) for k in ("d", "cov", "ray")))]:
        got = coverage_figures(d, cov, ray)
        off = np.abs(got - GAUSS_ALL).max()
        out.append("| " + " | ".join([name, *(f"{x:.2f}" for x in got), f"{100 * off:.0f}"]) + " |")
    return "\n".join(out)


def draws_table(clips, sport: str, shift: int, n: int, camera: str = "gt") -> str:
    """σ coverage of each clip over ``n`` draws of the 2D noise (and of the event jitter): per draw (its range)
    and pooled over the draws, Markdown. One draw's coverage rests on a few flights (their frames share one
    depth error); pooled over draws it says whether the covariance fits *this clip's* geometry."""
    out = [f"\n## {sport}: σ coverage per clip over {n} noise draws (events ±{shift}, camera {camera})\n",
           "| clip | frames | 1σ per draw (min–max) | 2σ per draw (min–max) | 1σ over the draws | 2σ over the draws | "
           "distance, points |", "|" + "---|" * 7]
    dist, pooled = [], []
    for clip in clips:
        figs = [clip_figures(clip, Setting(noise_px=2.0, players="gt", event_shift=shift, seed=1 + j, camera=camera),
                             oracle=0) for j in range(n)]
        m2s = [f["m2"] for f in figs]
        pooled.append({"name": clip.root.name, **{k: np.concatenate([f[k] for f in figs]) for k in ("d", "cov", "ray")}})
        c = np.array([(np.mean(m <= 1), np.mean(m <= 4)) for m in m2s if len(m)])
        m2 = np.concatenate(m2s)
        p1, p2 = float(np.mean(m2 <= 1)), float(np.mean(m2 <= 4))
        d = max(abs(p1 - GAUSS_3D[0]), abs(p2 - GAUSS_3D[1]))
        dist.append(d)
        out.append(f"| {clip.root.name} | {len(m2s[0])} | {c[:, 0].min():.2f}–{c[:, 0].max():.2f} | "
                   f"{c[:, 1].min():.2f}–{c[:, 1].max():.2f} | {p1:.2f} | {p2:.2f} | {100 * d:.0f} |")
    out += ["", f"Over {n} draws: {sum(x <= 0.10 for x in dist)} / {len(clips)} clips within 10 points of the Gaussian "
            f"figures ({GAUSS_3D[0]:.0%} / {GAUSS_3D[1]:.0%}); worst {100 * max(dist):.0f} points.", "",
            direction_table(pooled)]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=6, help="clips per sport (default 6)")
    ap.add_argument("--data", type=Path, default=Path("runs/bench_3d"))
    ap.add_argument("--shift", default="0,2", help="event jitter ±k frames to run (default 0,2)")
    ap.add_argument("--sports", default="padel,tennis")
    ap.add_argument("--draws", type=int, default=0,
                    help="instead of the accuracy tables: each clip's σ coverage over this many noise draws")
    ap.add_argument("--camera", choices=("gt", "clicked"), default="gt",
                    help="the true camera (default) or one calibrated from the clip's court clicks, ±1 px, whose "
                         "pose uncertainty the covariance then includes")
    ap.add_argument("--calibrate", action="store_true",
                    help="fit the court YAMLs' `uncertainty` on seeds 300/400")
    args = ap.parse_args()
    if args.calibrate:
        run_calibration(args)
        return
    for sport in args.sports.split(","):
        clips = dataset(args.data, sport, args.clips)
        for k in (int(x) for x in args.shift.split(",")):
            if args.draws:
                print(draws_table(clips, sport, k, args.draws, args.camera), flush=True)
                continue
            setting = Setting(noise_px=2.0, players="gt", event_shift=k, seed=1, camera=args.camera)
            rows = [clip_figures(c, setting) for c in clips]
            print(table(rows, f"\n## {sport}: {len(clips)} held-out clips, {setting.label()}\n"), flush=True)


def run_calibration(args) -> None:
    from bench import bench_reconstruct

    data = args.data if args.data != Path("runs/bench_3d") else Path("runs/calib_3d")
    bench_reconstruct.SEEDS.update(CALIBRATION_SEEDS)       # dataset() generates with these seeds
    for sport in args.sports.split(","):
        clips = dataset(data, sport, args.clips)
        rows = []
        for k in (int(x) for x in args.shift.split(",")):
            for j in range(max(args.draws, 1)):          # --draws: noise draws per clip and shift (default 1)
                setting = Setting(noise_px=2.0, players="gt", event_shift=k, seed=1 + j)
                rows += [clip_figures(c, setting, RAW, oracle=0) for c in clips]
        u, _ = calibrate(rows)
        print(f"{sport}: {len(rows)} clip runs; per-clip distance from the Gaussian figures, every figure (mean / "
              f"worst / clips within 10 points):", flush=True)
        for name, v in (("uncalibrated (scale 1, floor 3 mm)", Uncertainty()),
                        ("the court YAML's now", Uncertainty.from_court(load_court(sport))), ("calibrated", u)):
            dev = np.abs(coverage_per_clip(rows, v) - GAUSS_ALL).max(axis=1)
            pool = "; ".join(f"±{k}: " + " / ".join(f"{x:.2f}" for x in pooled_coverage(
                [r for r in rows if r["shift"] == k], v)) for k in sorted({r["shift"] for r in rows}))
            print(f"  {name}: {dev.mean() * 100:.1f} / {dev.max() * 100:.0f} points, {(dev <= 0.10).sum()} / "
                  f"{len(dev)}; all frames per event setting (ellipsoid 1σ / 2σ, along 1σ / 2σ, across 1σ / 2σ): "
                  f"{pool}")
        print(f"  uncertainty: {{scale: {u.scale:g}, along_scale: {u.along_scale:g}, model_m_per_s: "
              f"{u.model_m_per_s:g}, free_end_m_per_s: {u.free_end_m_per_s:g}, floor_m: {u.floor_m:g}, "
              f"residual_power: {u.residual_power:g}}}", flush=True)

if __name__ == "__main__":
    main()
