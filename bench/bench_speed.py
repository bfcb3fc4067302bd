"""The project's speed figures in one run: joint reconstruction frames per CPU-second, CLI start-up, and the
ball detector's frames per CPU-second with its 2D F1 for each way of running it, on the same held-out
synthetic clips. Prints Markdown and writes JSON.

    .venv/bin/python bench/bench_speed.py [--clips 2] [--frames 150] [--sizes 1280x720,1920x1080]
        [--threads 1] [--json runs/bench_speed.json]

- **Joint**: ``fit_joint`` on the held-out clips of bench/bench_joint.py (same code, ``--joint-clips`` per sport,
  σ 2 px, ground-truth events and camera).
- **CLI start-up**: CPU seconds of fresh ``rally3d ... --help`` processes (bench/bench_cli_startup.py).
- **Detector**: the shipped WASB padel weights on padel clips made with seed ``--seed`` (the weights were trained
  on seed 10; the embedded sample is seed 7), one folder per size, randomised camera and look, H.264. Variants:
  eager PyTorch as trained (batch norms unfolded), with batch norms folded, with crop-tracking, ONNX Runtime,
  ONNX Runtime with crop-tracking, and the weights' int8 companion (``wasb_padel.int8.onnx``) with crop-tracking. CPU seconds are the whole ``rally3d detect`` work (decode, letterbox,
  network, tracker) measured with ``time.process_time``; ``--threads`` threads for PyTorch and ONNX Runtime
  alike (1 by default: CPU time then does not pay for threads spinning on a busy machine). F1 at τ = 4 px in
  original pixels, pooled over the clips; "decode + letterbox" is the floor no detector variant goes below.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.bench_cli_startup import cpu_seconds  # noqa: E402

CLI_CASES = {"rally3d --help": ["--help"], "rally3d detect --help": ["detect", "--help"],
             "rally3d reconstruct --help": ["reconstruct", "--help"], "rally3d courts": ["courts"]}
VARIANTS = {  # name → BallDetectorRunner options
    "eager, BN unfolded": {"fold_bn": False},
    "eager + BN fold": {},
    "eager + BN fold + crop": {"crop": "auto"},
    "ONNX": {"backend": "onnx"},
    "ONNX + crop": {"backend": "onnx", "crop": "auto"},
    "ONNX int8 + crop": {"backend": "onnx-int8", "crop": "auto"},
}


def joint_speed(data: Path, n_clips: int) -> dict:
    """Frames per CPU-second of ``fit_joint`` over bench_joint's held-out clips, per sport."""
    from bench.bench_joint import clip_figures
    from bench.bench_reconstruct import dataset
    from inference.reconstruct.evaluate import Setting

    out = {}
    for sport in ("padel", "tennis"):
        rows = [clip_figures(c, Setting(noise_px=2.0, players="gt", event_shift=0, seed=1))
                for c in dataset(data, sport, n_clips)]
        frames, cpu = sum(r["frames"] for r in rows), sum(r["cpu"] for r in rows)
        out[sport] = {"clips": len(rows), "frames": frames, "cpu_s": cpu, "frames_per_cpu_s": frames / cpu}
    return out


def cli_startup(repeat: int) -> dict:
    """Median CPU seconds of fresh CLI processes."""
    return {name: cpu_seconds(["-m", "inference.cli", *argv], ROOT, repeat) for name, argv in CLI_CASES.items()}


def held_out_clips(data: Path, sizes: list[tuple[int, int]], n: int, frames: int, seed: int) -> dict:
    """``{"1280x720": [Clip, ...]}``: padel clips of each size (generated once into ``data``)."""
    from inference.clipio import Clip, Manifest
    from synth.generate import SynthConfig, generate_dataset

    out = {}
    for k, (w, h) in enumerate(sizes):
        folder = data / f"padel_{w}x{h}_seed{seed}"
        if not (folder / "manifest.yaml").is_file() or len(Manifest.load(folder).clips) != n:
            print(f"generating {n} padel clips {w}×{h} into {folder} ...", file=sys.stderr, flush=True)
            generate_dataset(folder, n, seed + k, SynthConfig(sport="padel", width=w, height=h, max_frames=frames))
        out[f"{w}x{h}"] = [Clip(p) for p in Manifest.load(folder).paths()]
    return out


def decode_floor(clip) -> float:
    """CPU seconds to decode and letterbox every frame of ``clip`` (what every variant pays)."""
    from inference.detection.geometry import Letterbox

    lb = Letterbox(clip.info.width, clip.info.height)
    c0 = time.process_time()
    with clip.frames(cache_size=0) as src:
        for frame in src.iter():
            lb.warp(frame)
    return time.process_time() - c0


