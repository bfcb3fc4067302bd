"""A tennis event dataset from TrackNet ``Label.csv`` files (status 1 hit / 2 bounce → events).

Example:
    >>> convert_tracknet_dataset({"train": [a_csv], "val": [b_csv], "test": [c_csv]}, "data/tracknet_events",
    ...                          fps=30, width=1280, height=720)
"""
from __future__ import annotations

from pathlib import Path

from inference.clipio import Clip, ClipInfo, Manifest, ManifestEntry, import_tracknet_label


def convert_tracknet_label(label_csv: str | Path, out: str | Path, *, fps: float, width: int, height: int,
                           split: str | None = None) -> Clip:
    """One ``Label.csv`` → a clip folder (clip.yaml, ball.csv, events.csv; no video)."""
    track, events = import_tracknet_label(label_csv, width, height)
    n = int(track.frame[-1]) + 1 if len(track) else 0
    clip = Clip.create(out, ClipInfo(sport="tennis", fps=float(fps), width=int(width), height=int(height),
                                     video="video.mp4", n_frames=n, camera_id=None, split=split,
                                     source=f"TrackNet Label.csv {Path(label_csv).name}", licence=None, court=None,
                                     extra={}), exist_ok=True)
    clip.write_ball(track)
    clip.write_events(events)
    return clip


def convert_tracknet_dataset(splits: dict[str, list[str | Path]], out: str | Path, *, fps: float, width: int,
                             height: int) -> Manifest:
    """Several ``Label.csv`` per split → a dataset folder with ``manifest.yaml``."""
    out = Path(out)
    entries = []
    for split, files in splits.items():
        for k, f in enumerate(files):
            name = f"{split}_{k:03d}"
            convert_tracknet_label(f, out / name, fps=fps, width=width, height=height, split=split)
            entries.append(ManifestEntry(name, split))
    manifest = Manifest(out, entries, name=out.name, sport="tennis", source="TrackNet Label.csv", extra={})
    manifest.save()
    return manifest
