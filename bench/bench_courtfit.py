"""Benchmark the automatic court fit (``rally3d calibrate CLIP --auto``) on random synthetic views. Markdown.

    .venv/bin/python bench/bench_courtfit.py [--cameras 20] [--seed 500] [--frames 9] [--size 1920x1080]

Per sport, ``--cameras`` random scenes (seeds from ``--seed``) in the randomised look: venue, players and
ball in play, lighting, sensor noise, lens blur, JPEG, and half of the cameras with mild radial distortion.
Padel alternates the ``padel_broadcast`` and ``padel_installed`` presets, tennis ``tennis_broadcast`` and
``tennis_high``; ``padel_tour`` is padel at a tour event as broadcast (``SynthConfig(venue="tour")``: bright
rails and posts, the court's outline unpainted and the glass on bright base profiles, floor logos, a score
box, an advertising board that may hide the near baseline), alternating the ``padel_tv`` and
``padel_broadcast`` presets. The fit sees the median of ``--frames`` frames spread over the rally, as on a
clip. Sport k of ``--sports`` takes the seeds from ``--seed`` + 1000 k.

Figures per sport: the share of fits the gate accepts (success rate); of those, the camera-centre error (m),
the focal error (%) and the reprojection RMS (px), against the ground truth, of those of the 12 floor
points most users click that are in view; accepted fits that are wrong (centre error > 0.3 m or focal error > 3 %: the gate let a bad
fit through); and the CPU time of the fit per clip (line detection, search and refinement, without the
frame decoding; rendering the frames is not counted either).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from inference.courtfit.fit import N_FRAMES, fit_court_frames, sample_frame_indices
from synth.generate import SynthConfig, SynthScene

from bench_calibration import FLOOR_12, GOALS, error_cells, goals_text  # noqa: E402  (bench/ is on the path)

PRESETS = {"padel": ("padel_broadcast", "padel_installed"), "tennis": ("tennis_broadcast", "tennis_high"),
           "padel_tour": ("padel_tv", "padel_broadcast")}
VENUE = {"padel_tour": ("padel", "tour")}  # bench row → (sport, SynthConfig.venue); others: the club look


def run_sport(sport: str, n: int, seed: int, n_frames: int, size: tuple[int, int] | None,
              verbose: bool) -> dict:
    rows = []
    for k in range(n):
        preset = PRESETS[sport][k % 2]
        court_sport, venue = VENUE.get(sport, (sport, "club"))
        cfg = SynthConfig(sport=court_sport, camera=preset, venue=venue)
        if size:
            cfg = replace(cfg, width=size[0], height=size[1])
        scene = SynthScene.build(seed + k, cfg)
        idx = sample_frame_indices(scene.rally.n_frames, n_frames)
        frames = [scene.frame(i)[0] for i in idx]
        t0 = time.process_time()
        fit = fit_court_frames(frames, scene.court, frame_indices=idx)
        cpu = time.process_time() - t0
        gt = scene.camera
        row = {"preset": preset, "accepted": fit.accepted, "cpu": cpu, "confidence": fit.confidence,
               "reason": fit.reason}
        if fit.camera is not None:
            pts = scene.court.point_array(FLOOR_12)
            px = gt.project(pts)
            pts = pts[((px >= 0) & (px <= np.array(gt.image_size))).all(1)]  # the points in view
            row["centre"] = float(np.linalg.norm(fit.camera.centre - gt.centre))
            row["focal"] = 100 * abs(fit.camera.K[0, 0] / gt.K[0, 0] - 1)
            row["rms"] = float(np.sqrt(np.mean(np.sum((fit.camera.project(pts) - gt.project(pts)) ** 2, 1))))
        rows.append(row)
        if verbose:
            print(f"  {sport} seed {seed + k} {preset} {gt.image_size[0]}x{gt.image_size[1]} "
                  f"dist={'yes' if gt.dist is not None else 'no'}: accepted={fit.accepted} "
                  f"centre {row.get('centre', float('nan')):.3f} m focal {row.get('focal', float('nan')):.2f} % "
                  f"rms {row.get('rms', float('nan')):.2f} px cpu {cpu:.2f} s {fit.reason}", flush=True)
    return summarise(rows)


def summarise(rows: list[dict]) -> dict:
    acc = [r for r in rows if r["accepted"]]
    good = [r for r in acc if r["centre"] <= GOALS["centre_m"] and r["focal"] <= GOALS["focal_pct"]
            and r["rms"] <= GOALS["rms_px"]]
    cpu = np.array([r["cpu"] for r in rows])
    return {"n": len(rows), "accepted": len(acc), "good": len(good), "wrong": len(acc) - len(good),
            **{k: [r[k] for r in acc] for k in ("centre", "focal", "rms")},
            "cpu_med": float(np.median(cpu)), "cpu_max": float(cpu.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cameras", type=int, default=20, help="scenes per sport (default 20)")
    ap.add_argument("--seed", type=int, default=500)
    ap.add_argument("--frames", type=int, default=N_FRAMES, help=f"frames per fit (default {N_FRAMES})")
    ap.add_argument("--size", help="fix the resolution, e.g. 1920x1080 (default: drawn per scene)")
    ap.add_argument("--sports", default="padel,tennis,padel_tour",
                    help="bench rows: padel, tennis, padel_tour (default: all three)")
    ap.add_argument("-v", "--verbose", action="store_true", help="one line per scene")
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x")) if args.size else None
    print("| sport | scenes | accepted (success) | accepted and within goals | accepted but wrong | "
          "centre err m (median / max) | focal err % (median / max) | RMS px (median / max) | CPU s per clip "
          "(median / max) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k, sport in enumerate(args.sports.split(",")):
        m = run_sport(sport, args.cameras, args.seed + 1000 * k, args.frames, size, args.verbose)
        print(f"| {sport} | {m['n']} | {m['accepted']} ({100 * m['accepted'] / m['n']:.0f} %) | {m['good']} | "
              f"{m['wrong']} | {error_cells(m)} | {m['cpu_med']:.2f} / {m['cpu_max']:.2f} |", flush=True)
    print(goals_text("RMS of the 12 floor points in view", "success goal ≥ 90 %; CPU goal < 5 s per clip"))


if __name__ == "__main__":
    main()
