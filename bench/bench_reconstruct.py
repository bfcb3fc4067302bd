"""Benchmark the 3D reconstruction on held-out synthetic rallies: the table of all methods, the default
method's sensitivity to 2D noise and event-frame errors, and frames/s on this CPU. Prints Markdown.

    .venv/bin/python bench/bench_reconstruct.py [--clips 6] [--data runs/bench_3d]

The evaluation clips are generated once (seeds 100+ for padel, 200+ for tennis, randomised cameras:
none of them was used while developing the methods) and reused on later runs. Inputs: ground-truth 2D
ball positions plus Gaussian noise (σ = 2 px unless stated), ground-truth events, the ground-truth
camera; the players' court positions from gt/players.csv where a row says "players".
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from inference.clipio import Clip, Manifest
from inference.reconstruct.api import METHOD_NAMES, methods
from inference.reconstruct.cli import sensitivity_table
from inference.reconstruct.evaluate import Setting, evaluate, format_table
from synth.generate import SynthConfig, generate_dataset

SEEDS = {"padel": 100, "tennis": 200}


def dataset(root: Path, sport: str, n: int) -> list[Clip]:
    folder = root / sport
    if not (folder / "manifest.yaml").is_file() or len(Manifest.load(folder).clips) != n:
        print(f"generating {n} {sport} clips into {folder} ...", flush=True)
        generate_dataset(folder, n, SEEDS[sport], SynthConfig(sport=sport, codec="mp4v"))
    return [Clip(p) for p in Manifest.load(folder).paths()]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", type=int, default=6, help="clips per sport (default 6)")
    ap.add_argument("--data", type=Path, default=Path("runs/bench_3d"))
    args = ap.parse_args()
    table = methods()
    for sport in ("padel", "tennis"):
        clips = dataset(args.data, sport, args.clips)
        n_frames = sum(c.n_frames for c in clips)
        base = Setting(noise_px=2.0, players="gt")
        print(f"\n## {sport}: {len(clips)} held-out clips, {n_frames} frames\n")
        rows = evaluate(clips, {m: table[m] for m in METHOD_NAMES}, base)
        print(format_table(rows, f"All methods — {base.label()}:\n"))
        print()
        rows = evaluate(clips, {"joint": table["joint"]}, replace(base, players="none"))
        print(format_table(rows, "Default method without players' positions:\n"))
        print()
        print(sensitivity_table(clips, table["joint"], base))


if __name__ == "__main__":
    main()
