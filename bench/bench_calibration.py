"""Benchmark the calibration from clicked floor points on random broadcast-like cameras. Prints Markdown.

    .venv/bin/python bench/bench_calibration.py [--cameras 25] [--seed 300]

Per sport, ``--cameras`` random cameras from the broadcast presets (``padel_broadcast``, ``tennis_broadcast``,
``tennis_high``; position, aim and roll jittered, 1920×1080) see the 12 floor points most users have (the four
corners, the six service-line points, the two net ends on the floor), clicked with 1–2 px of noise (a
uniform radius in [1, 2] px in a random direction). Rows: without lens distortion; with the presets' mild
radial distortion fitted (``n_dist=1``); and, for comparison, the same floor points plus the three net-top
points calibrated the old way (a free principal point). Figures: the camera-centre error (m), the focal
error (%), the reprojection RMS on the clicks (px), the share of cameras meeting all three goals
(centre ≤ 0.3 m, focal ≤ 3 %, RMS ≤ 2 px) and the CPU time per calibration.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from inference.camera.calibration import CalibrationError, calibrate_court
from inference.camera import Camera
from inference.court import load_court
from synth.cameras import CameraSpec

FLOOR_12 = ["near_left", "near_right", "far_left", "far_right", "near_service_left", "near_service_center",
            "near_service_right", "far_service_left", "far_service_center", "far_service_right", "net_left",
            "net_right"]
NET_TOPS = {"padel": ["net_post_left_top", "net_center_top", "net_post_right_top"],
            "tennis": ["net_post_left_top", "net_center_top", "net_post_right_top"]}
PRESETS = {"padel": ["padel_broadcast"], "tennis": ["tennis_broadcast", "tennis_high"]}
GOALS = {"centre_m": 0.3, "focal_pct": 3.0, "rms_px": 2.0}


def random_cameras(sport: str, n: int, seed: int, distortion: bool) -> list[Camera]:
    """``n`` random 1080p broadcast-like ground-truth cameras of ``sport``."""
    court = load_court(sport)
    rng = np.random.default_rng(seed)
    cams = []
    while len(cams) < n:
        preset = PRESETS[sport][len(cams) % len(PRESETS[sport])]
        spec = CameraSpec.preset(preset).randomised(rng, jitter_m=1.0, distortion=distortion)
        spec = replace(spec, width=1920, height=1080)
        if distortion and spec.dist is None:
            spec = replace(spec, dist=(float(rng.uniform(-0.15, -0.03)), 0.0, 0.0, 0.0, 0.0))
        cams.append(spec.build(court))
    return cams


def clicks(cam: Camera, court, names: list[str], rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Projected points with a 1–2 px error each, in a random direction."""
    px = cam.project(court.point_array(names))
    ang = rng.uniform(0, 2 * np.pi, len(names))
    rad = rng.uniform(1.0, 2.0, len(names))
    return {n: p + r * np.array([np.cos(a), np.sin(a)]) for n, p, r, a in zip(names, px, rad, ang)}


def run_row(sport: str, cams: list[Camera], names: list[str], seed: int, **kw) -> dict:
    court = load_court(sport)
    rng = np.random.default_rng(seed)
    errs, foc, rms, pp, cpu, fails = [], [], [], [], [], 0
    for cam in cams:
        pts = clicks(cam, court, names, rng)
        t0 = time.process_time()
        try:
            res = calibrate_court(court, pts, cam.image_size, **kw)
        except CalibrationError:
            fails += 1
            continue
        cpu.append(time.process_time() - t0)
        errs.append(float(np.linalg.norm(res.camera.centre - cam.centre)))
        foc.append(100 * abs(res.camera.K[0, 0] / cam.K[0, 0] - 1))
        rms.append(res.rms_px)
        pp.append(float(np.linalg.norm(res.camera.K[:2, 2] - cam.K[:2, 2])))
    e, f, r = np.array(errs), np.array(foc), np.array(rms)
    ok = (e <= GOALS["centre_m"]) & (f <= GOALS["focal_pct"]) & (r <= GOALS["rms_px"])
    return {"n": len(cams), "fails": fails, "centre": e, "focal": f, "rms": r, "pp_max": max(pp),
            "meets": int(ok.sum()), "cpu_ms": 1000 * np.mean(cpu)}


def error_cells(m: dict) -> str:
    """``centre | focal | RMS`` table cells, each ``median / max``."""
    c, f, r = (np.asarray(m[k], float) for k in ("centre", "focal", "rms"))
    if not len(c):
        return "- | - | -"
    return (f"{np.median(c):.3f} / {c.max():.3f} | {np.median(f):.2f} / {f.max():.2f} | "
            f"{np.median(r):.2f} / {r.max():.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cameras", type=int, default=25, help="random cameras per sport (default 25)")
    ap.add_argument("--seed", type=int, default=300)
    args = ap.parse_args()
    print("| sport | setting | cameras | failed | centre err m (median / max) | focal err % (median / max) | "
          "RMS px (median / max) | principal point off px (max) | meet all goals | CPU ms |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for k, sport in enumerate(("padel", "tennis")):
        plain = random_cameras(sport, args.cameras, args.seed + 10 * k, distortion=False)
        dist = random_cameras(sport, args.cameras, args.seed + 10 * k + 1, distortion=True)
        rows = [("12 floor points", plain, FLOOR_12, {}),
                ("12 floor points, lens k1 fitted", dist, FLOOR_12, {"n_dist": 1}),
                ("12 floor + 3 net tops, prior (default)", plain, FLOOR_12 + NET_TOPS[sport], {}),
                ("12 floor + 3 net tops, free principal point (old)", plain, FLOOR_12 + NET_TOPS[sport],
                 {"principal_point": "free"})]
        for label, cams, names, kw in rows:
            m = run_row(sport, cams, names, args.seed + 100 + k, **kw)
            print(f"| {sport} | {label} | {m['n']} | {m['fails']} | {error_cells(m)} | {m['pp_max']:.0f} | "
                  f"{m['meets']}/{m['n'] - m['fails']} | {m['cpu_ms']:.0f} |", flush=True)
    print(goals_text("RMS", "clicks off by 1–2 px; 1920×1080"))


def goals_text(rms_of: str, extra: str) -> str:
    """The line under a table that states the goals."""
    return (f"\nGoals: camera centre ≤ {GOALS['centre_m']} m, focal ≤ {GOALS['focal_pct']} %, {rms_of} ≤ "
            f"{GOALS['rms_px']} px; {extra}.")


if __name__ == "__main__":
    main()
