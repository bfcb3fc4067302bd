"""What a pose backend and the players stage do to the players, measured on rendered clips with ground truth
(``rally3d synth``): players missed and bridged, the joints' offset and jitter, wrists on something else,
left/right swaps, court-position error (:mod:`training.events.stats.pose_stats`), and the ``data.pose_noise``
settings that reproduce them. Writes both to a YAML (default ``conf/data/pose_noise/movenet_measured.yaml``)
and checks the settings: the same statistics of the clips' true players put through the noise model.

    .venv/bin/python bench/bench_pose_stats.py CLIP ... [--out FILE] [--backend movenet]

The clips of conf/data/pose_noise/movenet_measured.yaml: ``rally3d synth --sport padel --clips 6 --seed 7100
--codec mp4v --max-frames 500 --out runs/pose_stats/padel`` (also ``--clips 4 --seed 7300`` into ``padelb``, and
tennis ``--clips 4 --seed 7200``). Each CLIP runs through the pose backend once (MoveNet by default, ~30 s of CPU per 500 frames); its poses
are kept under ``runs/pose_stats/cache/`` and the players stage (tracking, gaps, court positions) runs on
them as ``rally3d players`` does. Prints the figures and the CPU time.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

HEADER = """# Statistics of the pose backend ({backend}) and the players stage (`rally3d players`) on rendered clips with
# ground truth, and the `data.pose_noise` settings that reproduce them. Written by bench/bench_pose_stats.py
# ({clips}); regenerate with its command line below.
#   {command}
# The clips: rally3d synth --sport padel --clips 6 --seed 7100 --codec mp4v --max-frames 500 (and --clips 4
# --seed 7300; tennis --clips 4 --seed 7200); docs/events.md#pose-noise-measured.
# Use as: python train.py +experiment=hitnet_tennis_players +data/pose_noise=movenet_measured
# (hitnet_padel_players uses it by default).
"""
KEYS = ("miss_frac", "bridged_frac", "body_sigma_px", "wrist_sigma_px", "body_jitter_px", "lag_corr",
        "wrist_outlier_frac", "flip_runs_per_s", "court_sigma_m")


def poses(clip_dir: Path, cache: Path, backend_name: str):
    """The backend's poses of one clip (cached as ``cache/<parent>_<clip>_<backend>@<input size>.npz``)."""
    from inference.clipio import Clip
    from inference.players.backends import make_backend
    from inference.players.types import Persons, PoseSequence

    name, _, size = backend_name.partition("@")              # e.g. movenet@960: MoveNet at another input size
    if name == "movenet":                                      # the cache names the input size used
        from inference.players.backends import movenet_input_size

        info = Clip(clip_dir).info
        size = str(movenet_input_size(info.height, info.width, int(size) if size else None))
        backend_name = f"movenet@{size}"
    path = cache / f"{clip_dir.parent.name}_{clip_dir.name}_{backend_name}.npz"
    if path.is_file():
        z = np.load(path)
        cut = np.cumsum(z["count"])[:-1]
        parts = [np.split(z[k], cut) for k in ("boxes", "keypoints", "kp_scores", "scores")]
        return PoseSequence([Persons(*p) for p in zip(*parts)], backend_name)
    backend = make_backend(name)
    if size:
        backend.input_size = int(size)
    seq = backend.run(Clip(clip_dir), progress=False)
    cache.mkdir(parents=True, exist_ok=True)
    cat = lambda k, shape: np.concatenate([getattr(p, k).reshape((-1,) + shape) for p in seq.frames])  # noqa: E731
    np.savez_compressed(path, count=np.array([len(p.scores) for p in seq.frames]), boxes=cat("boxes", (4,)),
                        keypoints=cat("keypoints", (17, 2)), kp_scores=cat("kp_scores", (17,)), scores=cat("scores", ()))
    return seq


CACHE = Path("runs/pose_stats/cache")


