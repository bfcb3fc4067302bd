"""Benchmark the player pipeline on held-out synthetic clips through the importer path.

    .venv/bin/python bench/bench_players.py [--clips 4] [--data runs/bench_players]

The true 2D keypoints of gt/players.csv become MMPose JSON predictions with Gaussian keypoint noise,
dropped detections (single frames and occlusion runs) and spectators standing off court; the pipeline
(import → OC-SORT → stitching → selection → teams → gaps → court positions) runs on them. Printed:
identity switches per player per minute, court-position error (m, against the floor point under the
true ankles), coverage of the true player-frames, and frames/s. Clips are generated once (seeds 300+ for
padel, 400+ for tennis, randomised cameras) and reused.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from inference.clipio import Clip, Manifest
from inference.court import load_court
from inference.players.evaluate import DetectionNoise, score, simulate_detections
from inference.players.importers import load_predictions, write_mmpose_json
from inference.players.tracking import TRACKERS, TrackingConfig, players_from_poses
from synth.generate import SynthConfig, generate_dataset

SEEDS = {"padel": 300, "tennis": 400}


def dataset(root: Path, sport: str, n: int) -> list[Clip]:
    folder = root / sport
    if not (folder / "manifest.yaml").is_file() or len(Manifest.load(folder).clips) != n:
        print(f"generating {n} {sport} clips into {folder} ...", flush=True)
        generate_dataset(folder, n, SEEDS[sport], SynthConfig(sport=sport, codec="mp4v", max_frames=600))
    return [Clip(p) for p in Manifest.load(folder).paths()]


def run(clips: list[Clip], noise: DetectionNoise, cfg: TrackingConfig) -> dict:
    switches = minutes = frames = seconds = 0.0
    errors, covered, total = [], 0, 0
    with tempfile.TemporaryDirectory() as d:
        for k, clip in enumerate(clips):
            gt = clip.read_players(gt=True)
            cam = clip.read_camera(gt=True)
            seq = simulate_detections(gt, clip.n_frames, cam.image_size, np.random.default_rng(k), noise)
            path = write_mmpose_json(Path(d) / f"{k}.json", seq)
            t0 = time.perf_counter()
            poses = load_predictions(path, n_frames=clip.n_frames)
            pred = players_from_poses(poses, cam, load_court(clip.court_path()), clip.info.fps, cfg)
            seconds += time.perf_counter() - t0
            s = score(pred, gt, clip.info.fps)
            n_players = len(gt.ids())
            switches += s.switches
            minutes += n_players * len(np.unique(gt.frame)) / clip.info.fps / 60
            frames += clip.n_frames
            from inference.players.evaluate import match_frames

            m = match_frames(pred, gt)
            pos_p = {(int(f), int(i)): xy for f, i, xy in zip(pred.frame, pred.player_id, pred.court_xy)}
            pos_g = {(int(f), int(i)): xy for f, i, xy in zip(gt.frame, gt.player_id, gt.court_xy)}
            for f, pairs in m.items():
                errors += [float(np.linalg.norm(pos_p[(f, p)] - pos_g[(f, g)])) for g, p in pairs]
            covered += sum(len(p) for p in m.values())
            total += len(gt)
    e = np.array(errors)
    return {"switches/player/min": switches / max(minutes, 1e-9), "median m": np.median(e), "mean m": e.mean(),
            "p90 m": np.percentile(e, 90), "coverage": covered / total, "fps": frames / seconds}


def movenet_rows(clips: list[Clip]) -> None:
    """The offline MoveNet backend end to end on rendered frames: detection recall of the true players
    (a detection whose keypoints are within 20 px on average), keypoint error, frames/s, and the
    pipeline's court-position error and identity switches."""
    from inference.players.backends import MoveNetBackend
    from inference.players.types import PoseSequence

    backend = MoveNetBackend()
    ok, reason = backend.available()
    if not ok:
        print(f"MoveNet unavailable: {reason}")
        return
    print("\n| clip | players found | keypoint error px (median) | pose frames/s | court error m (median) "
          "| ID switches / player / min |")
    print("|---|---|---|---|---|---|")
    for clip in clips:
        gt = clip.read_players(gt=True)
        cam = clip.read_camera(gt=True)
        wh = np.array([clip.info.width, clip.info.height], float)
        t0 = time.perf_counter()
        poses = backend.run(clip, progress=False)
        fps = clip.n_frames / (time.perf_counter() - t0)
        found, total, errs = 0, 0, []
        for f, persons in enumerate(poses.frames):
            for g in gt.keypoints[gt.frame == f, :, :2] * wh:
                total += 1
                if len(persons):
                    d = np.nanmean(np.linalg.norm(persons.keypoints - g[None], axis=2), axis=1).min()
                    if d < 20:
                        found += 1
                        errs.append(d)
        pred = players_from_poses(PoseSequence(poses.frames), cam, load_court(clip.court_path()), clip.info.fps)
        s = score(pred, gt, clip.info.fps)
        print(f"| {clip.root.parent.name}/{clip.root.name} | {found / max(total, 1) * 100:.0f}% | {np.median(errs):.1f} | {fps:.1f} | "
              f"{s.median_error_m:.3f} | {s.switches_per_player_minute:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=4)
    ap.add_argument("--data", type=Path, default=Path("runs/bench_players"))
    ap.add_argument("--movenet-clips", type=int, default=1, help="clips per sport for the MoveNet rows")
    args = ap.parse_args()
    settings = [("keypoints σ 3 px, 5 % dropped, occlusion runs, 3 spectators", DetectionNoise()),
                ("keypoints σ 6 px, 10 % dropped, occlusion runs, 6 spectators",
                 DetectionNoise(keypoint_px=6.0, drop_prob=0.10, drop_run_prob=0.02, spectators=6))]
    print("| sport | detections | tracker | ID switches / player / min | median m | mean m | p90 m | coverage | frames/s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for sport in ("padel", "tennis"):
        clips = dataset(args.data, sport, args.clips)
        for label, noise in settings:
            for tracker in TRACKERS:
                r = run(clips, noise, replace(TrackingConfig(), tracker=tracker))
                print(f"| {sport} | {label} | {tracker} | {r['switches/player/min']:.2f} | {r['median m']:.3f} | "
                      f"{r['mean m']:.3f} | {r['p90 m']:.3f} | {r['coverage'] * 100:.0f}% | {r['fps']:.0f} |",
                      flush=True)
    movenet_rows([c for sport in ("padel", "tennis") for c in dataset(args.data, sport, args.clips)[:args.movenet_clips]])


if __name__ == "__main__":
    main()
