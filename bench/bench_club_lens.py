"""Wide-angle club cameras calibrated from clicks: named floor points alone vs the same plus clicks along the
bent side lines (``court_line_points.csv``), lens k1 fitted.

    .venv/bin/python bench/bench_club_lens.py [--cameras 12] [--noise 1.5]

Simulated padel club cameras: 1920×1080, 100° across, 5.5–7.5 m high behind the near glass, barrel k1 −0.3…−0.6;
8 floor points (the service-line ends, the net ends, the far corners) and 6 clicks along each side line, each
with ±``noise`` px uniform error. Prints the camera centre and focal errors (median / max) and the CPU time per
calibration (``time.process_time``). Figures: docs/calibration.md ("Wide-angle club cameras").
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

POINTS = ["near_service_left", "near_service_right", "far_service_left", "far_service_right", "net_left",
          "net_right", "far_left", "far_right"]
SIDE_LINES = (("near_left", "far_left"), ("near_right", "far_right"))


def club_camera(rng):
    from inference.camera import Camera

    return Camera.from_look_at(eye=[5.0 + rng.uniform(-0.5, 0.5), -1.0 + rng.uniform(-1, 0.5), 6.5 + rng.uniform(-1, 1)],
                               target=[5.0, 8.5 + rng.uniform(-1, 1), 0.0], image_size=(1920, 1080), fov_deg=100,
                               dist=np.array([rng.uniform(-0.6, -0.3), 0, 0, 0, 0]))


def main(argv=None) -> int:
    from inference.camera.calibration import CalibrationError, calibrate_court
    from inference.court import load_court

    ap = argparse.ArgumentParser()
    ap.add_argument("--cameras", type=int, default=12)
    ap.add_argument("--noise", type=float, default=1.5)
    args = ap.parse_args(argv)
    court = load_court("padel")
    rows = {"8 floor points, k1 fitted": [], "the same + 12 along the side lines": []}
    cpu = {k: 0.0 for k in rows}
    for seed in range(args.cameras):
        rng = np.random.default_rng(seed)
        cam = club_camera(rng)
        pts = {n: cam.project(court.points[n][None])[0] + rng.uniform(-args.noise, args.noise, 2) for n in POINTS}
        lines = [(a, b, cam.project((court.points[a] + s * (court.points[b] - court.points[a]))[None])[0]
                  + rng.uniform(-args.noise, args.noise, 2)) for a, b in SIDE_LINES for s in np.linspace(0.1, 0.9, 6)]
        for key, lp in zip(rows, ((), lines)):
            t0 = time.process_time()
            try:
                c = calibrate_court(court, pts, (1920, 1080), n_dist=1, line_points=lp).camera
                rows[key].append((np.linalg.norm(c.centre - cam.centre), 100 * abs(c.K[0, 0] / cam.K[0, 0] - 1)))
            except CalibrationError:
                rows[key].append((np.inf, np.inf))
            cpu[key] += time.process_time() - t0
    print(f"{args.cameras} club cameras, ±{args.noise:g} px clicks\n")
    print("| clicks | centre error m (median / max) | focal error % (median / max) | CPU s per calibration |")
    print("|---|---|---|---|")
    for key, v in rows.items():
        v = np.array(v)
        print(f"| {key} | {np.median(v[:, 0]):.3f} / {v[:, 0].max():.3f} | {np.median(v[:, 1]):.2f} / "
              f"{v[:, 1].max():.2f} | {cpu[key] / len(v):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
