"""``clip.yaml``: what a clip is (sport, frame rate, image size, where its frames are).

Example::

    sport: padel
    fps: 30.0
    width: 1920
    height: 1080
    video: video.mp4        # or frames/
    n_frames: 912           # optional
    camera_id: cam0         # optional; so are split, source, licence
    source: {url: https://example.org/match, t0: 812.4}   # provenance: any YAML value
    court: ../courts/padel_indoor.yaml   # optional, overrides conf/court/<sport>.yaml

Unknown keys are kept in :attr:`ClipInfo.extra` and written back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from .atomic import atomic_write_text
from .csvtable import read_text
from .errors import FormatError
from .structured import parse_yaml, yaml_key_lines

REQUIRED_KEYS = ("sport", "fps", "width", "height", "video")
OPTIONAL_TEXT_KEYS = ("camera_id", "split", "licence", "court")


class ClipInfoError(ValueError):
    """A ``ValueError`` about one field of :class:`ClipInfo` (``key`` names it)."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


@dataclass
class ClipInfo:
    """The contents of ``clip.yaml``.

    Attributes:
        sport: names the court file ``conf/court/<sport>.yaml`` (e.g. ``padel``, ``tennis``).
        fps: frames per second, > 0.
        width, height: image size in pixels, > 0.
        video: the frames, relative to the clip folder: a video file (``video.mp4``) or a folder
            of JPEGs (``frames/``).
        n_frames: number of frames, when known (> 0).
        camera_id, split, licence: free text, optional.
        source: provenance, optional: any YAML value (text, a mapping, a list ...), kept as written.
        court: path to a court YAML (relative to the clip folder), overriding ``sport``'s default.
        extra: unknown keys, kept on a round trip.
    """

    sport: str
    fps: float
    width: int
    height: int
    video: str
    n_frames: int | None = None
    camera_id: str | None = None
    split: str | None = None
    source: Any = None
    licence: str | None = None
    court: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.sport = _text(self.sport, "sport")
        self.video = _text(self.video, "video")
        self.fps = _positive_number(self.fps, "fps")
        self.width = _positive_int(self.width, "width")
        self.height = _positive_int(self.height, "height")
        if self.n_frames is not None:
            self.n_frames = _positive_int(self.n_frames, "n_frames")
        for key in OPTIONAL_TEXT_KEYS:
            value = getattr(self, key)
            if value is not None:
                setattr(self, key, _text(value, key))
        if not isinstance(self.extra, dict):
            raise ClipInfoError("extra", "extra must be a dict")

    @property
    def is_frames_folder(self) -> bool:
        """Whether :attr:`video` names a folder of frames rather than a video file."""
        return self.video.endswith("/") or "." not in Path(self.video).name

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ClipInfo:
        """Build from a parsed ``clip.yaml`` mapping; unknown keys go to :attr:`extra`."""
        missing = [key for key in REQUIRED_KEYS if key not in data]
        if missing:
            raise ClipInfoError(missing[0], f"missing key(s) {missing}")
        known = {f.name for f in fields(cls)} - {"extra"}
        extra = {k: v for k, v in data.items() if k not in known}
        return cls(**{k: v for k, v in data.items() if k in known}, extra=extra)

    def to_dict(self) -> dict[str, Any]:
        """The ``clip.yaml`` mapping: known keys in a fixed order (None left out), then :attr:`extra`."""
        data = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "extra"}
        return {**{k: v for k, v in data.items() if v is not None}, **self.extra}


def _text(value: Any, key: str) -> str:
    if isinstance(value, bool) or not isinstance(value, str | int | float) or str(value).strip() == "":
        raise ClipInfoError(key, f"{key} must be a non-empty string, got {value!r}")
    return str(value)


def _positive_number(value: Any, key: str) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ClipInfoError(key, f"{key} must be a number > 0, got {value!r}")
    return float(value)


def _positive_int(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        if isinstance(value, float) and value.is_integer() and value > 0:
            return int(value)
        raise ClipInfoError(key, f"{key} must be a whole number > 0, got {value!r}")
    return int(value)


# ----------------------------------------------------------------------------------------- file I/O
def read_clip_yaml(path: str | Path) -> ClipInfo:
    """Read and validate ``clip.yaml``; ``FormatError`` names the line of the offending key."""
    path = Path(path)
    text = read_text(path)
    data = parse_yaml(path, text)
    lines = yaml_key_lines(path, text)
    if not isinstance(data, dict):
        raise FormatError(
            path,
            "expected a mapping of 'key: value' lines" if data is not None else "empty file",
            line=1,
            fix=f"write at least: {', '.join(REQUIRED_KEYS)}",
        )
    try:
        return ClipInfo.from_dict(data)
    except ClipInfoError as err:
        fix = (
            f"clip.yaml needs {', '.join(REQUIRED_KEYS)}"
            if err.key not in data
            else f"correct the value of {err.key}"
        )
        raise FormatError(path, str(err), line=lines.get(err.key), fix=fix) from None
    except TypeError as err:  # e.g. a key that is not a string
        raise FormatError(path, str(err), fix="use plain 'key: value' lines") from None


def write_clip_yaml(path: str | Path, info: ClipInfo) -> Path:
    """Write ``info`` to ``clip.yaml`` atomically (deterministic key order)."""
    text = yaml.safe_dump(info.to_dict(), sort_keys=False, default_flow_style=False, allow_unicode=True)
    return atomic_write_text(path, text)
