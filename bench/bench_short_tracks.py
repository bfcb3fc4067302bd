"""Short tracks with real ball physics: a racket hit, one bounce and a few frames after it, seen at 25 fps
with σ 2–3 px noise by a camera at the side, oblique or behind — the shape of the short motion-capture
trajectories that monocular methods are compared on. Prints the 3D error split along and across each
frame's line of sight, how many tracks were reconstructed and how many are more than 1 m off (mean per track),
the share of frames within 1 σ / 2 σ of the reported covariance along and across the line of sight (68 % / 95 %
when calibrated), with the hit and the bounce as events and
with the bounce alone (one event), and — as `rally3d infer` has it from players.csv — with the hitter's
court position (``--hitter SIGMA``: the body 0.4–1.1 m (table tennis 0.2–0.7 m) to one side of the ball and 0.2 m behind it, plus
SIGMA m of noise per axis; :func:`synth.short_tracks.hitter_players`).

    .venv/bin/python bench/bench_short_tracks.py [--sport tennis|table_tennis] [--tracks 30] [--seed 0] [--hitter 0.3]

The tracks are simulated by synth/short_tracks.py (court and ball from conf/court/<sport>.yaml; the
motion-capture tracks of the literature are table tennis, tennis is the same shape at ten times the scale):
drag, Magnus with random topspin or slice, the rigid-ball impact (restitution and friction of the playing
surface) at the bounce, then 3–8 frames; the first frame is a random phase after the hit. They are not made by `rally3d synth` and the reconstruction knows only the court YAML, the camera, the
2D track and the events.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inference.camera import Camera  # noqa: E402
from inference.court import load_court  # noqa: E402
from inference.reconstruct import Observations  # noqa: E402
from inference.reconstruct.evaluate import direction_coverage  # noqa: E402
from inference.reconstruct.joint import JointConfig, fit_joint  # noqa: E402
from synth.short_tracks import FPS, REACH, VIEWS, draw_tracks, hitter_players  # noqa: E402

SIZE = (1280, 720)


def run(n: int, seed: int, noise: tuple[float, float], hitter: float | None = None, sport: str = "tennis") -> None:
    court = load_court(sport)
    tracks = draw_tracks(court, n, seed)
    print(f"{n} simulated tracks ({sport.replace('_', ' ')} ball and court), 25 fps, hit → bounce → 3–8 frames, "
          f"{np.mean([len(t['frames']) for t in tracks]):.0f} frames on average, noise σ ∈ {noise} px\n")
    print("| camera | events | reconstructed | tracks > 1 m off | along-ray median m | along mean m | across median m | "
          "3D median m | 3D mean per track m | within 1σ / 2σ along | within 1σ / 2σ across | frames/CPU-s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    cfg = JointConfig(pixel_sigma=float(np.mean(noise)))
    for name, (eye, target, fov) in VIEWS[sport].items():
        cam = Camera.from_look_at(eye, target, SIZE, fov_deg=fov)
        kinds = ("hit + bounce", "bounce only") + ((f"hit + bounce + hitter ±{hitter:g} m",) if hitter is not None else ())
        for events in kinds:
            along, across, per_track, ok, frames, cpu = [], [], [], 0, 0, 0.0
            ds, covs, rays = [], [], []
            for k, tr in enumerate(tracks):
                r2 = np.random.default_rng(seed * 1000 + k)
                sigma = r2.uniform(*noise)
                uv = cam.project(tr["xyz"]) + r2.normal(0.0, sigma, (len(tr["xyz"]), 2))
                inside = (uv[:, 0] >= 0) & (uv[:, 0] < SIZE[0]) & (uv[:, 1] >= 0) & (uv[:, 1] < SIZE[1])
                uv[~inside] = np.nan
                players = None
                if events.startswith("hit"):
                    ev, lab = [tr["hit"], tr["bounce"]], ["player_near", "ground"]
                    if "hitter" in events:
                        players = hitter_players(np.random.default_rng(seed * 7777 + k), tr, hitter, REACH[sport])
                else:
                    ev, lab = [tr["bounce"]], ["ground"]
                obs = Observations(court, cam, FPS, uv, np.array(ev), lab, players)
                c0 = time.process_time()
                fit = fit_joint(obs, cfg)
                cpu += time.process_time() - c0
                b = fit.ball_3d()
                if not len(b):
                    continue
                ok += 1
                frames += len(b)
                gt = tr["xyz"][b.frame]
                d = b.xyz - gt
                ray = gt - cam.centre
                ray /= np.linalg.norm(ray, axis=1)[:, None]
                a = np.einsum("ij,ij->i", d, ray)
                along.append(np.abs(a))
                across.append(np.linalg.norm(d - a[:, None] * ray, axis=1))
                per_track.append(float(np.linalg.norm(d, axis=1).mean()))
                _, cov = fit.covariances()
                good = np.isfinite(cov).all(axis=(1, 2))
                ds.append(d[good])
                covs.append(cov[good])
                rays.append(ray[good])
            A, C = np.concatenate(along), np.concatenate(across)
            E = np.sqrt(A**2 + C**2)
            cv = direction_coverage(*(np.concatenate(x) for x in (ds, covs, rays)))
            print(f"| {name} | {events} | {ok}/{len(tracks)} | {sum(x > 1.0 for x in per_track)} | {np.median(A):.3f} | "
                  f"{A.mean():.3f} | {np.median(C):.4f} | {np.median(E):.3f} | {np.mean(per_track):.3f} | "
                  f"{cv['along'][0]:.2f} / {cv['along'][1]:.2f} | {cv['across'][0]:.2f} / {cv['across'][1]:.2f} | "
                  f"{frames / cpu:.0f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tracks", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", default="2,3", help="2D noise σ range in px (default 2,3)")
    ap.add_argument("--hitter", type=float, default=None,
                    help="also fit with the hitter's court position from players.csv, this noisy (m per axis)")
    ap.add_argument("--sport", choices=sorted(VIEWS), default="tennis",
                    help="court, ball, shots and cameras (conf/court/<sport>.yaml; default tennis)")
    args = ap.parse_args()
    lo, hi = (float(x) for x in args.noise.split(","))
    run(args.tracks, args.seed, (lo, hi), args.hitter, args.sport)


if __name__ == "__main__":
    main()