def players_of(clip_dir: Path, backend_name: str = "movenet", cache: Path = CACHE):
    """The clip, the backend's poses (cached, :func:`poses`) and the players stage's players from them, as
    ``rally3d players`` writes them (the clip's true camera)."""
    from inference.clipio import Clip
    from inference.court import load_court
    from inference.players.tracking import players_from_poses

    clip = Clip(clip_dir)
    seq = poses(clip_dir, cache, backend_name)
    pred = players_from_poses(seq, clip.read_camera(gt=True), load_court(clip.court_path()), clip.info.fps)
    return clip, seq, pred


def simulated(truths, settings: dict, seed: int = 0):
    """The truths' exact players through the noise model with ``settings`` (pose_noise.noisy_players)."""
    from training.events.synthetic.pose_noise import PoseNoiseConfig, noisy_players
    from training.events.stats.pose_stats import PoseClipTruth

    cfg = PoseNoiseConfig.from_dict({**settings, "p_no_players": 0.0, "p_no_poses": 0.0})
    out = []
    for k, t in enumerate(truths):
        sim = SimpleNamespace(players=t.gt, fps=t.fps, width=t.width, height=t.height)
        noisy = noisy_players(sim, np.random.default_rng(seed + k), cfg)
        out.append(PoseClipTruth(t.name, t.fps, t.width, t.height, t.gt, noisy))
    return out


def main(argv=None) -> dict:
    import yaml

    from training.events.stats.pose_stats import PoseClipTruth, measure_players, pose_noise_settings, refine_settings

    ap = argparse.ArgumentParser()
    ap.add_argument("clips", nargs="+", type=Path, help="rendered clip folders with gt/players.csv")
    ap.add_argument("--out", default="conf/data/pose_noise/movenet_measured.yaml")
    ap.add_argument("--backend", default="movenet",
                    help="pose backend; movenet@640: MoveNet at a 640-px input (default: its size for the frame)")
    ap.add_argument("--cache", type=Path, default=CACHE)
    ap.add_argument("--steps", type=int, default=3, help="correction steps of the settings (refine_settings)")
    args = ap.parse_args(argv)
    t0 = time.process_time()
    truths, names = [], []
    for d in args.clips:
        clip, seq, pred = players_of(d, args.backend, args.cache)
        truths.append(PoseClipTruth.from_clip(clip, pred, seq))
        names.append(f"{d.parent.name}/{d.name} ({clip.info.sport}, {clip.info.camera_id or 'camera'}, "
                     f"{clip.info.fps:g} fps, {clip.info.width}x{clip.info.height}, {clip.n_frames} frames)")
    stats = measure_players(truths)
    first = pose_noise_settings(stats)
    check = measure_players(simulated(truths, first), lag_s=stats["lag_s"])
    settings = first
    for step in range(1, args.steps + 1):                     # correction steps, each checked on new draws
        settings = refine_settings(settings, stats, check)
        check = measure_players(simulated(truths, settings, seed=100 * step), lag_s=stats["lag_s"])
    stats["clips"] = names
    cpu = time.process_time() - t0
    print(yaml.safe_dump({"measured": stats}, sort_keys=False, allow_unicode=True, default_flow_style=None))
    print(yaml.safe_dump({"pose_noise": settings}, sort_keys=False, default_flow_style=None))
    print("| figure | side | measured | noise model on the true players |\n|---|---|---|---|")
    for side in ("near", "far"):
        for k in KEYS:
            print(f"| {k} | {side} | {stats[side][k]} | {check[side][k]} |")
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        cmd = "python bench/bench_pose_stats.py " + " ".join(sys.argv[1:] if argv is None else map(str, argv))
        body = yaml.safe_dump({**settings, "measured": stats}, sort_keys=False, allow_unicode=True,
                              default_flow_style=None)
        out.write_text(HEADER.format(backend=args.backend, clips=f"{len(truths)} clips", command=cmd) + body)
        print(f"wrote {out}")
    print(f"CPU time {cpu:.1f} s (the pose backend included where it ran)")
    return {"stats": stats, "settings": settings, "check": check, "cpu_s": cpu}


if __name__ == "__main__":
    main()
