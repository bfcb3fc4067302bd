"""Courts as data: a typed :class:`Court` loaded from a YAML file under ``conf/court/``.

The court frame (docs/formats.md): right-handed, metres, z up, origin at the near-left ground
corner as seen from the main camera, x along the near baseline, y away from the camera.

Example:
    >>> court = load_court("padel")
    >>> court.points["net_post_left_top"]
    array([ 0.  , 10.  ,  0.92])
    >>> [p.name for p in court.planes_for("wall_left")]
    ['glass_left', 'glass_left_far']
"""
from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from inference.clipio.errors import FormatError
from inference.clipio.structured import load_yaml

#: Where the court YAML files live: ``$RALLY3D_CONF/court`` or the repository's ``conf/court``.
CONF_DIR = Path(os.environ.get("RALLY3D_CONF", Path(__file__).resolve().parents[2] / "conf"))


@dataclass(frozen=True)
class Material:
    """How the ball bounces off a surface: normal restitution and Coulomb friction."""

    restitution: float
    friction: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.restitution <= 1.0:
            raise ValueError(f"restitution must be in [0, 1], got {self.restitution}")
        if self.friction < 0.0:
            raise ValueError(f"friction must be >= 0, got {self.friction}")


@dataclass(frozen=True)
class BallConstants:
    """The ball's physical constants (SI units)."""

    radius: float
    mass: float
    drag_coefficient: float
    lift_coefficient: float = 0.0
    air_density: float = 1.2
    gravity: float = 9.81

    def __post_init__(self) -> None:
        for name in ("radius", "mass", "air_density", "gravity"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ball.{name} must be > 0, got {getattr(self, name)}")
        if self.drag_coefficient < 0 or self.lift_coefficient < 0:
            raise ValueError("ball drag/lift coefficients must be >= 0")

    @property
    def area(self) -> float:
        """Cross-section area in m²."""
        return float(np.pi * self.radius**2)

    @property
    def drag_k(self) -> float:
        """Drag acceleration factor k (1/m): a_drag = -k |v| v."""
        return 0.5 * self.air_density * self.drag_coefficient * self.area / self.mass


@dataclass(frozen=True)
class HitLimits:
    """Where a racket hit can happen: height range (m), offset along y from the hitter's court position
    (m), and the horizontal reach (m) from the hitter."""

    height: tuple[float, float] = (0.0, 2.8)
    offset_y: tuple[float, float] = (-1.2, 1.2)
    reach: float = 1.6

    def __post_init__(self) -> None:
        h, o = tuple(float(v) for v in self.height), tuple(float(v) for v in self.offset_y)
        if len(h) != 2 or h[0] > h[1] or len(o) != 2 or o[0] > o[1] or self.reach <= 0:
            raise ValueError("hits: height and offset_y must be [low, high] with low <= high, reach > 0")
        object.__setattr__(self, "height", h)
        object.__setattr__(self, "offset_y", o)


@dataclass(frozen=True)
class Plane:
    """A planar surface patch of the court that the ball can touch.

    Attributes:
        name: unique name, e.g. ``glass_left``.
        event: fine-grained events.csv label of a contact with it (``ground``, ``wall_left`` ...).
        material: key into :attr:`Court.materials`.
        origin: (3,) a point of the plane.
        u, v: (3,) orthonormal in-plane axes; the normal ``u × v`` points into the court.
        polygon: (M, 2) the extent as a polygon in (u, v) metres relative to ``origin``.
        two_sided: whether the ball can hit it from both sides (the net).
    """

    name: str
    event: str
    material: str
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    polygon: np.ndarray
    two_sided: bool = False

    def __post_init__(self) -> None:
        for attr in ("origin", "u", "v"):
            arr = np.asarray(getattr(self, attr), dtype=float)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise ValueError(f"plane {self.name}: {attr} must be 3 finite numbers, got {arr.tolist()}")
            object.__setattr__(self, attr, arr)
        poly = np.asarray(self.polygon, dtype=float)
        if poly.ndim != 2 or poly.shape[1] != 2 or len(poly) < 3:
            raise ValueError(f"plane {self.name}: polygon must be (M >= 3, 2), got shape {poly.shape}")
        object.__setattr__(self, "polygon", poly)
        if abs(np.linalg.norm(self.u) - 1) > 1e-6 or abs(np.linalg.norm(self.v) - 1) > 1e-6:
            raise ValueError(f"plane {self.name}: u and v must be unit vectors")
        if abs(float(self.u @ self.v)) > 1e-6:
            raise ValueError(f"plane {self.name}: u and v must be orthogonal")

    @cached_property
    def normal(self) -> np.ndarray:
        """(3,) unit normal ``u × v``, pointing into the court."""
        return np.cross(self.u, self.v)

    def to_plane_coords(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N, 2) (u, v) coordinates of their projection onto the plane."""
        d = np.atleast_2d(points) - self.origin
        return np.stack([d @ self.u, d @ self.v], axis=-1)

    def to_world(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) (u, v) plane coordinates → (N, 3) world points."""
        uv = np.atleast_2d(uv)
        return self.origin + uv[:, :1] * self.u + uv[:, 1:2] * self.v

    def contains(self, points: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """(N, 3) points already on the plane → (N,) bool: inside the polygon extent (edges included)."""
        return points_in_polygon(self.to_plane_coords(points), self.polygon, tol=tol)

    def corners_3d(self) -> np.ndarray:
        """(M, 3) the polygon's vertices in world coordinates."""
        return self.to_world(self.polygon)


def points_in_polygon(pts: np.ndarray, poly: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Even-odd point-in-polygon test with points on an edge (within ``tol``) counted inside.

    Args:
        pts: (N, 2) query points.
        poly: (M, 2) polygon vertices in order.
    Returns:
        (N,) bool.
    """
    pts = np.atleast_2d(np.asarray(pts, dtype=float))
    x, y = pts[:, 0:1], pts[:, 1:2]
    a = poly
    b = np.roll(poly, -1, axis=0)
    ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = ax + (y - ay) * (bx - ax) / (by - ay)
    inside = np.logical_xor.reduce(crosses & (x < x_at), axis=1)
    # distance to each edge, for points on the boundary
    ex, ey = bx - ax, by - ay
    seg_len2 = np.maximum(ex**2 + ey**2, 1e-30)
    with np.errstate(over="ignore", invalid="ignore"):  # a point thousands of km away (a wild fit trial): not on an edge
        s = np.clip(((x - ax) * ex + (y - ay) * ey) / seg_len2, 0.0, 1.0)
        dist2 = (x - (ax + s * ex)) ** 2 + (y - (ay + s * ey)) ** 2
    on_edge = (dist2 <= tol**2).any(axis=1)
    return inside | on_edge


@dataclass(frozen=True)
class Court:
    """A court model: named points, contact planes, lines to draw and the ball's constants.

    Attributes:
        name: e.g. ``padel``.
        sport: the sport whose rules apply (``padel`` or ``tennis``).
        size: (2,) playing-area extent along x and y in metres.
        net_y: y of the net plane.
        points: name → (3,) court-frame coordinates.
        planes: contact surfaces.
        materials: material name → bounce constants.
        lines: drawing layer (``paint``, ``net``, ``glass``, ``mesh``) → (L, 2, 3) segments.
        ball: the ball's physical constants.
        hits: where racket hits can happen (for the reconstruction).
        n_players: players on court (4 for doubles, 2 for singles).
        event_groups: coarse class name → the fine-grained surface labels it stands for.
        source: the YAML file it came from.
    """

    name: str
    sport: str
    size: np.ndarray
    net_y: float
    points: dict[str, np.ndarray]
    planes: tuple[Plane, ...]
    materials: dict[str, Material]
    lines: dict[str, np.ndarray]
    ball: BallConstants
    hits: HitLimits = field(default_factory=HitLimits)
    n_players: int = 4
    event_groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    source: Path | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = [p.name for p in self.planes]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"court {self.name}: duplicate plane names {sorted(dup)}")
        missing = {p.material for p in self.planes} - set(self.materials)
        if missing:
            raise ValueError(f"court {self.name}: planes use undefined materials {sorted(missing)}")

    @property
    def point_names(self) -> list[str]:
        return list(self.points)

    def point_array(self, names: Iterable[str]) -> np.ndarray:
        """(N, 3) coordinates of the named points; unknown names raise KeyError listing valid ones."""
        out = []
        for n in names:
            if n not in self.points:
                raise KeyError(f"unknown point {n!r} for court {self.name}; valid: {', '.join(self.points)}")
            out.append(self.points[n])
        return np.array(out, dtype=float).reshape(-1, 3)

    def plane(self, name: str) -> Plane:
        for p in self.planes:
            if p.name == name:
                return p
        raise KeyError(f"court {self.name} has no plane {name!r}; planes: {[p.name for p in self.planes]}")

    def planes_for(self, events: str | Iterable[str]) -> list[Plane]:
        """The planes of an event label, of a group name of :attr:`event_groups`, or of several labels."""
        wanted = {events} if isinstance(events, str) else set(events)
        for group in wanted & set(self.event_groups):
            wanted |= set(self.event_groups[group])
        return [p for p in self.planes if p.event in wanted]

    @property
    def event_labels(self) -> list[str]:
        """The distinct surface-contact labels of this court, in plane order."""
        return list(dict.fromkeys(p.event for p in self.planes))

    @property
    def annotation_labels(self) -> list[str]:
        """The labels an ``events.csv`` of this court may hold: its surfaces, then the two player hits."""
        from inference.clipio.tables import EVENT_LABELS

        surfaces = [e for e in self.event_labels if e in EVENT_LABELS]
        return list(dict.fromkeys([*surfaces, "player_near", "player_far"]))

    def off_ground_points(self, tol: float = 1e-6) -> list[str]:
        """Names of points with z ≠ 0 (needed to calibrate a camera)."""
        return [n for n, p in self.points.items() if abs(p[2]) > tol]


def court_path(name_or_path: str | Path) -> Path:
    """Resolve a court name (``padel``) or a YAML path to an existing file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        if not p.is_file():
            raise FileNotFoundError(f"court file {p} not found")
        return p
    cand = CONF_DIR / "court" / f"{name_or_path}.yaml"
    if not cand.is_file():
        known = sorted(f.stem for f in (CONF_DIR / "court").glob("*.yaml"))
        raise FileNotFoundError(
            f"no court named {name_or_path!r} (looked for {cand}); known courts: {known}. "
            "Pass a path to a court YAML to use another one."
        )
    return cand


def _vec3(path: Path, where: str, value) -> np.ndarray:
    arr = np.asarray(value, dtype=float) if isinstance(value, (list, tuple)) else None
    if arr is None or arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise FormatError(path, f"{where} must be a list of 3 numbers [x, y, z], got {value!r}")
    return arr


def load_court(name_or_path: str | Path) -> Court:
    """Load a court YAML (by name under ``conf/court/`` or by path) into a validated :class:`Court`."""
    path = court_path(name_or_path)
    data = load_yaml(path, fix="compare with conf/court/padel.yaml")
    if not isinstance(data, dict):
        raise FormatError(path, "expected a mapping at the top level")
    required = ["name", "points", "planes", "materials", "ball"]
    missing = [k for k in required if k not in data]
    if missing:
        raise FormatError(path, f"missing keys {missing}", fix=f"a court YAML needs {required}")
    try:
        if not isinstance(data["points"], dict):
            raise FormatError(path, "points must be a mapping `name: [x, y, z]`")
        points = {str(n): _vec3(path, f"points.{n}", v) for n, v in data["points"].items()}
        materials = {str(k): Material(**v) for k, v in data["materials"].items()}
        planes = tuple(
            Plane(
                name=str(p["name"]),
                event=str(p["event"]),
                material=str(p["material"]),
                origin=p["origin"],
                u=p["u"],
                v=p["v"],
                polygon=p["polygon"],
                two_sided=bool(p.get("two_sided", False)),
            )
            for p in data["planes"]
        )
        lines = {}
        for layer, segs in (data.get("lines") or {}).items():
            arr = np.asarray(segs, dtype=float)
            if arr.ndim != 3 or arr.shape[1:] != (2, 3):
                raise ValueError(f"lines.{layer} must be a list of [[x,y,z],[x,y,z]] segments")
            lines[str(layer)] = arr
        ball = BallConstants(**data["ball"])
        hits = HitLimits(**(data.get("hits") or {}))
        groups = {str(k): tuple(str(x) for x in v) for k, v in (data.get("event_groups") or {}).items()}
        size = np.asarray(data.get("size", [0, 0]), dtype=float)
        if data.get("player_area") is not None:  # rectangles x0, x1, y0, y1 (inference.players.tracking)
            area = np.asarray(data["player_area"], dtype=float).reshape(-1, 4)
            if not np.isfinite(area).all() or (area[:, 1] <= area[:, 0]).any() or (area[:, 3] <= area[:, 2]).any():
                raise ValueError("player_area must be [[x0, x1, y0, y1], ...] with x0 < x1 and y0 < y1")
        return Court(
            name=str(data["name"]),
            sport=str(data.get("sport", data["name"])),
            size=size,
            net_y=float(data.get("net_y", size[1] / 2)),
            points=points,
            planes=planes,
            materials=materials,
            lines=lines,
            ball=ball,
            hits=hits,
            n_players=int(data.get("players", 4)),
            event_groups=groups,
            source=path,
            extra={k: v for k, v in data.items()
                   if k not in {*required, "sport", "size", "net_y", "lines", "hits", "event_groups", "players"}},
        )
    except FormatError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, ArithmeticError) as e:
        raise FormatError(path, f"invalid court definition: {type(e).__name__}: {e}",
                          fix="compare with conf/court/padel.yaml") from None