def detector_speed(clips: dict, onnx_dir: Path) -> dict:
    """Per size and variant: frames, CPU seconds, windows, F1 (pooled counts)."""
    from inference.detection.crop import CropConfig
    from inference.detection.detect import SHIPPED, BallDetectorRunner
    from inference.detection.metrics import DetectionCounts, evaluate_ball_tracks

    runners = {}
    for name, opts in VARIANTS.items():
        opts = {**opts, "crop": CropConfig() if opts.get("crop") == "auto" else None}
        runners[name] = BallDetectorRunner.from_weights("wasb", SHIPPED["wasb"], onnx_dir=onnx_dir, **opts)
    out = {}
    for size, group in clips.items():
        fig = {name: {"frames": 0, "cpu_s": 0.0, "counts": DetectionCounts(), "windows": {}} for name in VARIANTS}
        fig["decode + letterbox"] = {"frames": 0, "cpu_s": 0.0}
        for clip in group:   # variants interleaved per clip, so a change in machine load hits them alike
            fig["decode + letterbox"]["cpu_s"] += decode_floor(clip)
            fig["decode + letterbox"]["frames"] += clip.n_frames
            gt = clip.read_ball()
            for name, runner in runners.items():
                c0 = time.process_time()
                result = runner.run(clip)
                f = fig[name]
                f["cpu_s"] += time.process_time() - c0
                f["frames"] += result.n_frames
                f["counts"] += evaluate_ball_tracks(result.track, gt, clip.info.width, clip.info.height,
                                                    tau_px=4.0).counts
                for k, v in result.windows.items():
                    f["windows"][k] = f["windows"].get(k, 0) + v
                print(f"  {size} {clip.root.name} {name}: {result.n_frames / (time.process_time() - c0):.2f} "
                      f"frames/CPU-s", file=sys.stderr, flush=True)
        for f in fig.values():
            f["frames_per_cpu_s"] = f["frames"] / f["cpu_s"]
            f["cpu_s_per_frame"] = f["cpu_s"] / f["frames"]
            if "counts" in f:
                c = f.pop("counts")
                f.update(f1=c.f1, precision=c.precision, recall=c.recall)
        out[size] = fig
    return out


def markdown(fig: dict) -> str:
    lines = [f"Machine: {fig['machine']}; torch/ONNX Runtime threads: {fig['threads']}", "", "## Joint reconstruction",
             "", "| sport | clips | frames | CPU s | frames/CPU-s |", "|---|---:|---:|---:|---:|"]
    for sport, j in fig["joint"].items():
        lines.append(f"| {sport} | {j['clips']} | {j['frames']} | {j['cpu_s']:.2f} | **{j['frames_per_cpu_s']:.0f}** |")
    lines += ["", "## CLI start-up (CPU s, median of fresh processes)", "", "| command | CPU s |", "|---|---:|"]
    lines += [f"| `{k}` | {v:.2f} |" for k, v in fig["cli"].items()]
    for size, rows in fig["detector"].items():
        base = rows["eager, BN unfolded"]["frames_per_cpu_s"]
        lines += ["", f"## Ball detector, {size} ({rows['decode + letterbox']['frames']} frames, held-out seed "
                  f"{fig['seed']})", "", "| variant | frames/CPU-s | CPU s/frame | × eager | F1 (τ 4 px) | P | R | "
                  "windows full / crop / re-run |", "|---|---:|---:|---:|---:|---:|---:|---|"]
        for name, r in rows.items():
            if "f1" not in r:
                lines.append(f"| {name} (floor) | {r['frames_per_cpu_s']:.1f} | {r['cpu_s_per_frame']:.3f} | – | – | "
                             "– | – | – |")
                continue
            w = r["windows"]
            lines.append(f"| {name} | **{r['frames_per_cpu_s']:.2f}** | {r['cpu_s_per_frame']:.3f} | "
                         f"{r['frames_per_cpu_s'] / base:.2f} | **{r['f1']:.4f}** | {r['precision']:.3f} | "
                         f"{r['recall']:.3f} | {w.get('full', 0)} / {w.get('crop', 0)} / {w.get('crop_rerun', 0)} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=2, help="held-out detector clips per size (default 2)")
    ap.add_argument("--frames", type=int, default=150, help="frames per detector clip (default 150)")
    ap.add_argument("--sizes", default="1280x720,1920x1080")
    ap.add_argument("--seed", type=int, default=31, help="synth seed of the detector clips (default 31)")
    ap.add_argument("--threads", type=int, default=1, help="PyTorch / ONNX Runtime threads (default 1)")
    ap.add_argument("--joint-clips", type=int, default=2, help="bench_joint clips per sport (default 2)")
    ap.add_argument("--cli-repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=ROOT / "runs" / "bench_speed")
    ap.add_argument("--json", type=Path, default=ROOT / "runs" / "bench_speed.json")
    args = ap.parse_args()

    import torch

    torch.set_num_threads(args.threads)
    sizes = [tuple(int(v) for v in s.lower().split("x")) for s in args.sizes.split(",")]
    fig = {"machine": f"{platform.machine()}, torch {torch.__version__}", "threads": args.threads,
           "seed": args.seed}
    fig["joint"] = joint_speed(ROOT / "runs" / "bench_3d", args.joint_clips)
    fig["cli"] = cli_startup(args.cli_repeat)
    clips = held_out_clips(args.data, sizes, args.clips, args.frames, args.seed)
    fig["detector"] = detector_speed(clips, args.data / "onnx_cache")
    print(markdown(fig))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(fig, indent=2, default=float))
    print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
