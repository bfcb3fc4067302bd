"""The marker of an unfinished generation (``rally3d synth`` / :func:`~synth.generate.generate_dataset`
interrupted): a folder holding :data:`PARTIAL` is never read as a dataset, and generating it again resumes it.
Read by the generator and by the training run's dataset checks (:mod:`training.preflight`)."""
from __future__ import annotations

from pathlib import Path

import yaml

PARTIAL = ".synth_partial.yaml"
"""The marker of a generation in progress in a dataset folder (``synth.generate.generate_dataset``):
written before the first clip, removed after ``manifest.yaml``. A folder holding it is unfinished: it is never
read as a dataset, and generating it again resumes it."""


def unfinished_generation(out: str | Path) -> str | None:
    """What an interrupted ``generate_dataset`` left in ``out``, in words (``an unfinished `rally3d synth
    --sport padel --clips 24 --seed 10` (3 of 24 clips made, no manifest.yaml)``); None when it left nothing."""
    state = read_marker(Path(out))
    if state is None:
        return None
    plan = state.get("plan") or {}
    return (f"an unfinished `{state.get('source', 'rally3d synth')}` ({len(state.get('done') or {})} of "
            f"{plan.get('n_clips', '?')} clips made, no manifest.yaml)")


def refuse_unfinished(out: str | Path) -> None:
    """Raise :class:`FileNotFoundError` naming ``out`` and the fix when it is an unfinished generation."""
    why = unfinished_generation(out)
    if why:
        raise FileNotFoundError(f"{out} is {why}: it is not a dataset until it is finished — run the same generation "
                                f"again into {out} (it resumes where it stopped), or delete the folder")


def read_marker(out: Path) -> dict | None:
    """The :data:`PARTIAL` marker of ``out`` (an unreadable one counts as a marker without clips)."""
    path = out / PARTIAL
    if not path.is_file():
        return None
    try:
        state = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        state = None
    return state if isinstance(state, dict) else {}
