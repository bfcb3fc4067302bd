"""Dataset manifests: which clip folders make up a dataset and which split each belongs to.

``manifest.yaml`` sits in the dataset root::

    name: synth_padel
    sport: padel
    source: rally3d synth --sport padel --clips 20 --seed 0
    clips:
      - {path: clip_0000, split: train}
      - {path: clip_0001, split: val}

Paths are relative to the manifest's folder. An entry may name its folder with ``name:`` instead of
``path:`` (as other dataset tools write it), or be the folder name alone (``- clip_0002``). Splits are by clip (or by match: give all clips of a
match the same split), never by frame, so no rally leaks between training and evaluation.

A dataset may also be a plain folder of clip folders (no manifest): :func:`dataset_clips` lists the clips of
either form.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .atomic import atomic_write_text
from .errors import FormatError
from .structured import load_yaml

SPLITS = ("train", "val", "test")
SKIP_DIRS = {".cache", ".rally3d", "gt", "frames", "__pycache__"}
"""Folders never searched for clip folders (caches, ground truth, frame folders)."""
MANIFEST_FIX = "see datasets/README.md for the manifest layout"


@dataclass(frozen=True)
class ManifestEntry:
    """One clip of a dataset: its folder (relative to the manifest) and its split."""

    path: str
    split: str

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {self.split!r}")


@dataclass
class Manifest:
    """A dataset: clip folders with their splits.

    Attributes:
        root: the folder holding manifest.yaml (clip paths are relative to it).
        clips: the entries, in order.
        name, sport, source: descriptive fields; extra: other keys, kept on a round trip.
    """

    root: Path
    clips: list[ManifestEntry]
    name: str = ""
    sport: str = ""
    source: str = ""
    extra: dict = field(default_factory=dict)

    def paths(self, split: str | None = None) -> list[Path]:
        """Absolute clip folders, optionally of one split."""
        return [self.root / c.path for c in self.clips if split is None or c.split == split]

    def counts(self) -> dict[str, int]:
        return {s: sum(c.split == s for c in self.clips) for s in SPLITS}

    def save(self, path: str | Path | None = None) -> Path:
        """Write manifest.yaml atomically (default: ``root/manifest.yaml``)."""
        path = Path(path) if path else self.root / "manifest.yaml"
        data = {"name": self.name, "sport": self.sport, "source": self.source, **self.extra,
                "clips": [{"path": c.path, "split": c.split} for c in self.clips]}
        return atomic_write_text(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))

    @classmethod
    def load(cls, path: str | Path, *, skipped: list[FormatError] | None = None) -> Manifest:
        """Read a manifest.yaml (or the manifest.yaml inside a dataset folder).

        With ``skipped=[]`` an entry that cannot be used (no path, a bad split, a folder without clip.yaml)
        is left out and its error appended, one per entry; otherwise the first such entry raises.
        """
        path = Path(path)
        if path.is_dir():
            path = path / "manifest.yaml"
        data = load_yaml(path, fix=MANIFEST_FIX)
        if not isinstance(data, dict) or not isinstance(data.get("clips"), list):
            raise FormatError(path, "needs a `clips:` list of {path, split}", fix=MANIFEST_FIX)
        clips, bad = [], []
        for i, c in enumerate(data["clips"]):
            try:
                clips.append(_entry(path, i, c))
            except FormatError as e:
                bad.append(e)
        if bad and skipped is None:
            raise bad[0]
        missing = [c.path for c in clips if not (path.parent / c.path / "clip.yaml").is_file()]
        if missing and skipped is None:
            raise FormatError(path, f"clip folders without clip.yaml: {missing[:5]}",
                              fix="fix the paths (relative to the manifest) or remove the entries")
        if skipped is not None:
            skipped += bad + [FormatError(path, f"clip folder {m} has no clip.yaml (looked in {path.parent / m})",
                                          fix="fix the path (relative to the manifest) or remove the entry")
                              for m in missing]
        clips = [c for c in clips if c.path not in missing]
        known = {"name", "sport", "source", "clips"}
        return cls(path.parent, clips, str(data.get("name", "")), str(data.get("sport", "")),
                   str(data.get("source", "")), {k: v for k, v in data.items() if k not in known})

    @classmethod
    def from_folder(cls, root: str | Path, fractions: tuple[float, float, float] = (0.8, 0.1, 0.1),
                    group_key=None) -> Manifest:
        """A manifest for every clip folder under ``root``, split deterministically by hashing names.

        Args:
            fractions: train/val/test shares.
            group_key: maps a clip folder name to its group (e.g. the match); a group stays in one split.
        """
        root = Path(root)
        folders = sorted(p.parent.relative_to(root).as_posix() for p in root.rglob("clip.yaml"))
        clips = [ManifestEntry(f, split_of(group_key(f) if group_key else f, fractions)) for f in folders]
        return cls(root, clips, name=root.name)


def _entry(path: Path, i: int, c) -> ManifestEntry:
    """Entry ``i`` of manifest ``path``: ``{path, split}``, ``{name, split}`` or a folder name."""
    if isinstance(c, str) and c.strip():
        c = {"path": c}
    folder = c.get("path", c.get("name")) if isinstance(c, dict) else None
    if folder is None or not str(folder).strip():
        raise FormatError(path, f"clip entry {i} needs a `path` (or `name`): the clip folder",
                          fix="write `- {path: clip_0000, split: train}`")
    try:
        return ManifestEntry(str(folder), str(c.get("split", "train")))
    except ValueError as e:
        raise FormatError(path, f"clip entry {i} ({folder}): {e}", fix=f"use one of {', '.join(SPLITS)}") from None


def clip_folders(root: str | Path) -> list[str]:
    """Clip folders (holding ``clip.yaml``) under ``root``, relative, sorted; hidden and data folders
    (:data:`SKIP_DIRS`) skipped."""
    root = Path(root)
    out = []
    for p in sorted(root.rglob("clip.yaml")):
        rel = p.parent.relative_to(root)
        if any(part in SKIP_DIRS or part.startswith(".") for part in rel.parts):
            continue
        out.append(rel.as_posix() if rel.parts else ".")
    return out


def is_manifest_file(path: str | Path) -> bool:
    """``path`` is a YAML file: a manifest passed as it is (not the folder holding it)."""
    return Path(path).is_file() and Path(path).suffix in (".yaml", ".yml")


def dataset_clips(path: str | Path, *, skipped: list[FormatError] | None = None) -> list[Path]:
    """The clip folders of ``path``: itself (it holds clip.yaml), the entries of a manifest (``manifest.yaml``
    or a folder holding one; ``skipped`` as in :meth:`Manifest.load`), or the clip folders below a folder
    (:func:`clip_folders`). Empty when ``path`` is none of these."""
    path = Path(path)
    if (path / "clip.yaml").is_file():
        return [path]
    if (path / "manifest.yaml").is_file() or is_manifest_file(path):
        return Manifest.load(path, skipped=skipped).paths()
    return [path / f for f in clip_folders(path)] if path.is_dir() else []


def split_of(key: str, fractions: tuple[float, float, float] = (0.8, 0.1, 0.1)) -> str:
    """A stable split for ``key``: the same name always lands in the same split."""
    h = int(hashlib.sha1(key.encode()).hexdigest()[:8], 16) / 0xFFFFFFFF
    total = sum(fractions)
    edges = [fractions[0] / total, (fractions[0] + fractions[1]) / total]
    return SPLITS[0] if h < edges[0] else SPLITS[1] if h < edges[1] else SPLITS[2]
