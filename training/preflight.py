"""Checks that run before anything heavy is imported or built (no torch, no Lightning): the first command
on a fresh clone either makes its small default dataset or stops at once with one line naming the fix.

``python train.py +experiment=wasb_padel`` reads ``data.root`` (default ``data/synth_padel``):

- it exists (a dataset folder with ``manifest.yaml``, or clip folders): go on; a default dataset of
  :data:`DEFAULT_DATASETS` only when finished (``manifest.yaml``, no marker of an interrupted generation), and
  no folder that ``rally3d synth`` left unfinished (Ctrl-C) is ever read as a dataset;
- it is a default dataset of :data:`DEFAULT_DATASETS`, missing or unfinished, and ``auto_data`` is true (the
  default): it is generated (or resumed) now, with a progress bar, after a line saying what and about how long;
- otherwise: :class:`SystemExit` with one line: the folder and the exact ``rally3d synth`` command (or
  how to point ``data.root`` elsewhere).

Then every clip of every root is read the way the run will read it (:func:`check_clips`, the same checks as
``rally3d check``): a run never stops at its first broken clip; it stops before training with every problem
(file, line, fix) and a summary, or goes on.
"""
from __future__ import annotations

import os
import shlex
import time
from pathlib import Path


# the generator's unfinished-folder marker lives with the generator; named here for the dataset checks
from synth.partial import PARTIAL, read_marker, refuse_unfinished, unfinished_generation  # noqa: F401

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
    """A dataset folder (manifest.yaml) or a manifest.yaml, a clip folder, or a folder with clip folders below it."""
    from inference.clipio.manifest import is_manifest_file

    root = Path(root)
    if (root / "manifest.yaml").is_file() or (root / "clip.yaml").is_file() or is_manifest_file(root):
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


def init_source(cfg) -> str | None:
    """The weights a run starts from: ``init_weights``, or its older spelling ``model.pretrained``."""
    return cfg.get("init_weights") or (cfg.model.get("pretrained") if "model" in cfg else None) or None


def require_eval_weights(cfg) -> None:
    """A detector's evaluation needs a model file: say so before any data is checked or generated (the
    default dataset takes minutes to make). Hit-event models evaluate the shipped file without one.

    Raises:
        ValueError: no ``ckpt_path`` (nor ``init_weights``); FileNotFoundError: the file is not there.
    """
    if cfg.get("task") == "events":
        return
    path = cfg.get("ckpt_path") or init_source(cfg)
    if not path:
        raise ValueError("eval needs ckpt_path=PATH: a model file or checkpoint (ours, Lightning or WASB-SBDT's)")
    if not Path(str(path)).is_file():
        raise FileNotFoundError(f"checkpoint {path} not found")


def check_data(cfg, generate=None) -> list[str]:
    """Make sure every ``data.root`` exists and every clip of it can be read (see the module docstring);
    returns the roots generated."""
    made = []
    for root in data_roots(cfg):
        name = Path(root).name
        spec = DEFAULT_DATASETS.get(name)
        default_dir = Path(str(cfg.paths.data_dir)) / name if cfg.get("paths") else None
        if spec is not None and default_dir is not None and Path(root).resolve() == default_dir.resolve():
            why = default_dataset_state(root)
            if why is None:
                continue
            if not cfg.get("auto_data", True):
                raise SystemExit(f"{_shown(root)} {why}: make it with `{synth_command(root, spec)}` "
                                 f"(about {_minutes(spec)} on a 2-core CPU)")
            (generate or generate_default)(root, spec)
            made.append(root)
            continue
        try:
            refuse_unfinished(root)
        except FileNotFoundError as e:
            raise SystemExit(str(e)) from None
        if not dataset_exists(root):
            raise SystemExit(f"no dataset at {_shown(root)} (no manifest.yaml, no clip folders): pass data.root=DIR, "
                             f"a folder of clip folders as rally3d label writes them, or make synthetic clips with "
                             f"`{synth_command('data/synth_padel', DEFAULT_DATASETS['synth_padel'])}`")
    key = _checked_key(cfg)
    if key not in _CHECKED:  # train.py checks before importing torch, run.train again for API callers: once
        check_clips(cfg)
        _CHECKED.add(key)
    return made


def default_dataset_state(root: str | Path) -> str | None:
    """Why a default dataset folder must be made (``does not exist``, ``is an unfinished …``, ``holds 3 generated
    clip folders but no manifest.yaml …``); None when it is finished, or holds clips a person made (read as they are)."""
    from synth.cli import check_out_folder

    root = Path(root)
    if not root.exists():
        return "does not exist"
    why = unfinished_generation(root)
    if why:
        return f"is {why}"
    if (root / "manifest.yaml").is_file():
        return None
    clips = list(root.glob("*/clip.yaml"))
    try:
        check_out_folder(root)  # a clip rally3d synth did not make: a person's folder, read as it is
    except ValueError:
        return None
    return (f"holds {len(clips)} generated clip folders but no manifest.yaml (an interrupted generation)" if clips
            else "holds no dataset")


