"""Typed, validated containers for the per-clip tables (see docs/formats.md).

Each container is a dataclass of parallel numpy arrays, one row per entry. ``__post_init__`` coerces
the dtypes and raises ``ValueError`` naming the expected shape when the arrays do not fit together,
so an object that exists is always valid. Reading and writing files is in :mod:`.csvfiles`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

EVENT_LABELS: tuple[str, ...] = (
    "ground",
    "wall_near",
    "wall_far",
    "wall_left",
    "wall_right",
    "mesh",
    "net",
    "player_near",
    "player_far",
)
"""Fine-grained hit-event labels of ``events.csv``, as the annotator sees them."""

BALL3D_KINDS: tuple[str, ...] = ("fitted", "contact", "gt")
"""Values of the ``kind`` column of ``ball_3d.csv``."""

UNIT_TOLERANCE = 1e-6
"""Normalised coordinates this far outside ``[0, 1]`` are clipped; further out is an error."""

MAX_FRAMES = 4 * 60 * 60 * 240
"""Most frames a file may address when nothing states the clip's length: four hours of video at 240 fps
(3,456,000); a frame number beyond it is an error, never an allocation."""
MAX_FRAMES_TEXT = "four hours at 240 fps"


# --------------------------------------------------------------------------------------- validators
def as_vector(values, name: str, dtype, n: int | None = None) -> np.ndarray:
    """Return ``values`` as a 1-D array of ``dtype``; ``ValueError`` unless its shape is ``(n,)``."""
    arr = np.asarray(values)
    if arr.ndim == 0 and arr.size == 1 and n is None:
        raise ValueError(f"{name} must have shape (N,), got a scalar")
    if arr.size == 0:
        arr = arr.reshape(0)
    expected = "(N,)" if n is None else f"({n},)"
    if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
        raise ValueError(f"{name} must have shape {expected}, got {arr.shape}")
    if np.issubdtype(np.dtype(dtype), np.integer):
        return _as_integer(arr, name, dtype)
    return arr.astype(dtype, copy=False)


def _as_integer(arr: np.ndarray, name: str, dtype) -> np.ndarray:
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise ValueError(f"{name} must hold integers")
    elif arr.size and arr.dtype.kind not in "iub":
        raise ValueError(f"{name} must hold integers, got dtype {arr.dtype}")
    info = np.iinfo(dtype)
    if arr.size and (arr.min() < info.min or arr.max() > info.max):
        raise ValueError(f"{name} must fit in {np.dtype(dtype).name}")
    return arr.astype(dtype, copy=False)


def as_matrix(values, name: str, n: int, cols: int) -> np.ndarray:
    """Return ``values`` as a float64 array; ``ValueError`` unless its shape is ``(n, cols)``."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0 and n == 0:
        arr = arr.reshape(0, cols)
    if arr.shape != (n, cols):
        raise ValueError(f"{name} must have shape (N, {cols}) with N={n}, got {arr.shape}")
    return arr


def as_strings(values, name: str, n: int) -> np.ndarray:
    """Return ``values`` as a 1-D unicode string array of shape ``(n,)``."""
    arr = np.asarray(values, dtype=str) if len(values) else np.empty(0, dtype="<U1")
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    return arr


def check_frames(frame: np.ndarray, name: str = "frame", *, strict: bool = True) -> None:
    """Frames must be ``>= 0`` and increasing (strictly unless ``strict=False``)."""
    if frame.size and frame.min() < 0:
        raise ValueError(f"{name} must be >= 0 (zero-based frame indices)")
    steps = np.diff(frame)
    if np.any(steps <= 0 if strict else steps < 0):
        kind = "strictly increasing" if strict else "sorted (non-decreasing)"
        raise ValueError(f"{name} must be {kind}")


def clip_unit(xy: np.ndarray, name: str, *, allow_nan: bool = False) -> np.ndarray:
    """Check normalised coordinates lie in ``[0, 1]`` (within ``UNIT_TOLERANCE``) and clip them."""
    finite = np.isfinite(xy)
    if not allow_nan and not finite.all():
        raise ValueError(f"{name} must be finite")
    if np.any(np.isinf(xy)):
        raise ValueError(f"{name} must not be infinite")
    values = xy[finite]
    if values.size and (values.min() < -UNIT_TOLERANCE or values.max() > 1 + UNIT_TOLERANCE):
        raise ValueError(f"{name} must be normalised image coordinates in [0, 1]")
    return np.clip(xy, 0.0, 1.0)


