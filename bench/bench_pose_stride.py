"""Pose every N-th frame: what the players and the events lose, and what the pose stage saves.

    .venv/bin/python bench/bench_pose_stride.py [--clips 2] [--strides 1,2,3,4] [--frames 300] [--data runs/bench_pose_stride]

Held-out rendered rallies (padel seeds 300+, tennis 400+, generated once under ``--data``) go through MoveNet
once on every frame, each frame's inference CPU time kept; a stride N keeps the poses of
:func:`~inference.players.sampling.sampled_frames` only — the poses MoveNet would give there, since it looks at one
frame at a time — and runs the player pipeline (tracking at the looks' rate, gaps filled) on them. Printed per
sport and stride, against ``gt/players.csv``: court-position error, identity switches, coverage of the true
player-frames, the wrists' error in pixels on the frames where the pose model did not look, the shipped
player-aware event model's F1 (ball: ``gt/ball.csv``, ±2 frames at 50 fps) with those players and without any,
and the pose CPU seconds per second of video (the kept frames' measured inference time). ``--crops`` adds rows
"N + tiles": the default clip loop (:class:`~inference.players.crops.CropLooks`: most looks pose only tiles
around the people of the look before) run for real at that stride, its looks' CPU time measured.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from inference.clipio import Clip, Manifest
from inference.court import load_court
from inference.players.tracking import TrackingConfig, players_from_poses
from inference.players.sampling import sampled_frames
from inference.players.types import Persons, PoseSequence

SEEDS = {"padel": 300, "tennis": 400}
WRISTS = (9, 10)


def dataset(root: Path, sport: str, n: int, frames: int) -> list[Clip]:
    from synth.generate import SynthConfig, generate_dataset

    folder = root / sport
    if not (folder / "manifest.yaml").is_file() or len(Manifest.load(folder).clips) != n:
        print(f"generating {n} {sport} clips into {folder} ...", flush=True)
        generate_dataset(folder, n, SEEDS[sport], SynthConfig(sport=sport, codec="mp4v", max_frames=frames))
    return [Clip(p) for p in Manifest.load(folder).paths()]


def pose_every_frame(clip: Clip) -> tuple[PoseSequence, np.ndarray]:
    """MoveNet on every frame: the poses and each frame's inference CPU seconds (N,); kept beside the clip
    (``movenet_poses.npz``) and reused."""
    from inference.players.backends import MoveNetBackend

    cache = clip.root / "movenet_poses.npz"
    if cache.is_file():
        z = np.load(cache)
        edges = np.concatenate([[0], np.cumsum(z["count"])])
        out = [Persons(z["boxes"][a:b], z["keypoints"][a:b], z["kp_scores"][a:b], z["scores"][a:b])
               for a, b in zip(edges[:-1], edges[1:])]
        return PoseSequence(out, "movenet"), z["cpu"]
    backend = MoveNetBackend()
    out, cpu = [], []
    with clip.frames() as frames:
        for img in frames.iter(0, len(frames)):
            t0 = time.process_time()
            out.append(backend.infer(img))
            cpu.append(time.process_time() - t0)
    np.savez(cache, count=[len(p) for p in out], cpu=cpu,
             **{k: np.concatenate([getattr(p, k) for p in out]) for k in ("boxes", "keypoints", "kp_scores", "scores")})
    return PoseSequence(out, "movenet"), np.array(cpu)


def keep_stride(seq: PoseSequence, stride: int) -> PoseSequence:
    """The poses a stride-N run would have: the looked-at frames' poses, nobody elsewhere."""
    look = sampled_frames(len(seq), stride)
    kept = [p if look[i] else Persons.empty() for i, p in enumerate(seq.frames)]
    return PoseSequence(kept, seq.source, None if stride == 1 else look)


def pose_with_tiles(clip: Clip, stride: int) -> tuple[PoseSequence, float, dict]:
    """The default clip loop with tile looks at ``stride``: the poses, the looks' CPU seconds and their kinds."""
    from inference.players.backends import MoveNetBackend
    from inference.players.crops import CropLooks

    backend = MoveNetBackend(crops=CropLooks())
    backend.infer(np.zeros((64, 64, 3), np.uint8))  # load the model outside the measurement
    backend.looks = {"full": 0, "tiles": 0}
    seq = backend.run(clip, progress=False, stride=stride)
    return seq, backend.look_cpu_s, dict(backend.looks)