#: the data settings whose clips :func:`check_clips` already passed in this process
_CHECKED: set[str] = set()


def _checked_key(cfg) -> str:
    """The data settings that decide what :func:`check_clips` reads, as one string."""
    from omegaconf import OmegaConf

    data = cfg.get("data")
    return repr((cfg.get("task"), OmegaConf.to_container(data, resolve=True) if data is not None else None))


def detector_files(root: Path) -> tuple[str, ...]:
    """What a detector run reads of a clip folder: the video and ball.csv; clip.yaml alone for a clip without
    ball.csv (not labelled yet: the run skips it with a warning)."""
    return ("video", "ball.csv") if (root / "ball.csv").is_file() else ()


def event_files(root: Path) -> tuple[str, ...]:
    """What a hit-event run reads of a clip folder: ball.csv and gt/events.csv (else events.csv), and the
    video only to count the frames when clip.yaml has no ``n_frames``; clip.yaml alone for a clip without
    them (skipped with a warning)."""
    from inference.clipio import Clip, FormatError

    events = "gt/events.csv" if (root / "gt" / "events.csv").is_file() else "events.csv"
    if not ((root / "ball.csv").is_file() and (root / events).is_file()):
        return ()
    clip = Clip(root)
    try:
        counted = clip.info.n_frames is None and clip.video_path.exists()
    except FormatError:  # clip.yaml's own problem: check_clip reports it
        counted = False
    return ("ball.csv", events, *(("video",) if counted else ()))


def event_labels(cfg) -> list[str] | None:
    """The events.csv labels a hit-event run can learn from: those its class set maps (``on_unmapped:
    error``, the default, stops at any other); None (any label) for detectors or ``on_unmapped: warn``."""
    data = cfg.get("data") or {}
    if cfg.get("task") != "events" or data.get("on_unmapped", "error") != "error":
        return None
    from inference.clipio.tables import EVENT_LABELS
    from inference.events.classes import ClassSet

    classes = ClassSet.load(data.get("class_set", "padel6"))
    return [label for label in EVENT_LABELS if classes.encode_label(label) is not None]


def check_clips(cfg) -> None:
    """Read every clip of every ``data.root`` the way the run will (:func:`detector_files`,
    :func:`event_files`; the checks of ``rally3d check``) and stop before anything is trained, with every
    problem (file, line, fix) and a summary; return quietly when every clip can be read."""
    roots = [r for r in data_roots(cfg) if dataset_exists(r)]  # a missing one was made or named by check_data
    if not roots:
        return
    from inference.cli_commands import check_paths

    files = event_files if cfg.get("task") == "events" else detector_files
    report = check_paths([Path(r) for r in roots], files=files, labels=event_labels(cfg))
    lines = [str(e) for e in report.problems]
    if report.clips and not any(files(c.root) for c in report.clips):
        what = "ball.csv and events.csv" if files is event_files else "ball.csv"
        lines.append(f"none of the {len(report.clips)} clips has {what}: nothing to train on — label them "
                     "(rally3d label DIR) or point data.root to labelled clips")
    if lines:
        shown = " ".join(shlex.quote(_shown(r)) for r in roots)
        raise SystemExit(f"data.root: {report.summary() if report.problems else 'no clip is labelled'}. Nothing was "
                         f"trained; fix this, then run again (`.venv/bin/rally3d check {shown}` checks every clip):\n"
                         + "\n".join(f"  {ln}" for ln in lines))


def _minutes(spec: dict) -> str:
    frames = spec["clips"] * spec["max_frames"] * 0.86  # rallies end before max_frames ~14 % of the time
    return f"{max(1, round(frames / SYNTH_FPS_2CORE / 60))} min"


def generate_default(root: str | Path, spec: dict) -> None:
    """Generate a default dataset with a progress bar (what ``rally3d synth`` does); an unfinished one is
    resumed (``generate_dataset``)."""
    from tqdm import tqdm

    from synth.generate import SynthConfig, generate_dataset

    print(f"{_shown(root)} {default_dataset_state(root) or 'is made again'}: generating the default dataset now — "
          f"{spec['clips']} {spec['sport']} clips of up to {spec['max_frames']} frames, about {_minutes(spec)} on a "
          f"2-core CPU (same as `{synth_command(root, spec)}`; Ctrl-C stops, running again resumes, auto_data=false "
          "skips this)", flush=True)
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
