"""Lines of sight against court surfaces: where a ray meets a plane within its extent.

All functions are vectorised over N rays.

Example:
    >>> origins, dirs = camera.rays_normalized(uv)                # (N, 3), (N, 3)
    >>> hit = intersect_event(origins, dirs, court, "ground", offset=court.ball.radius)
    >>> hit.points[hit.valid]                                      # (M, 3) ball centres on the floor
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from inference.court import Court, Plane


@dataclass(frozen=True)
class RayHits:
    """Result of intersecting N rays with a set of planes.

    Attributes:
        points: (N, 3) hit points (NaN where no valid hit).
        t: (N,) distance along each ray (NaN where none).
        plane_index: (N,) index into ``planes`` (-1 where none).
        planes: the candidate planes.
    """

    points: np.ndarray
    t: np.ndarray
    plane_index: np.ndarray
    planes: tuple[Plane, ...]

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: the ray hit one of the planes within its extent."""
        return self.plane_index >= 0

    def plane_names(self) -> list[str | None]:
        return [self.planes[i].name if i >= 0 else None for i in self.plane_index]


def intersect_plane(
    origins: np.ndarray, directions: np.ndarray, plane: Plane, offset: float = 0.0, tol: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Intersect rays with one plane, keeping only hits in front of the origin and inside the extent.

    Args:
        origins, directions: (N, 3) rays (directions need not be unit; t is in their units).
        plane: the surface.
        offset: the plane is moved this far along its normal before intersecting — the ball's radius,
            since the centre of a ball touching a surface lies one radius off it. One-sided planes move
            into the court; two-sided planes (the net) move towards each ray's origin.
        tol: extent tolerance in metres.
    Returns:
        t: (N,) ray parameter (NaN if no valid hit); points: (N, 3) (NaN if none).
    """
    o = np.atleast_2d(np.asarray(origins, dtype=float))
    d = np.atleast_2d(np.asarray(directions, dtype=float))
    n = plane.normal
    side = np.ones(len(o))
    if plane.two_sided:
        side = np.where((o - plane.origin) @ n >= 0, 1.0, -1.0)
    p0 = plane.origin[None, :] + (offset * side)[:, None] * n[None, :]
    denom = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,j->i", p0 - o, n) / denom
        ok = np.isfinite(t) & (t > 0) & (np.abs(denom) > 1e-12)
        pts = o + np.where(ok, t, 0.0)[:, None] * d
    # the extent is checked on the surface itself (the hit point projected back by the offset)
    ok &= plane.contains(pts, tol=tol) if len(pts) else ok
    t = np.where(ok, t, np.nan)
    pts[~ok] = np.nan
    return t, pts


def intersect_planes(
    origins: np.ndarray, directions: np.ndarray, planes: Sequence[Plane], offset: float = 0.0
) -> RayHits:
    """First valid hit (smallest positive t within extent) of each ray among ``planes``."""
    o = np.atleast_2d(np.asarray(origins, dtype=float))
    planes = tuple(planes)
    if not planes:
        n = len(o)
        return RayHits(np.full((n, 3), np.nan), np.full(n, np.nan), np.full(n, -1), planes)
    ts, pts = zip(*(intersect_plane(o, directions, p, offset) for p in planes))
    T = np.stack(ts, axis=1)  # (N, P)
    has = np.isfinite(T).any(axis=1)
    idx = np.where(has, np.nanargmin(np.where(np.isfinite(T), T, np.inf), axis=1), -1)
    rows = np.arange(len(o))
    points = np.stack(pts, axis=1)[rows, np.maximum(idx, 0)]
    points[~has] = np.nan
    t = np.where(has, T[rows, np.maximum(idx, 0)], np.nan)
    return RayHits(points, t, idx, planes)


def intersect_event(
    origins: np.ndarray,
    directions: np.ndarray,
    court: Court,
    events: str | Iterable[str],
    offset: float = 0.0,
) -> RayHits:
    """Intersect rays with the planes of an event label or a group of labels (first valid hit).

    For a grouped class such as ``ground_or_other_wall``, pass its fine-grained labels
    (``["ground", "wall_far", "wall_left", "wall_right"]``): for any line of sight only one plane of
    such a group is reachable first, so the contact surface is resolved geometrically.
    """
    planes = court.planes_for(events)
    if not planes:
        raise KeyError(f"court {court.name} has no plane for event(s) {events!r}; it has {court.event_labels}")
    return intersect_planes(origins, directions, planes, offset)
