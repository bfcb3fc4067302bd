"""Where training data come from: a dataset folder with ``manifest.yaml``, a plain folder of clip folders as
the labeler writes them (a manifest is inferred and printed), or several of these mixed with weights.

``data.root`` accepts one path or a list (``data.root=[real_clips,data/synth_padel]``) and
``data.root_weights`` the share of training samples each root gets (default: in proportion to its size).

An inferred manifest splits by clip, or by match when ``clip.yaml`` names one (``match: …``), with a seeded
assignment that gives every split at least one clip (group) once there are three; a ``split`` written in a
clip's ``clip.yaml`` is kept. Nothing is written into the dataset folder: the run keeps a copy of the
inferred manifest (:func:`save_inferred`).

Example:
    >>> sources = resolve_sources(["my_clips", "data/synth_padel"], weights=[3, 1], seed=1234)
    >>> sources[0].paths("train")                         # clip folders of the train split of my_clips
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inference.clipio import Clip, Manifest, ManifestEntry
from inference.clipio.manifest import SPLITS, clip_folders, is_manifest_file

log = logging.getLogger(__name__)

FRACTIONS = (0.8, 0.1, 0.1)


@dataclass
class DataSource:
    """One root of a (possibly mixed) dataset.

    Attributes:
        root: the folder; manifest: its clips and splits; inferred: the manifest was built here (the
        folder has no manifest.yaml); weight: its share of training samples (None: by size).
    """

    root: Path
    manifest: Manifest
    inferred: bool = False
    weight: float | None = None
    stated: int = 0          # clips whose clip.yaml states their split (inferred manifests)
    carved: list[str] = field(default_factory=list)  # training clips moved to val (no val split was given)

    def eval_split(self) -> str:
        """What ``split=auto`` scores: every clip of a plain folder whose clips state no split, else the
        test split (a folder where any clip says ``split:`` is a dataset like one with manifest.yaml)."""
        return "all" if self.inferred and not self.stated else "test"

    def paths(self, split: str | None) -> list[Path]:
        """Clip folders of ``split`` (``None`` or ``all``: every clip)."""
        return self.manifest.paths(None if split in (None, "all") else split)

    def describe(self) -> str:
        counts = self.manifest.counts()
        how = "inferred (no manifest.yaml)" if self.inferred else "manifest.yaml"
        return f"{self.root}: {sum(counts.values())} clips, " + ", ".join(f"{s} {counts[s]}" for s in SPLITS) + f" [{how}]"


def group_of(clip: Clip, name: str) -> str:
    """The split group of a clip: ``clip.yaml``'s ``match`` when it names one, else the clip itself."""
    match = clip.info.extra.get("match")
    return f"match:{match}" if match not in (None, "") else f"clip:{name}"


def infer_manifest(root: str | Path, seed: int = 0, fractions: Sequence[float] = FRACTIONS) -> Manifest:
    """A manifest for a folder of clip folders (see the module docstring). Raises FileNotFoundError
    naming the folder when it holds no clip folder."""
    return _infer(root, seed, fractions)[0]


def _infer(root: str | Path, seed: int, fractions: Sequence[float]) -> tuple[Manifest, int]:
    """:func:`infer_manifest` and how many clips state their split in clip.yaml."""
    from synth.generate import split_assignment

    root = Path(root)
    folders = clip_folders(root) if root.is_dir() else []
    if not folders:
        raise FileNotFoundError(f"{root} holds no clip folders (no */clip.yaml) and no manifest.yaml: point "
                                "data.root to a folder of clips (as rally3d label writes them) or a dataset")
    fixed, groups = {}, {}
    for f in folders:
        clip = Clip(root / f)
        info = clip.info  # a bad clip.yaml is a FormatError naming the file and line
        if info.split in SPLITS:
            fixed[f] = info.split
        else:
            groups.setdefault(group_of(clip, f), []).append(f)
    names = sorted(groups)
    assigned = dict(zip(names, split_assignment(len(names), tuple(fractions), np.random.default_rng(seed))))
    split = {**fixed, **{f: assigned[g] for g, fs in groups.items() for f in fs}}
    by_match = any(g.startswith("match:") for g in names)
    return Manifest(root, [ManifestEntry(f, split[f]) for f in folders], name=root.name,
                    source=f"inferred by rally3d training: split by {'match' if by_match else 'clip'}, seed {seed}"
                    ), len(fixed)


def carve_val(manifest: Manifest, seed: int = 0, fraction: float = FRACTIONS[1]) -> list[str]:
    """Give a manifest with training clips but no val split one: a seeded ``fraction`` of the training
    groups (clip.yaml's ``match``, else the clip; at least one) become ``val``, never the last training
    group. Returns the clips moved (changed in place; none when there is a val split or < 2 groups)."""
    if any(c.split == "val" for c in manifest.clips):
        return []
    groups: dict[str, list[int]] = {}
    for i, c in enumerate(manifest.clips):
        if c.split == "train":
            path = manifest.root / c.path
            key = group_of(Clip(path), c.path) if (path / "clip.yaml").is_file() else f"clip:{c.path}"
            groups.setdefault(key, []).append(i)
    if len(groups) < 2:
        return []
    names = sorted(groups)
    k = min(max(int(round(len(names) * fraction)), 1), len(names) - 1)
    moved = sorted(i for j in np.random.default_rng(seed).permutation(len(names))[:k] for i in groups[names[j]])
    for i in moved:
        manifest.clips[i] = ManifestEntry(manifest.clips[i].path, "val")
    return sorted(manifest.clips[i].path for i in moved)


