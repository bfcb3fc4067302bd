"""Resumable runs: what each stage consumed and produced, kept in ``<clip>/.rally3d/pipeline.json``.

A stage is skipped when its *key* (the fingerprints of its input files, its parameters and the source of
the code that computes it) equals the recorded one and its outputs still have the recorded fingerprints:
after an upgrade of rally3d, the stages whose code changed run again instead of keeping stale outputs.
Outputs that exist but were not written by the pipeline (hand annotations, say) are never overwritten
silently.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
from pathlib import Path
from typing import Any

from inference.clipio import atomic
from inference.clipio.atomic import atomic_write_text
from inference.clipio.errors import FormatError
from inference.clipio.structured import load_json

STATE_DIR = ".rally3d"
STATE_FILE = "pipeline.json"
_HASH_LIMIT = 64 << 20  # larger files (videos) are fingerprinted by size and modification time
_HASHES: dict[tuple[str, int, int], str] = {}  # (path, size, mtime_ns) → content hash


def fingerprint(path: Path) -> str | None:
    """A fingerprint of a file's content (sha256; size+mtime for files over 64 MiB); None if missing."""
    path = Path(path)
    if not path.is_file():
        return None
    st = path.stat()
    if st.st_size > _HASH_LIMIT:
        return f"size:{st.st_size}:mtime:{st.st_mtime_ns}"
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:  # the video is an input of several stages: read each unchanged file once
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _HASHES[key] = "sha256:" + h.hexdigest()
    return _HASHES[key]


def backup_file(clip_root: Path, path: Path) -> Path:
    """Copy ``path`` into ``<clip>/.rally3d/backup/<name>.<timestamp>`` (before it is replaced); the copy's path."""
    return atomic.backup_file(path, Path(clip_root) / STATE_DIR / "backup")


@functools.cache
def code_fingerprint(modules: tuple[str, ...]) -> str:
    """sha256 of the Python source of ``modules`` (a package counts with every ``.py`` file under it).

    Raises ModuleNotFoundError for a name that is not importable (a typo in a stage's list must not pass)."""
    h = hashlib.sha256()
    for name in sorted(modules):
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            raise ModuleNotFoundError(f"no module {name!r} to fingerprint")
        origin = Path(spec.origin)
        files = sorted(origin.parent.rglob("*.py")) if origin.name == "__init__.py" else [origin]
        for f in files:
            h.update(f"{name}:{f.relative_to(origin.parent).as_posix()}\0".encode())
            h.update(f.read_bytes())
    return "sha256:" + h.hexdigest()


def stage_key(inputs: dict[str, Path | None], params: dict[str, Any], code: tuple[str, ...] = ()) -> str:
    """Key of one stage run: fingerprints of its inputs (by role), its parameters and its code's source."""
    blob = json.dumps({"inputs": {k: fingerprint(p) if p is not None else None for k, p in sorted(inputs.items())},
                       "params": params, "code": code_fingerprint(tuple(code)) if code else None},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


class RunState:
    """The pipeline record of one clip folder."""

    def __init__(self, clip_root: Path):
        self.root = Path(clip_root)
        self.path = self.root / STATE_DIR / STATE_FILE
        self.stages: dict[str, dict[str, Any]] = {}
        if self.path.is_file():
            try:
                stages = load_json(self.path).get("stages", {})
                self.stages = {k: v for k, v in stages.items() if isinstance(v, dict)}
            except (FormatError, AttributeError):
                self.stages = {}  # a damaged record only costs a re-run

    def is_current(self, stage: str, key: str, outputs: list[Path]) -> bool:
        """Whether ``stage`` already ran with this key and its outputs are unchanged since."""
        rec = self.stages.get(stage)
        if not rec or rec.get("key") != key or rec.get("status") != "done":
            return False
        written = rec.get("outputs", {})
        return all(written.get(p.name) == fingerprint(p) is not None for p in outputs) and \
            all(fingerprint(p) is not None for p in outputs)

    def written_by_pipeline(self, path: Path) -> bool:
        """Whether ``path`` is missing or is exactly what some stage of the pipeline wrote there."""
        fp = fingerprint(path)
        if fp is None:
            return True
        return any(rec.get("outputs", {}).get(path.name) == fp for rec in self.stages.values())

    def record(self, stage: str, key: str, status: str, outputs: list[Path], seconds: float,
               note: str = "") -> None:
        """Remember a stage's result and save the record atomically."""
        self.stages[stage] = {"key": key, "status": status, "seconds": round(seconds, 3), "note": note,
                              "outputs": {p.name: fingerprint(p) for p in outputs}}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.path, json.dumps({"stages": self.stages}, indent=2, sort_keys=True) + "\n")