def as_extra(extra, n: int, reserved) -> dict[str, np.ndarray]:
    """Unknown columns of a file, ``{name: (n,) str}``: kept on a round trip (a hand-added ``note`` column)."""
    if not isinstance(extra, dict):
        raise ValueError("extra must be a dict {column name: (N,) values}")
    out = {}
    for k, v in extra.items():
        name = str(k)
        if not name or name in reserved:
            raise ValueError(f"extra column name {name!r} is empty or a known column")
        out[name] = as_strings(list(np.asarray(v, dtype=str).reshape(-1)), f"extra[{name!r}]", n)
    return out


def _check_labels(values: np.ndarray, allowed: tuple[str, ...], name: str) -> None:
    unknown = sorted(set(values.tolist()) - set(allowed))
    if unknown:
        raise ValueError(f"{name} has unknown values {unknown}; valid: {', '.join(allowed)}")


class ArraysEqualMixin:
    """``==`` for dataclasses of arrays: equal when every field is equal (NaN equals NaN)."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(_equal(getattr(self, f.name), getattr(other, f.name)) for f in dataclasses.fields(self))

    __hash__ = None  # type: ignore[assignment]


def _equal(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return False
        if a.dtype.kind == "f" and b.dtype.kind == "f":
            return bool(np.array_equal(a, b, equal_nan=True))
        return bool(np.array_equal(a, b))
    return a == b


# --------------------------------------------------------------------------------------- ball track
class DenseBallTrack(NamedTuple):
    """A :class:`BallTrack` spread over every frame of a clip (index = frame).

    Attributes:
        labelled: ``(n_frames,) bool``, True where the track has a row.
        visibility: ``(n_frames,) int8``, 0..3, and -1 where not labelled.
        xy: ``(n_frames, 2) float64``, NaN where not labelled or not visible.
    """

    labelled: np.ndarray
    visibility: np.ndarray
    xy: np.ndarray


@dataclass(eq=False)
class BallTrack(ArraysEqualMixin):
    """The 2D ball of one clip (``ball.csv``): one row per annotated (or detected) frame.

    A frame with no row is *not labelled*, which differs from visibility 0 (*not in the frame*).

    Attributes:
        frame: ``(N,) int64``, zero-based frame indices, strictly increasing.
        visibility: ``(N,) int8``, 0 not in frame, 1 visible, 2 hard to see, 3 occluded.
        xy: ``(N, 2) float64``, normalised image coordinates ``(u, v)`` in ``[0, 1]``; NaN exactly
            where ``visibility == 0``.
        extra: unknown columns of the file, ``{name: (N,) str}``, written back unchanged.

    Examples:
        >>> t = BallTrack(frame=[0, 1], visibility=[1, 0], xy=[[0.5, 0.25], [np.nan, np.nan]])
        >>> t.to_pixels(1280, 720)[0].tolist()
        [640.0, 180.0]
    """

    frame: np.ndarray
    visibility: np.ndarray
    xy: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.frame = as_vector(self.frame, "frame", np.int64)
        n = len(self.frame)
        self.extra = as_extra(self.extra, n, ("frame", "visibility", "x", "y"))
        visibility = as_vector(self.visibility, "visibility", np.int64, n)
        if visibility.size and (visibility.min() < 0 or visibility.max() > 3):
            raise ValueError("visibility must be in 0..3")
        self.visibility = visibility.astype(np.int8)
        xy = as_matrix(self.xy, "xy", n, 2)
        check_frames(self.frame)
        hidden = self.visibility == 0
        if np.any(np.isnan(xy[~hidden])):
            raise ValueError("xy must be finite where visibility > 0")
        if not np.all(np.isnan(xy[hidden])):
            raise ValueError("xy must be NaN where visibility == 0")
        self.xy = clip_unit(xy, "xy", allow_nan=True)

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> BallTrack:
        """A track with no rows."""
        return cls(np.empty(0, np.int64), np.empty(0, np.int8), np.empty((0, 2)))

    @classmethod
    def from_pixels(cls, frame, visibility, xy_px, width: int, height: int) -> BallTrack:
        """Build a track from pixel coordinates ``xy_px (N, 2)`` of a ``width x height`` image."""
        xy = np.asarray(xy_px, dtype=np.float64) / np.array([width, height], dtype=np.float64)
        return cls(frame, visibility, xy)

    @property
    def visible_mask(self) -> np.ndarray:
        """``(N,) bool``, True where the ball is in the frame (visibility 1..3)."""
        return self.visibility > 0

    def to_pixels(self, width: int, height: int) -> np.ndarray:
        """Return ``(N, 2)`` pixel coordinates (NaN where not visible)."""
        return self.xy * np.array([width, height], dtype=np.float64)

    def at(self, frame: int) -> tuple[int, np.ndarray] | None:
        """``(visibility, xy (2,))`` of ``frame``, or None when that frame is not labelled."""
        i = int(np.searchsorted(self.frame, frame))
        if i < len(self.frame) and self.frame[i] == frame:
            return int(self.visibility[i]), self.xy[i].copy()
        return None

    def dense(self, n_frames: int) -> DenseBallTrack:
        """Spread the track over frames ``0..n_frames-1`` (see :class:`DenseBallTrack`)."""
        if len(self) and self.frame[-1] >= n_frames:
            raise ValueError(f"track has frame {self.frame[-1]} but the clip has {n_frames} frames")
        labelled = np.zeros(n_frames, dtype=bool)
        visibility = np.full(n_frames, -1, dtype=np.int8)
        xy = np.full((n_frames, 2), np.nan)
        labelled[self.frame] = True
        visibility[self.frame] = self.visibility
        xy[self.frame] = self.xy
        return DenseBallTrack(labelled, visibility, xy)


# ----------------------------------------------------------------------------------- inactive balls
@dataclass(eq=False)
class InactiveBalls(ArraysEqualMixin):
    """Balls lying still on court, not in play (``inactive_balls.csv``).

    Attributes:
        frame: ``(N,) int64``, zero-based frame indices, sorted.
        ball_no: ``(N,) int64``, ``>= 0``, which still ball; ``(frame, ball_no)`` pairs are unique and
            sorted.
        xy: ``(N, 2) float64``, normalised image coordinates in ``[0, 1]``.
        extra: unknown columns of the file, ``{name: (N,) str}``, written back unchanged.
    """

    frame: np.ndarray
    ball_no: np.ndarray
    xy: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.frame = as_vector(self.frame, "frame", np.int64)
        n = len(self.frame)
        self.extra = as_extra(self.extra, n, ("frame", "ball_no", "x", "y"))
        self.ball_no = as_vector(self.ball_no, "ball_no", np.int64, n)
        self.xy = clip_unit(as_matrix(self.xy, "xy", n, 2), "xy")
        check_frames(self.frame, strict=False)
        if self.ball_no.size and self.ball_no.min() < 0:
            raise ValueError("ball_no must be >= 0")
        same_frame = np.diff(self.frame) == 0
        if np.any(same_frame & (np.diff(self.ball_no) <= 0)):
            raise ValueError("(frame, ball_no) pairs must be unique and sorted")

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> InactiveBalls:
        """No inactive balls."""
        return cls(np.empty(0, np.int64), np.empty(0, np.int64), np.empty((0, 2)))


# --------------------------------------------------------------------------------------- hit events
@dataclass(eq=False)
class HitEvents(ArraysEqualMixin):
    """Hit events of one clip (``events.csv``); frames without a row are "no event".

    Attributes:
        frame: ``(N,) int64``, zero-based frame indices, strictly increasing.
        event: ``(N,) str``, labels from :data:`EVENT_LABELS`.
        extra: unknown columns of the file, ``{name: (N,) str}``, written back unchanged.

    Examples:
        >>> HitEvents(frame=[3, 9], event=["player_near", "ground"]).at(9)
        'ground'
    """

    frame: np.ndarray
    event: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.frame = as_vector(self.frame, "frame", np.int64)
        self.event = as_strings(self.event, "event", len(self.frame))
        self.extra = as_extra(self.extra, len(self.frame), ("frame", "event"))
        check_frames(self.frame)
        _check_labels(self.event, EVENT_LABELS, "event")

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> HitEvents:
        """No events."""
        return cls(np.empty(0, np.int64), np.empty(0, dtype="<U1"))

    def at(self, frame: int) -> str | None:
        """The event at ``frame``, or None."""
        i = int(np.searchsorted(self.frame, frame))
        return str(self.event[i]) if i < len(self.frame) and self.frame[i] == frame else None


# ------------------------------------------------------------------------------------- court points
@dataclass(eq=False)
class CourtPoints(ArraysEqualMixin):
    """Clicked image positions of named court points (``court_points.csv``).

    Attributes:
        names: ``N`` unique point names of the court YAML.
        xy: ``(N, 2) float64``, normalised image coordinates in ``[0, 1]``.
        extra: unknown columns of the file, ``{name: (N,) str}``, written back unchanged.
    """

    names: list[str]
    xy: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.names = [str(name) for name in self.names]
        self.extra = as_extra(self.extra, len(self.names), ("name", "x", "y"))
        if any(not name for name in self.names):
            raise ValueError("names must be non-empty strings")
        if len(set(self.names)) != len(self.names):
            raise ValueError("names must be unique")
        self.xy = clip_unit(as_matrix(self.xy, "xy", len(self.names), 2), "xy")

    def __len__(self) -> int:
        return len(self.names)

    @classmethod
    def from_dict(cls, points: dict[str, tuple[float, float]]) -> CourtPoints:
        """Build from ``{name: (u, v)}``."""
        return cls(list(points), np.array(list(points.values()), dtype=np.float64).reshape(-1, 2))

    def as_dict(self) -> dict[str, tuple[float, float]]:
        """``{name: (u, v)}`` in file order."""
        return {name: (float(u), float(v)) for name, (u, v) in zip(self.names, self.xy)}


@dataclass(eq=False)
class CourtLinePoints(ArraysEqualMixin):
    """Image positions clicked somewhere along straight court lines (``court_line_points.csv``): several per
    line trace a side line that a wide-angle lens bends, which gives the lens distortion.

    Attributes:
        start, end: ``M`` names of the court points at the two ends of each click's line.
        xy: ``(M, 2) float64``, normalised image coordinates in ``[0, 1]``.
    """

    start: list[str]
    end: list[str]
    xy: np.ndarray

    def __post_init__(self) -> None:
        self.start, self.end = [str(n) for n in self.start], [str(n) for n in self.end]
        if len(self.start) != len(self.end):
            raise ValueError("start and end must have one name per point")
        self.xy = clip_unit(as_matrix(self.xy, "xy", len(self.start), 2), "xy")

    def __len__(self) -> int:
        return len(self.start)

    @classmethod
    def empty(cls) -> CourtLinePoints:
        """No clicks along lines."""
        return cls([], [], np.empty((0, 2)))


# ------------------------------------------------------------------------------------------ 3D ball
@dataclass(eq=False)
class Ball3D(ArraysEqualMixin):
    """Per-frame 3D ball position in court coordinates (``ball_3d.csv``).

    Attributes:
        frame: ``(N,) int64``, zero-based frame indices, sorted; ``(frame, kind)`` pairs are unique.
        xyz: ``(N, 3) float64``, metres in the court frame (finite).
        segment: ``(N,) int64``, flight-segment id (-1 for none).
        kind: ``(N,) str``, one of :data:`BALL3D_KINDS`.
        sigma: ``(N,) float64``, per-frame uncertainty in metres; NaN where unknown (default all NaN).
        extra: unknown columns of the file, ``{name: (N,) array}``, written back unchanged.
    """

    frame: np.ndarray
    xyz: np.ndarray
    segment: np.ndarray
    kind: np.ndarray
    sigma: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.frame = as_vector(self.frame, "frame", np.int64)
        n = len(self.frame)
        self.xyz = as_matrix(self.xyz, "xyz", n, 3)
        if not np.all(np.isfinite(self.xyz)):
            raise ValueError("xyz must be finite")
        self.segment = as_vector(self.segment, "segment", np.int64, n)
        self.kind = as_strings(self.kind, "kind", n)
        _check_labels(self.kind, BALL3D_KINDS, "kind")
        sigma = np.full(n, np.nan) if self.sigma is None else as_vector(self.sigma, "sigma", np.float64, n)
        if np.any(sigma < 0) or np.any(np.isinf(sigma)):
            raise ValueError("sigma must be >= 0 and finite (or NaN when unknown)")
        self.sigma = sigma
        self.extra = {
            str(k): as_vector(v, f"extra[{k!r}]", np.asarray(v).dtype, n) for k, v in self.extra.items()
        }
        check_frames(self.frame, strict=False)
        key = self.frame * len(BALL3D_KINDS) + np.searchsorted(np.sort(BALL3D_KINDS), self.kind)
        if len(np.unique(key)) != n:
            raise ValueError("(frame, kind) pairs must be unique")

    def __len__(self) -> int:
        return len(self.frame)

    @classmethod
    def empty(cls) -> Ball3D:
        """No 3D ball."""
        return cls(np.empty(0, np.int64), np.empty((0, 3)), np.empty(0, np.int64), np.empty(0, "<U1"))
