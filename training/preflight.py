"""Checks that run before anything heavy is imported or built (no torch, no Lightning): the first command
on a fresh clone either makes its small default dataset or stops at once with one line naming the fix.

``python train.py +experiment=wasb_padel`` reads ``data.root`` (default ``data/synth_padel``):

- it exists (a dataset folder with ``manifest.yaml``, or clip folders): go on;
- it is a default dataset of :data:`DEFAULT_DATASETS` and ``auto_data`` is true (the default): it is
  generated now, with a progress bar, after a line saying what and about how long;
- otherwise: :class:`SystemExit` with one line: the folder and the exact ``rally3d synth`` command (or
  how to point ``data.root`` elsewhere).
"""
from __future__ import annotations

import os
import shlex
import time
from pathlib import Path

#: The small default datasets the experiments read (the README's command), by folder name.
DEFAULT_DATASETS = {
    "synth_padel": {"sport": "padel", "clips": 24, "seed": 10, "max_frames": 300},
    "synth_tennis": {"sport": "tennis", "clips": 24, "seed": 10, "max_frames": 300},
}
#: Frames per second ``rally3d synth`` renders on a 2-core CPU (measured: 6,194 frames in 4 min 15 s).
SYNTH_FPS_2CORE = 24.0


def synth_command(root: str | Path, spec: dict) -> str:
    """The ``rally3d synth`` command line that makes a default dataset at ``root``."""
    return (f".venv/bin/rally3d synth --sport {spec['sport']} --clips {spec['clips']} "
            f"--out {shlex.quote(_shown(root))} --seed {spec['seed']} --max-frames {spec['max_frames']}")


def _shown(path: str | Path) -> str:
    """A path relative to the working folder when it lies inside it (as a user would type it)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def dataset_exists(root: str | Path) -> bool:
    """A dataset folder (manifest.yaml), a clip folder, or a folder with clip folders below it."""
    root = Path(root)
    if (root / "manifest.yaml").is_file() or (root / "clip.yaml").is_file():
        return True
    return root.is_dir() and next(root.glob("*/clip.yaml"), None) is not None or (
        root.is_dir() and next(root.glob("*/*/clip.yaml"), None) is not None)


def data_roots(cfg) -> list[str]:
    """The folders a training / evaluation config reads (none for simulated hit-event data; the crop model
    falls back to the embedded sample by itself)."""
    data = cfg.get("data") or {}
    if cfg.get("task") == "events" and data.get("source") != "folder":
        return []
    root = data.get("root")
    if root is None:
        if cfg.get("task") != "events" and "_target_" in data:
            raise SystemExit("no data.root: pass data.root=DIR (your clip folders, a dataset, or a list of them)")
        return []
    return [str(root)] if isinstance(root, (str, Path)) else [str(r) for r in root]


def check_data(cfg, generate=None) -> list[str]:
    """Make sure every ``data.root`` exists (see the module docstring); returns the roots generated."""
    made = []
    for root in data_roots(cfg):
        if dataset_exists(root):
            continue
        name = Path(root).name
        spec = DEFAULT_DATASETS.get(name)
        default_dir = Path(str(cfg.paths.data_dir)) / name if cfg.get("paths") else None
        is_default = spec is not None and default_dir is not None and Path(root).resolve() == default_dir.resolve()
        if is_default and cfg.get("auto_data", True):
            (generate or generate_default)(root, spec)
            made.append(root)
            continue
        if spec is not None:
            raise SystemExit(f"no dataset at {_shown(root)}: make it with `{synth_command(root, spec)}` "
                             f"(about {_minutes(spec)} on a 2-core CPU)")
        raise SystemExit(f"no dataset at {_shown(root)} (no manifest.yaml, no clip folders): pass data.root=DIR, a "
                         f"folder of clip folders as rally3d label writes them, or make synthetic clips with "
                         f"`{synth_command('data/synth_padel', DEFAULT_DATASETS['synth_padel'])}`")
    return made


def _minutes(spec: dict) -> str:
    frames = spec["clips"] * spec["max_frames"] * 0.86  # rallies end before max_frames ~14 % of the time
    return f"{max(1, round(frames / SYNTH_FPS_2CORE / 60))} min"


def generate_default(root: str | Path, spec: dict) -> None:
    """Generate a default dataset with a progress bar (what ``rally3d synth`` does)."""
    from tqdm import tqdm

    from training.synth.generate import SynthConfig, generate_dataset

    print(f"{_shown(root)} does not exist: generating the default dataset now — {spec['clips']} {spec['sport']} "
          f"clips of up to {spec['max_frames']} frames, about {_minutes(spec)} on a 2-core CPU "
          f"(same as `{synth_command(root, spec)}`; Ctrl-C stops, auto_data=false skips this)", flush=True)
    t0 = time.perf_counter()
    frames = [0]
    tty = os.isatty(2)
    with tqdm(total=spec["clips"], unit="clip", desc=f"synth {spec['sport']}", disable=not tty) as bar:
        def progress(k, summary):
            frames[0] += summary.n_frames
            bar.update(1)
            if not tty and (k % 4 == 0 or k == spec["clips"]):  # a log file gets lines, not a bar
                print(f"  {k}/{spec['clips']} clips, {frames[0]} frames, {time.perf_counter() - t0:.0f} s", flush=True)

        generate_dataset(root, spec["clips"], spec["seed"],
                         SynthConfig(sport=spec["sport"], max_frames=spec["max_frames"], **spec.get("config", {})),
                         progress=progress)
    print(f"wrote {spec['clips']} clips ({frames[0]} frames) to {_shown(root)} in "
          f"{(time.perf_counter() - t0) / 60:.1f} min", flush=True)