def wrist_error_px(pred, gt, look: np.ndarray, wh: np.ndarray) -> float:
    """Median wrist error (px) of matched players on the frames the pose model did not look at (stride 1: all)."""
    from inference.players.evaluate import match_frames

    rows_p = {(int(f), int(i)): k for k, (f, i) in enumerate(zip(pred.frame, pred.player_id))}
    rows_g = {(int(f), int(i)): k for k, (f, i) in enumerate(zip(gt.frame, gt.player_id))}
    errs = []
    for f, pairs in match_frames(pred, gt).items():
        if look[f] and not look.all():
            continue
        for g, p in pairs:
            kp = pred.keypoints[rows_p[(f, p)], WRISTS, :2] * wh
            kg = gt.keypoints[rows_g[(f, g)], WRISTS]
            vis = kg[:, 2] > 0.9
            if vis.any():
                errs += np.linalg.norm(kp[vis] - kg[vis, :2] * wh, axis=1).tolist()
    errs = np.array(errs)
    errs = errs[np.isfinite(errs)]
    return float(np.median(errs)) if len(errs) else float("nan")


def event_counts(det, clip: Clip, players, counts) -> None:
    from inference.events.metrics import tolerance_frames

    gt = clip.read_events(gt=True)
    res = det.predict(clip.read_ball(), clip.info.fps, clip.info.width, clip.info.height,
                      camera=clip.read_camera(gt=True), players=players)
    index = {c: i for i, c in enumerate(counts.classes)}
    counts.add(gt.frame, [index[e] for e in gt.event], res.events.frame, [index[e] for e in res.events.event],
               tolerance_frames(clip.info.fps))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=2, help="clips per sport")
    ap.add_argument("--strides", default="1,2,3,4")
    ap.add_argument("--frames", type=int, default=300, help="frames per generated clip at most")
    ap.add_argument("--sports", default="padel,tennis")
    ap.add_argument("--data", type=Path, default=Path("runs/bench_pose_stride"))
    ap.add_argument("--extend", default="", help="comma-separated TrackingConfig.extend_s values to compare, e.g. "
                    "0,0.5 (0: the tracks' ends are not carried onto weak detections); default: the default only")
    ap.add_argument("--crops", default="", help="comma-separated strides that also get a row with tile looks "
                    "(the default clip loop, run for real)")
    args = ap.parse_args()
    from inference.clipio import EVENT_LABELS
    from inference.events import EventDetector
    from inference.events.metrics import EventCounts
    from inference.players.backends import MoveNetBackend
    from inference.players.evaluate import score

    ok, reason = MoveNetBackend().available()
    if not ok:
        print(f"MoveNet unavailable: {reason}")
        return 0
    strides = [int(s) for s in args.strides.split(",")]
    classes = ("none", *EVENT_LABELS)
    print("| sport | pose every | looks / s | pose CPU s per s of video | court error m (median / p90) | "
          "ID switches | coverage | wrist error px, frames not looked at (median) | events F1 (none: ball only) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for sport in args.sports.split(","):
        clips = dataset(args.data, sport, args.clips, args.frames)
        det = EventDetector.from_checkpoint(None, sport=sport)
        cache = [(clip, *pose_every_frame(clip)) for clip in clips]
        none = EventCounts(classes)
        for clip, _, _ in cache:
            event_counts(det, clip, None, none)
        extends = [float(x) for x in args.extend.split(",") if x] or [TrackingConfig().extend_s]
        rows = [(stride, False, e) for stride in strides for e in extends]
        rows += [(int(x), True, e) for x in args.crops.split(",") if x for e in extends]
        for stride, tiles, extend in rows:
            errs, p90, switches, cover, wrist, cpu_s, video_s = [], [], 0, [], [], 0.0, 0.0
            counts = EventCounts(classes)
            kinds = {"full": 0, "tiles": 0}
            for clip, seq, cpu in cache:
                look = sampled_frames(len(seq), stride)
                if tiles:
                    kept, took, k = pose_with_tiles(clip, stride)
                    cpu_s += took
                    kinds = {key: kinds[key] + k[key] for key in kinds}
                else:
                    kept = keep_stride(seq, stride)
                    cpu_s += float(cpu[look].sum())
                gt = clip.read_players(gt=True)
                pred = players_from_poses(kept, clip.read_camera(gt=True), load_court(clip.court_path()),
                                          clip.info.fps, TrackingConfig(extend_s=extend))
                s = score(pred, gt, clip.info.fps)
                errs.append(s.median_error_m)
                p90.append(s.p90_error_m)
                switches += s.switches
                cover.append(s.coverage)
                wh = np.array([clip.info.width, clip.info.height], float)
                wrist.append(wrist_error_px(pred, gt, look, wh))
                video_s += len(seq) / clip.info.fps
                event_counts(det, clip, pred, counts)
            fps = clips[0].info.fps
            name = f"{stride} + tiles ({kinds['tiles']} of {sum(kinds.values())} looks)" if tiles else f"{stride}"
            if len(extends) > 1:
                name += f", ends carried {extend:g} s"
            print(f"| {sport} | {name} | {fps / stride:.1f} | {cpu_s / video_s:.2f} | {np.mean(errs):.3f} / "
                  f"{np.mean(p90):.3f} | {switches} | {np.mean(cover) * 100:.0f}% | {np.nanmean(wrist):.1f} | "
                  f"{counts.scores()['f1']:.3f} ({none.scores()['f1']:.3f}) |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