def resolve_source(root: str | Path, seed: int = 0, fractions: Sequence[float] = FRACTIONS,
                   weight: float | None = None) -> DataSource:
    """A :class:`DataSource` for a dataset folder (manifest.yaml), a manifest.yaml itself (e.g. one a run saved,
    :func:`save_inferred`) or a folder of clip folders; never a folder ``rally3d synth`` left unfinished
    (FileNotFoundError naming it and the fix)."""
    from training.preflight import refuse_unfinished

    root = Path(root)
    refuse_unfinished(root)
    if (root / "manifest.yaml").is_file() or is_manifest_file(root):
        manifest = Manifest.load(root)
        source = DataSource(manifest.root, manifest, False, weight)
    elif (root / "clip.yaml").is_file():  # a single clip folder: a dataset of one clip
        return DataSource(root.parent, Manifest(root.parent, [ManifestEntry(root.name, "train")], name=root.name,
                                                source="a single clip folder"), True, weight)
    else:
        manifest, stated = _infer(root, seed, fractions)
        source = DataSource(root, manifest, True, weight, stated)
    source.carved = carve_val(source.manifest, seed, fractions[1] / max(sum(fractions), 1e-9))
    if source.carved:
        log.info("%s has no val split: validating on %d training clip(s) set aside by clip (seed %d): %s", root,
                 len(source.carved), seed, ", ".join(source.carved))
    return source


def as_list(root) -> list[str]:
    """``data.root`` as a list of paths (one path, a list, or None → [])."""
    if root is None:
        return []
    if isinstance(root, (str, Path)):
        return [str(root)]
    return [str(r) for r in root]


def resolve_sources(root, weights: Sequence[float] | None = None, seed: int = 0,
                    fractions: Sequence[float] = FRACTIONS) -> list[DataSource]:
    """Every root of ``data.root`` resolved, with its weight; inferred manifests are logged."""
    roots = as_list(root)
    if not roots:
        raise ValueError("no data.root given: pass a dataset folder or a folder of clip folders")
    if weights is not None and len(weights) != len(roots):
        raise ValueError(f"data.root_weights has {len(weights)} values for {len(roots)} roots: give one per root")
    if weights is not None and (min(weights) < 0 or sum(weights) <= 0):
        raise ValueError(f"data.root_weights must be ≥ 0 with a positive sum, got {list(weights)}")
    sources = [resolve_source(r, seed, fractions, None if weights is None else float(w))
               for r, w in zip(roots, weights if weights is not None else [None] * len(roots))]
    for s in sources:
        if s.inferred:
            log.info("dataset %s\n%s", s.describe(), format_manifest(s.manifest))
    return sources


def format_manifest(manifest: Manifest) -> str:
    """One line per split: its clips."""
    lines = []
    for split in SPLITS:
        clips = [c.path for c in manifest.clips if c.split == split]
        lines.append(f"  {split:5s} {len(clips):3d}: {', '.join(clips) if clips else '-'}")
    return "\n".join(lines)


def save_inferred(sources: Sequence[DataSource], out_dir: str | Path) -> list[Path]:
    """Write each inferred manifest to ``out_dir/manifest_<k>_<name>.yaml`` (paths absolute, so the file
    can be copied into the dataset folder, or passed on as it is, to fix the split)."""
    written = []
    for k, s in enumerate(sources):
        if not s.inferred:
            continue
        entries = [ManifestEntry(str((s.root / c.path).resolve()), c.split) for c in s.manifest.clips]
        m = Manifest(Path(out_dir), entries, name=s.manifest.name, source=s.manifest.source)
        written.append(m.save(Path(out_dir) / f"manifest_{k}_{s.root.name or 'root'}.yaml"))
    return written


def ball_input(clip: Clip, override: str = "auto") -> str:
    """What a clip's ``ball.csv`` is: ``annotated``, ``tracker`` or ``detector``.

    ``auto``: ``detector`` when ``rally3d infer`` wrote it (its record in ``.rally3d/``), else
    ``annotated`` (labeler, synthetic ground truth, imported labels). A tracker's file imported from
    elsewhere cannot be recognised: say so with ``ball_input=tracker``.
    """
    if override != "auto":
        return override
    from inference.pipeline.state import RunState

    state = RunState(clip.root)
    if state.stages and clip.ball_path.is_file() and state.written_by_pipeline(clip.ball_path):
        return "detector"
    return "annotated"


def skip_unlabelled(clips: list[Clip], needs: str, where: str) -> list[Clip]:
    """The clips that have ``needs`` (``ball.csv`` or ``events.csv``); the others are skipped with one
    warning (a clip the annotator has not labelled yet is not an error)."""
    keep, skipped = [], []
    for c in clips:
        (keep if (c.root / needs).is_file() else skipped).append(c)
    if skipped:
        log.warning("%s: %d clip(s) without %s skipped (not labelled yet): %s", where, len(skipped), needs,
                    ", ".join(c.root.name for c in skipped[:8]) + (" …" if len(skipped) > 8 else ""))
    return keep


__all__ = ["DataSource", "as_list", "ball_input", "carve_val", "clip_folders", "format_manifest", "infer_manifest",
           "resolve_source", "resolve_sources", "save_inferred", "skip_unlabelled"]
