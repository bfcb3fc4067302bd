"""The court's painted floor lines as a model to fit: segments, their infinite lines, sample points.

The net's top (``lines.net`` segments above 0.3 m) is kept apart: it is not on the floor, so it cannot take
part in the floor homography, but it tells a right camera from a wrong one that fits the floor lines.

Lines come from the court YAML's ``lines.paint`` layer (segments on the floor, z = 0). Each segment is
*transverse* (along x: baselines, service lines) or *longitudinal* (along y: side lines, centre line);
collinear segments share one model line. Segments shorter than :data:`MIN_SEARCH_LENGTH_M` (tennis'
centre marks) are kept for scoring and refinement but not used to search correspondences.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.camera import Camera
from inference.court import Court

MIN_SEARCH_LENGTH_M = 2.0


@dataclass(frozen=True)
class ModelLine:
    """An infinite model line: ``y = value`` (transverse) or ``x = value`` (longitudinal)."""

    kind: str
    value: float

    def point(self, other: ModelLine) -> np.ndarray:
        """(2,) floor point where a transverse and a longitudinal line cross."""
        x, y = (other.value, self.value) if self.kind == "transverse" else (self.value, other.value)
        return np.array([x, y])


@dataclass(frozen=True)
class CourtLines:
    """The floor-paint model of a court.

    Attributes:
        segments: (S, 2, 2) floor segments (x, y metres).
        transverse: model lines along x, far (largest y) first.
        longitudinal: model lines along y, left (smallest x) first.
        raised: (R, 2, 3) painted or taped lines above the floor (the net's top), used to check a fit in 3D.
        structure: (T, 2, 3) raised transverse edges of the near walls (glass and mesh tops): rails between
            the camera and the court that can hide or double a painted line in the image (see
            :func:`.fit.confused_segments`).
        net_y: y of the net (the near half of the court lies below it).
    """

    segments: np.ndarray
    transverse: tuple[ModelLine, ...]
    longitudinal: tuple[ModelLine, ...]
    raised: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    structure: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    net_y: float = float("inf")

    @property
    def segments_3d(self) -> np.ndarray:
        """(S, 2, 3) the segments on the floor (z = 0)."""
        return np.concatenate([self.segments, np.zeros((*self.segments.shape[:2], 1))], axis=2)

    def samples(self, step_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Points every ``step_m`` along every segment: (P, 2) floor points and (P,) segment indices."""
        pts, idx = [], []
        for i, (a, b) in enumerate(self.segments):
            n = max(2, int(np.ceil(np.linalg.norm(b - a) / step_m)) + 1)
            s = np.linspace(0, 1, n)[:, None]
            pts.append(a + s * (b - a))
            idx.append(np.full(n, i))
        return np.concatenate(pts), np.concatenate(idx)

    def crossings(self) -> np.ndarray:
        """(Q, 2) floor points where a transverse and a longitudinal segment cross or meet."""
        out = []
        for a, b in self.segments:
            for c, d in self.segments:
                if abs(b[1] - a[1]) < 1e-9 and abs(d[0] - c[0]) < 1e-9:  # (a, b) transverse, (c, d) longitudinal
                    x, y = c[0], a[1]
                    if min(a[0], b[0]) - 1e-6 <= x <= max(a[0], b[0]) + 1e-6 and \
                            min(c[1], d[1]) - 1e-6 <= y <= max(c[1], d[1]) + 1e-6:
                        out.append((x, y))
        return np.unique(np.round(np.array(out, dtype=float).reshape(-1, 2), 6), axis=0)


def court_lines(court: Court) -> CourtLines:
    """The floor-paint model of ``court`` (raises ValueError when it has too few painted lines)."""
    paint = court.lines.get("paint", np.zeros((0, 2, 3)))
    segs = [s[:, :2] for s in paint if np.allclose(s[:, 2], 0.0)]
    trans, longi = set(), set()
    for a, b in segs:
        long_enough = np.linalg.norm(b - a) >= MIN_SEARCH_LENGTH_M
        if abs(b[1] - a[1]) < 1e-9 and long_enough:
            trans.add(round(float(a[1]), 6))
        elif abs(b[0] - a[0]) < 1e-9 and long_enough:
            longi.add(round(float(a[0]), 6))
    if len(trans) < 2 or len(longi) < 2:
        raise ValueError(f"court {court.name}: the automatic fit needs at least two painted floor lines along "
                         "each axis (lines.paint in the court YAML)")
    net = court.lines.get("net", np.zeros((0, 2, 3)))
    raised = np.array([s for s in net if np.all(s[:, 2] > 0.3)], dtype=float).reshape(-1, 2, 3)
    walls = [s for layer in ("glass", "mesh") for s in court.lines.get(layer, np.zeros((0, 2, 3)))]
    near = [s for s in walls if np.all(s[:, 2] > 0.3) and abs(s[1, 1] - s[0, 1]) < 1e-9 and s[0, 1] < court.net_y]
    structure = np.array(near, dtype=float).reshape(-1, 2, 3)
    return CourtLines(np.array(segs, dtype=float).reshape(-1, 2, 2),
                      tuple(ModelLine("transverse", y) for y in sorted(trans, reverse=True)),
                      tuple(ModelLine("longitudinal", x) for x in sorted(longi)), raised, structure,
                      float(court.net_y))


def court_line_samples(cam: Camera, court: Court, step_m: float = 0.1) -> np.ndarray:
    """(P, 2) full-resolution pixels of the court's floor lines inside the image of ``cam``, one every
    ``step_m`` metres of line."""
    model = court_lines(court)
    pts, _ = model.samples(step_m)
    px = cam.project(np.concatenate([pts, np.zeros((len(pts), 1))], axis=1))
    w, h = cam.image_size
    return px[np.isfinite(px).all(1) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)]
