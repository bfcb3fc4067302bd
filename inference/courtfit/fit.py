"""Automatic court fit: line evidence → line correspondences → camera refined on line distances → gate.

1. :mod:`.lines`: the median of a few frames, its line pixels and straight lines (:func:`.search.find_lines`:
   each direction gets its own lines when dense transverse structure fills the list);
2. :mod:`.search`: ordered correspondences between image lines and the court's painted lines, each a floor
   homography of a camera that looks down on the floor (not an edge-on view of upright structure), scored
   on the line pixels;
3. the best few: a camera from the homography's crossing points by the coplanar calibration
   (:func:`inference.camera.calibration.calibrate`: Zhang's constraints, then f, R, t), refined on the distances of
   line pixels to the projected court lines (robust least squares; radial distortion k1, then k1 and k2,
   kept when they explain the lines clearly better), rescored;
4. the gate: the fit is *accepted* only when enough of the visible court lines are found on line pixels
   (coverage), the pixels sit close to the lines (line RMS), lines of both directions are supported, the
   runner-up explains clearly less (margin; a rival that lays a painted line on the near wall's top rail is
   the rail's echo, not a rival), the line pixels on the fitted court's floor are mostly on its modelled
   lines (:func:`unexplained_share`; not counting what a fence's mesh covers) and the camera is plausible
   (above the floor on the near side, seeing it at ≥ 5°). A near painted line running along that rail in
   the image (a camera right behind the glass, where the rail hides or doubles the near service line) has
   the fit refined with the rails as lines of their own; it then needs a larger margin (rivals the gate
   would refuse on their own count only when the rails are not found along most of their length) and that
   paint or a rail found. Last, the nearest painted line across must stay where the fit puts it when the
   camera is refitted without it (:func:`_near_line_check`). A rejected fit says why; nothing downstream
   uses it silently.
5. a refused fit searches again on the background undistorted by a guessed strong barrel lens
   (:data:`DISTORTION_SEARCH`, :func:`_undistorted`): such a lens bends the near lines past what straight
   image lines follow. Those placements are refined on the real line pixels (k1 free) and judged with the
   first search's; the result replaces the refusal only when the gate accepts it.

Example:
    >>> fit = fit_court(Clip("runs/clip"), load_court("padel"))
    >>> fit.accepted, fit.confidence, fit.camera.centre, fit.summary()
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from inference.camera.calibration import CalibrationError, CameraLayout, camera_layout, coplanar_camera
from inference.camera import Camera
from inference.court import Court
from inference.video.masks import apply_mask, clip_mask

from .lines import LineEvidence, background, line_mask, working_scale
from .model import CourtLines, court_lines
from .search import (HIT_PX, MIN_ELEVATION_DEG, best_hypotheses, elevation_deg, find_lines, hypotheses,
                     split_lines)

N_FRAMES = 9
MIN_COVERAGE = 0.6
MAX_LINE_RMS = 1.0  # working px
MIN_MARGIN = 1.1
MAX_UNEXPLAINED = 0.45  # of the line pixels inside the fitted court's floor, on none of its modelled lines
MIN_MARGIN_RAIL = 1.2  # ... when a painted line runs along a near wall's top rail (less independent evidence)
MIN_PINNED = 0.9  # ... and the painted line along the rail, or a rail, found along this share of its image
MIN_LINES_PER_KIND = 2
MIN_NET_COVERAGE = 0.7  # of the net top's visible image length, when it is at least MIN_NET_PX long
MIN_NET_PX = 50.0
MAX_PIXELS = 4000
COVERAGE_STEP_M = 0.1
BANDS = (6.0, 3.0, 2.0)  # working px: pixels this close to a projected line are assigned to it, per round
CONFUSION_PX = 16.0  # working px: a painted line whose image runs this close to a near rail's is not trusted
CONFUSION_SHARE = 0.5  # ... along at least this share of its visible length
MIN_GAIN_CLEAR = 1.2  # a refit without the paint along a rail is kept when it explains this many times the pixels
MAX_NEAR_CHECK_PX = 6.0  # working px: the nearest transverse line, left out, moves at most this far (_near_line_check)
TAPE_CENTRE_M = 0.025  # the net's tape (5-6 cm) hangs from its top: its centre line is this far below
START_NFEV_PER_PARAM = 50  # evaluations per parameter a start camera's refinement may take
MIN_K2_REACH = 0.75  # k2 is tried only when the line pixels reach this share of the way to the image corners
DISTORTION_SEARCH = (-0.15,)  # lens guesses (image k1, radius in half-diagonals) searched when a fit is refused


class AutoFitError(RuntimeError):
    """The automatic fit found no court it can vouch for; the message says why and what to do instead."""


@dataclass
class AutoFit:
    """The result of the automatic court fit.

    Attributes:
        camera: the fitted camera (``source: auto``, ``meta['auto']`` filled), or None when nothing fitted.
        accepted: whether the fit passed the gate (see the module docstring).
        confidence: in [0, 1]: coverage × (1 − line RMS / 3 working px) × (margin − 1) / 0.5, each clipped.
        coverage: fraction of the visible painted court lines found on line pixels.
        net_coverage: the same for the net's top (NaN when out of view).
        line_rms_px: RMS distance (full-resolution px) of the assigned line pixels to the fitted lines.
        lines_supported: (transverse, longitudinal) model lines with ≥ 50 % of their visible length found.
        margin: score of the fit over that of the best different candidate (inf when there is none).
        unexplained: share of the line pixels inside the fitted court's floor on none of its modelled lines
            (NaN when too few; see :func:`unexplained_share`).
        near_check_px: how far (full-resolution px) the nearest painted transverse line moves when the camera
            is refitted without it (see :func:`_near_line_check`; refused above 6 working px).
        reason: why the fit was rejected ("" when accepted).
        frames: the frame indices whose median was used.
        cpu_seconds: CPU time of the fit (frame decoding included when :func:`fit_court` read them).
    """

    camera: Camera | None
    accepted: bool
    confidence: float = 0.0
    coverage: float = 0.0
    net_coverage: float = float("nan")
    line_rms_px: float = float("nan")
    lines_supported: tuple[int, int] = (0, 0)
    margin: float = 0.0
    unexplained: float = float("nan")
    near_check_px: float = float("nan")
    reason: str = ""
    frames: list[int] = field(default_factory=list)
    cpu_seconds: float = 0.0

    def meta(self) -> dict:
        """The ``auto`` block of camera.yaml (docs/formats.md §11)."""
        return {"accepted": self.accepted, "confidence": round(self.confidence, 3),
                "coverage": round(self.coverage, 3),
                "net_coverage": None if not np.isfinite(self.net_coverage) else round(self.net_coverage, 3),
                "line_rms_px": round(float(self.line_rms_px), 3),
                "lines_supported": list(self.lines_supported),
                "margin": None if not np.isfinite(self.margin) else round(float(self.margin), 3),
                "unexplained": None if not np.isfinite(self.unexplained) else round(float(self.unexplained), 3),
                "near_check_px": None if not np.isfinite(self.near_check_px) else round(self.near_check_px, 2),
                "frames": list(self.frames), "reason": self.reason}

    def summary(self) -> str:
        state = "accepted" if self.accepted else f"REJECTED ({self.reason})"
        net = f"{100 * self.net_coverage:.0f} %" if np.isfinite(self.net_coverage) else "not in view"
        return (f"automatic court fit {state}: confidence {self.confidence:.2f}, coverage {100 * self.coverage:.0f} %, "
                f"net {net}, line RMS {self.line_rms_px:.2f} px, "
                f"lines {self.lines_supported[0]}+{self.lines_supported[1]}, margin {self.margin:.2f}, "
                f"{self.cpu_seconds:.2f} s CPU")

    def court_points(self, court: Court, margin_frac: float = 0.01) -> dict[str, np.ndarray]:
        """Named floor points of ``court`` that the fitted camera puts inside the image: name → (2,) px."""
        if self.camera is None:
            return {}
        w, h = self.camera.image_size
        names = [n for n, p in court.points.items() if abs(p[2]) < 1e-9]
        px = self.camera.project(court.point_array(names))
        m = margin_frac * np.array([w, h])
        ok = np.all((px >= m) & (px <= np.array([w, h]) - m), axis=1)
        return {n: px[i] for i, n in enumerate(names) if ok[i]}

    def require(self) -> Camera:
        """The camera of an accepted fit; :class:`AutoFitError` otherwise."""
        if not self.accepted or self.camera is None:
            raise AutoFitError(f"the automatic court fit is not reliable ({self.reason or 'no court found'}) — "
                               "click court points instead (rally3d label CLIP, or court_points.csv) and run "
                               "rally3d calibrate")
        return self.camera


# ------------------------------------------------------------------------------- line refinement
def _project(layout: CameraLayout, p: np.ndarray, X: np.ndarray) -> np.ndarray:
    from inference.camera import distort_normalized

    K, R, t, dist = layout.unpack(p)
    Xc = X @ R.T + t
    z = np.where(Xc[..., 2:3] > 1e-6, Xc[..., 2:3], 1e-6)
    xn = Xc[..., :2] / z
    if layout.n_dist:
        xn = distort_normalized(xn.reshape(-1, 2), dist).reshape(xn.shape)
    return xn @ K[:2, :2].T + K[:2, 2]


def _signed_distance(pix: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N, 2) pixels, (K, 2) polyline → (N,) signed distance to the nearest piece of the polyline."""
    A, B = poly[:-1], poly[1:]
    abx, aby = B[:, 0] - A[:, 0], B[:, 1] - A[:, 1]
    L2 = np.maximum(abx * abx + aby * aby, 1e-12)
    apx = pix[:, :1] - A[None, :, 0]  # (N, K-1): coordinates spelled out, no reductions over a length-2 axis
    apy = pix[:, 1:2] - A[None, :, 1]
    t = np.clip((apx * abx + apy * aby) / L2, 0.0, 1.0)
    dx, dy = apx - t * abx, apy - t * aby
    d2 = dx * dx + dy * dy
    j = np.argmin(d2, axis=1)
    rows = np.arange(len(pix))
    d = np.sqrt(d2[rows, j])
    sign = np.sign(abx[j] * apy[rows, j] - aby[j] * apx[rows, j])
    return np.where(sign == 0, 1.0, sign) * d


def _polyline_points(segments: np.ndarray, n_dist: int) -> np.ndarray:
    """(S, K, 3) points along each 3D segment: the ends alone when lines project straight (no distortion)."""
    s = np.linspace(0.0, 1.0, 12 if n_dist else 2)[None, :, None]
    return segments[:, :1] + s * (segments[:, 1:] - segments[:, :1])


def _assign(cam_layout: CameraLayout, p: np.ndarray, polys3d: np.ndarray, pix: np.ndarray,
            band: float) -> list[np.ndarray]:
    """Indices of the pixels nearest to each projected segment, within ``band`` (full px)."""
    proj = _project(cam_layout, p, polys3d)
    d = np.stack([np.abs(_signed_distance(pix, poly)) for poly in proj], axis=1)
    j = np.argmin(d, axis=1)
    near = d[np.arange(len(pix)), j] <= band
    return [np.nonzero(near & (j == s))[0] for s in range(len(polys3d))]


def refine_on_lines(cam: Camera, segments: np.ndarray, pixels: np.ndarray, scale: float, n_dist: int = 0,
                    bands: tuple[float, ...] = BANDS) -> tuple[Camera, np.ndarray, float]:
    """Refine f, R, t (and k1 when ``n_dist``) on the distances of line pixels to the projected segments.

    Args:
        cam: the start camera (principal point at the image centre).
        segments: (S, 2, 3) model line segments (court metres).
        pixels: (N, 2) line pixels, full-resolution px.
        scale: working px per full px (the bands and the robust scale are in working px).
        n_dist: 0 or 1 radial coefficients.
    Returns:
        the camera, the final residuals (full px, of the pixels within the last band) and the robust cost.
    """
    layout = camera_layout("square", n_dist, "centre", cam.image_size)
    p = layout.pack(cam)
    polys = _polyline_points(segments, n_dist)
    res, cost = np.zeros(0), np.inf
    for band in bands:
        groups = _assign(layout, p, polys, pixels, band / scale)
        used = [(s, g) for s, g in enumerate(groups) if len(g) >= 5]
        if sum(len(g) for _, g in used) < len(p) + 5:
            break

        def residuals(q, used=used):
            proj = _project(layout, q, polys)
            return np.concatenate([_signed_distance(pixels[g], proj[s]) for s, g in used])

        # robust (soft-L1) through weights fixed for this round: Levenberg-Marquardt stays fast
        f_scale = 1.0 / scale
        w = (1.0 + (residuals(p) / f_scale) ** 2) ** -0.25
        sol = least_squares(lambda q, w=w, fn=residuals: w * fn(q), p, method="lm", x_scale="jac",
                            max_nfev=40 * len(p))
        if np.all(np.isfinite(sol.x)) and sol.x[0] > 0:
            p = sol.x
            res = residuals(p)
            cost = float(np.sum(2 * f_scale**2 * (np.sqrt(1 + (res / f_scale) ** 2) - 1)))
    return layout.camera(p, cam.image_size), res, cost


# ------------------------------------------------------------------------------------- evaluation
@dataclass
class _Candidate:
    camera: Camera
    residuals: np.ndarray
    per_line: list[tuple[str, float, float]]  # floor segments: (kind, supported, visible) image length
    net: tuple[float, float]  # the net's top: supported, visible image length
    confused: np.ndarray | None = None  # (S,) painted segments along a near rail (None: not refitted with rails)

    @property
    def hits(self) -> float:
        return sum(p[1] for p in self.per_line)

    @property
    def visible(self) -> float:
        return sum(p[2] for p in self.per_line)

    @property
    def score(self) -> float:
        """Supported minus half the unsupported image length (working px), floor lines and net."""
        hits, vis = self.hits + self.net[0], self.visible + self.net[1]
        return hits - 0.5 * (vis - hits)

    @property
    def net_coverage(self) -> float:
        return self.net[0] / self.net[1] if self.net[1] > 0 else float("nan")

    @property
    def net_found(self) -> bool:
        """The net's top is where this placement puts it (or too little of it is in view to tell)."""
        return self.net[1] < MIN_NET_PX or self.net_coverage >= MIN_NET_COVERAGE

    def same_as(self, other: _Candidate, model: CourtLines) -> bool:
        """Whether both put the court's lines at the same place in the image (every floor crossing this
        camera sees within 0.6 % of the larger image side): one placement, not a rival one."""
        pts = np.concatenate([model.crossings(), np.zeros((len(model.crossings()), 1))], axis=1)
        a, b = self.camera.project(pts), other.camera.project(pts)
        w, h = self.camera.image_size
        seen = np.isfinite(a).all(1) & (a >= 0).all(1) & (a[:, 0] <= w) & (a[:, 1] <= h)
        if not seen.any():
            return False
        return bool(np.max(np.linalg.norm(a[seen] - b[seen], axis=1)) <= 0.006 * max(w, h))


def _support(cam: Camera, ev: LineEvidence, segments: np.ndarray) -> list[tuple[str, float, float]]:
    """Per 3D segment (S, 2, 3): its kind and the supported and visible image length (working px) of its
    projection on the line pixels (as :func:`.search.score` does for homographies)."""
    hh, ww = ev.distance.shape
    per = []
    for a, b in segments:
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / COVERAGE_STEP_M)) + 1)
        xy = (cam.project(a + np.linspace(0, 1, n)[:, None] * (b - a)) + 0.5) * ev.scale - 0.5
        step = np.linalg.norm(np.diff(xy, axis=0, append=xy[-1:]), axis=1)
        wgt = np.where(np.isfinite(step), step, 0.0)
        r = np.round(np.nan_to_num(xy, nan=-1.0, posinf=-1.0, neginf=-1.0)).astype(int)
        ok = np.isfinite(xy).all(1) & (r[:, 0] >= 0) & (r[:, 0] < ww) & (r[:, 1] >= 0) & (r[:, 1] < hh)
        d = np.full(n, np.inf)
        d[ok] = ev.distance[r[ok, 1], r[ok, 0]]
        kind = "transverse" if abs(b[1] - a[1]) < 1e-9 else "longitudinal"
        per.append((kind, float(np.sum(wgt * (d <= HIT_PX))), float(np.sum(wgt * ok))))
    return per


def _centreline_rms(cam: Camera, segments: np.ndarray, pixels: np.ndarray, scale: float,
                    bin_px: float = 12.0) -> float:
    """RMS offset (full px) of the painted bands' centres from the fitted lines: line pixels within 2 working
    px of a projected segment, their signed distances averaged in bins of ``bin_px`` working px along it
    (a band's width averages out; its centre's offset remains)."""
    layout = camera_layout("square", _n_dist(cam), "centre", cam.image_size)
    p = layout.pack(cam)
    polys = _polyline_points(segments, layout.n_dist)
    proj = _project(layout, p, polys)
    groups = _assign(layout, p, polys, pixels, 2.0 / scale)
    offsets = []
    for s, g in enumerate(groups):
        if len(g) < 5:
            continue
        d = _signed_distance(pixels[g], proj[s])
        a, b = proj[s][0], proj[s][-1]
        u = (b - a) / max(np.linalg.norm(b - a), 1e-9)
        along = np.floor((pixels[g] - a) @ u * scale / bin_px).astype(int)
        for k in np.unique(along):
            sel = along == k
            if sel.sum() >= 3:
                offsets.append(float(np.mean(d[sel])))
    return float(np.sqrt(np.mean(np.square(offsets)))) if offsets else float("nan")


def _evaluate(cam: Camera, residuals: np.ndarray, ev: LineEvidence, model: CourtLines) -> _Candidate:
    net = _support(cam, ev, model.raised)
    return _Candidate(cam, residuals, _support(cam, ev, model.segments_3d),
                      (sum(p[1] for p in net), sum(p[2] for p in net)))


def _projected_polylines(cam: Camera, segments: np.ndarray, n: int = 24) -> np.ndarray:
    """(S, 2, 3) 3D segments → (S, n, 2) image points along each (NaN where behind the camera)."""
    s = np.linspace(0.0, 1.0, n)[None, :, None]
    pts = segments[:, :1] + s * (segments[:, 1:] - segments[:, :1])
    return cam.project(pts.reshape(-1, 3)).reshape(len(segments), n, 2)


def _distance_to_polylines(pix: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """(N, 2) pixels, (P, K, 2) image polylines → (N,) distance to the nearest one (inf when none is seen)."""
    d = np.full(len(pix), np.inf)
    for poly in polys:
        poly = poly[np.isfinite(poly).all(1)]
        if len(poly) >= 2:
            d = np.minimum(d, np.abs(_signed_distance(pix, poly)))
    return d


def confused_segments(cam: Camera, model: CourtLines, scale: float, n: int = 24) -> np.ndarray:
    """(S,) whether each floor segment of the near half of the court (both ends nearer than the net) runs
    within :data:`CONFUSION_PX` working px of a near wall's top rail (glass or mesh top,
    :attr:`CourtLines.structure`) in the image along :data:`CONFUSION_SHARE` of its visible length. Seen from
    a camera right behind the glass, the near wall's top rail hides the near service line or lies next to it
    as a second bright line: its pixels cannot tell the paint from the rail. A far line is not marked: seen
    from a broadcast camera high behind the court, the near fence's top runs just beside the far service
    line and baseline, but as a line of its own (the rail is nearer and thicker, the far paint thin), and the
    placement tests (net, unexplained paint) and the margin judge such a view."""
    S = len(model.segments_3d)
    if not len(model.structure):
        return np.zeros(S, dtype=bool)
    w, h = cam.image_size
    rails = _projected_polylines(cam, model.structure, n)
    pts = _projected_polylines(cam, model.segments_3d, n)
    out = np.zeros(S, dtype=bool)
    for i in range(S):
        if np.any(model.segments_3d[i, :, 1] >= model.net_y):
            continue
        q = pts[i]
        seen = np.isfinite(q).all(1) & (q[:, 0] >= 0) & (q[:, 0] <= w) & (q[:, 1] >= 0) & (q[:, 1] <= h)
        if seen.sum() < 2:
            continue
        d = _distance_to_polylines(q[seen], rails)
        out[i] = np.mean(d * scale <= CONFUSION_PX) >= CONFUSION_SHARE
    return out


def _start_camera(H: np.ndarray, model: CourtLines, size: tuple[int, int]) -> Camera | None:
    """The coplanar calibration (item 1) from the court-line crossings mapped by the homography; a start
    still unconverged after :data:`START_NFEV_PER_PARAM` evaluations per parameter is given up (a wrong
    correspondence: they ended metres off at costs 1e6–1e10 px², and took most of a slow fit's time)."""
    floor = model.crossings()
    P = np.concatenate([floor, np.ones((len(floor), 1))], axis=1) @ H.T
    if np.any(P[:, 2] <= 0):
        return None
    world = np.concatenate([floor, np.zeros((len(floor), 1))], axis=1)
    try:
        return coplanar_camera(world, P[:, :2] / P[:, 2:3], size, START_NFEV_PER_PARAM)
    except CalibrationError:
        return None


def _tape(model: CourtLines) -> np.ndarray:
    """(R, 2, 3) the centre line of the net's white tape: the net's top lowered by :data:`TAPE_CENTRE_M`."""
    return model.raised - np.array([0.0, 0.0, TAPE_CENTRE_M])


def _n_dist(cam: Camera) -> int:
    """Radial coefficients a fitted camera carries: 0, 1 (k1) or 2 (k1, k2)."""
    return 0 if cam.dist is None else (2 if cam.dist[1] != 0 else 1)


def _with_distortion(best: _Candidate, model: CourtLines, pixels: np.ndarray, ev: LineEvidence,
                     distortion: str) -> _Candidate:
    """Refit with k1, then k1 and k2, each kept when it explains clearly more painted line (2 % of the
    visible length), or puts the bands' centres closer to the lines (5 % lower centre-line RMS) while
    explaining about as much (within 2 %). A lens without distortion fits k1 ≈ 0 and changes nothing."""
    if distortion == "none":
        return best
    for n_dist in (1, 2):
        if n_dist == 2 and _evidence_reach(best.camera, model, pixels, ev.scale) < MIN_K2_REACH:
            break
        cam1, res1, _ = refine_on_lines(best.camera, model.segments_3d, pixels, ev.scale, n_dist=n_dist)
        cand = _evaluate(cam1, res1, ev, model)
        if distortion == "k1":
            return cand
        if not _clearly_better(cand, best, model, pixels, ev):
            break
        best = cand
    return best


def _evidence_reach(cam: Camera, model: CourtLines, pixels: np.ndarray, scale: float) -> float:
    """How far out the court's line pixels reach: the 99th percentile of their distance from the image centre
    (pixels within 2 working px of a projected painted line), as a share of the distance to the corners."""
    layout = camera_layout("square", _n_dist(cam), "centre", cam.image_size)
    polys = _polyline_points(model.segments_3d, layout.n_dist)
    groups = _assign(layout, layout.pack(cam), polys, pixels, 2.0 / scale)
    used = np.concatenate([g for g in groups if len(g) >= 5] or [np.zeros(0, int)])
    if not len(used):
        return 0.0
    centre = np.asarray(cam.image_size, float) / 2
    return float(np.percentile(np.linalg.norm(pixels[used] - centre, axis=1), 99) / np.linalg.norm(centre))


def _clearly_better(new: _Candidate, old: _Candidate, model: CourtLines, pixels: np.ndarray,
                    ev: LineEvidence) -> bool:
    """Whether a refit with more lens terms is worth keeping (the rule of :func:`_with_distortion`)."""
    if new.score > old.score + 0.02 * old.visible:
        return True
    rms0 = _centreline_rms(old.camera, model.segments_3d, pixels, ev.scale)
    rms1 = _centreline_rms(new.camera, model.segments_3d, pixels, ev.scale)
    return bool(rms1 < 0.95 * rms0 and new.score > old.score - 0.02 * old.visible)


def unexplained_share(cam: Camera, court: Court, ev: LineEvidence, band_px: float = 3.0, n: int = 24) -> float:
    """Share of the line pixels inside the fitted court's floor (its projected outline) that lie on none of
    the court's modelled lines (paint, net, glass and mesh edges: ``court.lines``) by more than ``band_px``
    working px. A right fit explains nearly all of them; a fit that laid the court's near lines on the
    walls' rails leaves the real painted lines unexplained inside it. Where a mesh panel (``court.planes``
    of material ``mesh``) lies over the far half of the floor in the image — the near fence's top above the
    far court, seen from a broadcast camera high behind it — the pixels are not counted: the wires and posts
    in front of the floor say nothing about its paint. Over the near half (a camera right behind the glass
    sees the near fence over the near service line) they are: there a court laid on the rails leaves the
    real near line unexplained."""
    segs = np.concatenate([np.asarray(v, dtype=float).reshape(-1, 2, 3) for v in court.lines.values()])
    x1, y1 = court.size[:2]
    corners = np.array([[0.0, 0.0, 0.0], [x1, 0.0, 0.0], [x1, y1, 0.0], [0.0, y1, 0.0]])
    outline = _projected_polylines(cam, np.stack([corners, np.roll(corners, -1, axis=0)], axis=1), n).reshape(-1, 2)
    if not np.isfinite(outline).all():
        return float("nan")
    h, w = ev.mask.shape
    floor = np.zeros((h, w), np.uint8)
    cv2.fillPoly(floor, [np.round((outline + 0.5) * ev.scale - 0.5).astype(np.int32)], 1)
    far = _image_region(cam, np.array([[0.0, court.net_y, 0.0], [x1, court.net_y, 0.0], [x1, y1, 0.0],
                                       [0.0, y1, 0.0]]), ev.scale, (h, w), n)
    mesh = np.zeros((h, w), np.uint8)
    for plane in court.planes:
        if plane.material == "mesh":
            mesh |= _image_region(cam, plane.corners_3d(), ev.scale, (h, w), n)
    floor[(far & mesh).astype(bool)] = 0
    ys, xs = np.nonzero(ev.mask & floor.astype(bool))
    if len(xs) < 20:
        return float("nan")
    d = _line_distance_map(_projected_polylines(cam, segs, n), ev.scale, (h, w))
    return float(np.mean(d[ys, xs] > band_px))


def _image_region(cam: Camera, corners: np.ndarray, scale: float, shape: tuple[int, int],
                  n: int = 24) -> np.ndarray:
    """(h, w) uint8 mask (working scale) of a 3D polygon's image (corners (M, 3)); empty when a corner lies
    behind the camera."""
    out = np.zeros(shape, np.uint8)
    sides = np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)
    edges = _projected_polylines(cam, sides, n).reshape(-1, 2)
    if np.isfinite(edges).all() and np.all(cam.depth(corners) > 0):
        cv2.fillPoly(out, [np.round((edges + 0.5) * scale - 0.5).astype(np.int32)], 1)
    return out


def _line_distance_map(polys: np.ndarray, scale: float, shape: tuple[int, int], subpixel: int = 4) -> np.ndarray:
    """(P, K, 2) image polylines (full-resolution px, NaN where unseen) → (h, w) float32 distance (working
    px) from every working-image pixel to the nearest drawn polyline (lines drawn 1 px wide from sub-pixel
    ends, then a Euclidean distance transform: within ~1 px of the exact distance; pieces far outside the
    image are left out, and a pixel near the border does not see a line just outside it)."""
    h, w = shape
    canvas = np.full((h, w), 255, np.uint8)
    q = (polys + 0.5) * scale - 0.5
    far = 4.0 * max(h, w)
    keep = np.isfinite(q).all(axis=2) & (np.abs(q) < far).all(axis=2)
    fixed = np.round(np.nan_to_num(q) * (1 << subpixel)).astype(np.int32)
    for poly, ok in zip(fixed, keep):
        for a, b in zip(np.flatnonzero(ok[:-1] & ok[1:]), np.flatnonzero(ok[:-1] & ok[1:]) + 1):
            cv2.line(canvas, tuple(int(v) for v in poly[a]), tuple(int(v) for v in poly[b]), 0, 1, cv2.LINE_8,
                     subpixel)
    return cv2.distanceTransform(canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def _without_rail(best: _Candidate, model: CourtLines, pixels: np.ndarray, ev: LineEvidence) -> _Candidate:
    """Refit with the near walls' top rails as lines of their own when a painted line runs along one in the
    image: seen from right behind the glass, the rail doubles that line and its pixels pull the fit onto
    the rail; fitted as a line of its own, the rail keeps its pixels and the paint keeps the paint's. The
    candidate's evidence stays that of the painted lines (its ``confused`` segments are recorded)."""
    conf = confused_segments(best.camera, model, ev.scale)
    if not conf.any():
        return best
    n_dist = _n_dist(best.camera)
    # two refits: all lines and the rails from the fit; and, when the confused paint has pulled the fit onto
    # the rail's edge (the paint hidden behind it), out of the rails' reach: a refit without that paint but
    # with the net's tape (which then takes the near line's part in fixing the camera's depth) first, then
    # with the rails. The second is kept only when it explains clearly more line pixels (MIN_GAIN_CLEAR):
    # without the paint, the rail can take a visible painted line's pixels.
    clear = model.segments_3d[~conf]
    start, _, _ = refine_on_lines(best.camera, np.concatenate([clear, _tape(model)]), pixels, ev.scale,
                                  n_dist=n_dist)
    cam, res, _ = refine_on_lines(best.camera, np.concatenate([model.segments_3d, model.structure]), pixels,
                                  ev.scale, n_dist=n_dist)
    cam2, res2, _ = refine_on_lines(start, np.concatenate([clear, model.structure]), pixels, ev.scale,
                                    n_dist=n_dist)
    if len(res2) >= MIN_GAIN_CLEAR * len(res):
        cam, res = cam2, res2
    cand = _evaluate(cam, res, ev, model)
    cand.confused = conf
    return cand


# ---------------------------------------------------------------------------------------- the fit
def fit_court_frames(frames: list[np.ndarray], court: Court, distortion: str = "auto", n_candidates: int = 6,
                     frame_indices: list[int] | None = None) -> AutoFit:
    """Fit the court's painted lines in RGB frames of one fixed view.

    Args:
        frames: RGB uint8 (H, W, 3) frames of the view (their median is used; 5–15 spread over the clip).
        court: the court model (its ``lines.paint`` floor segments are fitted).
        distortion: ``auto`` (k1, then k1 and k2, when they explain the lines clearly better), ``none`` or
            ``k1``.
        n_candidates: correspondence hypotheses refined.
        frame_indices: recorded in the result.
    """
    t0 = time.process_time()
    if not frames:
        raise ValueError("no frames to fit the court in")
    h, w = frames[0].shape[:2]
    size = (w, h)
    model = court_lines(court)
    scale = working_scale(size)
    bg = background(frames, scale)
    ev = LineEvidence.from_mask(line_mask(bg), scale, size)
    rng = np.random.default_rng(0)
    pixels = ev.pixels if len(ev.pixels) <= MAX_PIXELS else ev.pixels[rng.choice(len(ev.pixels), MAX_PIXELS,
                                                                                 replace=False)]
    cands, found = _candidates(ev, ev, model, size, court.net_y, pixels, n_candidates)
    out = _select(cands, ev, court, model, pixels, distortion, frame_indices)
    if not out.accepted and distortion == "auto":
        # a strong barrel lens bends the near lines too much for straight-line search: search again on the
        # background undistorted by a guessed lens, refine on the real line pixels (k1 free), judge the lot
        for k_img in DISTORTION_SEARCH:
            ev_u = LineEvidence.from_mask(line_mask(_undistorted(bg, k_img, size, scale)), scale, size)
            extra, _ = _candidates(ev_u, ev, model, size, court.net_y, pixels, n_candidates, k_img)
            if extra and any(_lead(cands + extra, court, ev) is c for c in extra):  # else the same verdict
                again = _select(cands + extra, ev, court, model, pixels, distortion, frame_indices)
                if again.accepted or out.camera is None:
                    out = again
                if out.accepted:
                    break
    if out.camera is None:
        out.reason = f"no court found ({found})"
    out.cpu_seconds = time.process_time() - t0
    return out


def _undistorted(bg: np.ndarray, k_img: float, size: tuple[int, int], scale: float) -> np.ndarray:
    """The working-scale background (h, w) as an ideal lens would see it, for a radial lens
    ``x_d = x_u (1 + k_img r_u²)`` with image coordinates about the centre in half-diagonals (``k_img`` < 0:
    barrel). Barrel distortion pulls the content in, so every output pixel samples inside the input."""
    h, w = bg.shape[:2]
    W, H = size
    f0 = 0.5 * float(np.hypot(W, H))
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    xu = ((xs + 0.5) / scale - 0.5 - W / 2) / f0
    yu = ((ys + 0.5) / scale - 0.5 - H / 2) / f0
    g = 1.0 + k_img * (xu * xu + yu * yu)
    mx = ((W / 2 + f0 * xu * g + 0.5) * scale - 0.5).astype(np.float32)
    my = ((H / 2 + f0 * yu * g + 0.5) * scale - 0.5).astype(np.float32)
    return cv2.remap(bg, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _candidates(ev_search: LineEvidence, ev: LineEvidence, model: CourtLines, size: tuple[int, int], net_y: float,
                pixels: np.ndarray, n_candidates: int, k_img: float = 0.0) -> tuple[list[_Candidate], str]:
    """Correspondence hypotheses on ``ev_search`` (the background undistorted by ``k_img``, see
    :func:`_undistorted`; ``ev`` itself when 0), each a camera refined on the real line pixels and evaluated
    on ``ev``; and a note of what the search found."""
    trans, longi = split_lines(find_lines(ev_search), size)
    Hs = hypotheses(trans, longi, model, size, net_y)
    cands: list[_Candidate] = []
    f0 = 0.5 * float(np.hypot(*size))
    for hyp in best_hypotheses(Hs, ev_search, model, n_candidates):
        start = _start_camera(hyp.H, model, size)
        if start is None:
            continue
        n_dist = 0
        if k_img:
            # the same lens in the camera's own normalised coordinates: k1 = k_img (f / f0)²
            k1 = k_img * (start.K[0, 0] / f0) ** 2
            start = Camera.from_krt(start.K, start.R, start.t, size, dist=[k1, 0.0, 0.0, 0.0, 0.0])
            n_dist = 1
        cam, res, _ = refine_on_lines(start, model.segments_3d, pixels, ev.scale, n_dist=n_dist)
        cands.append(_evaluate(cam, res, ev, model))
    return cands, (f"{len(trans)} transverse and {len(longi)} longitudinal lines, "
                   f"{len(Hs)} plausible correspondences")


def _select(cands: list[_Candidate], ev: LineEvidence, court: Court, model: CourtLines, pixels: np.ndarray,
            distortion: str, frame_indices: list[int] | None) -> AutoFit:
    """The fit from refined candidates: the best placeable one, its lens and rail refits, its margin over
    the rivals, judged by the gate (:func:`_judge`). No camera when there is no candidate."""
    out = AutoFit(None, False, frames=list(frame_indices or []))
    if not cands:
        return out
    scale = ev.scale
    cands = sorted(cands, key=lambda c: -c.score)
    lead = _lead(cands, court, ev)
    best = _with_distortion(lead, model, pixels, ev, distortion)
    best = _without_rail(best, model, pixels, ev)
    others = [c for c in cands if c is not lead and not c.same_as(lead, model)]
    best_confused = confused_segments(best.camera, model, scale)
    if not best_confused.any() or (best.confused is not None and _rails_found(best, model, ev) >= MIN_PINNED):
        # a rival that lays a painted line on the near wall's top rail is the rail's echo, not another court;
        # nor is one the gate would refuse on its own (the net not where it puts it, most floor paint unexplained).
        # A fit refined with the rails counts such rivals only when the rails do not confirm it: rails found
        # along most of their image length pin the camera's height and tilt independently of the floor paint.
        others = [c for c in others
                  if not confused_segments(c.camera, model, scale).any() and _placeable(c, court, ev)]
    margin = best.score / max(others[0].score, 1e-9) if others and others[0].score > 0 else float("inf")
    _judge(out, best, margin, best_confused, ev, court, model, pixels)
    return out


def _lead(cands: list[_Candidate], court: Court, ev: LineEvidence) -> _Candidate:
    """The best-scoring candidate that passes the gate's placement tests on its own, else the best."""
    ranked = sorted(cands, key=lambda c: -c.score)
    return next((c for c in ranked if _placeable(c, court, ev)), ranked[0])


def _placeable(cand: _Candidate, court: Court, ev: LineEvidence) -> bool:
    """Whether a candidate placement passes the gate's placement tests on its own: the net found where it
    puts it, and at most ``MAX_UNEXPLAINED`` of the line pixels on its floor on none of its lines."""
    return cand.net_found and not unexplained_share(cand.camera, court, ev) > MAX_UNEXPLAINED


def _near_pinned(best: _Candidate, model: CourtLines, ev: LineEvidence) -> bool:
    """For a fit refined with the near rails as lines of their own: whether the painted line(s) running along
    a rail are found along :data:`MIN_PINNED` of their visible length, or a rail is (one at least
    :data:`MIN_NET_PX` long in the image). Otherwise the near court is placed by the side lines' extrapolation
    alone, a few pixels off (dark rails, the paint hidden behind them)."""
    paint = [h / v for (_, h, v), c in zip(best.per_line, best.confused) if c and v > 0]
    rails = [h / v for h, v in _rail_support(best, model, ev)]
    return min(paint, default=1.0) >= MIN_PINNED or max(rails, default=0.0) >= MIN_PINNED


def _rail_support(best: _Candidate, model: CourtLines, ev: LineEvidence) -> list[tuple[float, float]]:
    """(found, visible) image length of each near wall's top rail at least :data:`MIN_NET_PX` long where
    ``best`` projects it."""
    return [(h, v) for _, h, v in _support(best.camera, ev, model.structure) if v >= MIN_NET_PX]


def _rails_found(best: _Candidate, model: CourtLines, ev: LineEvidence) -> float:
    """Share of the rails of :func:`_rail_support` found in the line pixels, weighted by image length; 0 when
    none is that long."""
    sup = _rail_support(best, model, ev)
    total = sum(v for _, v in sup)
    return sum(h for h, _ in sup) / total if total > 0 else 0.0


def _judge(out: AutoFit, best: _Candidate, margin: float, confused: np.ndarray, ev: LineEvidence, court: Court,
           model: CourtLines, pixels: np.ndarray) -> None:
    """Fill the fit's figures, confidence and gate decision (``confused``: (S,) :func:`confused_segments`
    of the fit's camera)."""
    cam = best.camera
    out.camera = cam
    out.coverage = best.hits / max(best.visible, 1)
    out.net_coverage = best.net_coverage
    out.line_rms_px = _centreline_rms(cam, model.segments_3d, pixels, ev.scale)
    out.lines_supported = tuple(sum(1 for k, hh, v in best.per_line if k == kind and v >= 20 and hh >= 0.5 * v)
                                for kind in ("transverse", "longitudinal"))
    out.margin = margin
    rms_w = out.line_rms_px * ev.scale
    out.confidence = float(np.clip(out.coverage, 0, 1) * np.clip(1 - rms_w / 3.0, 0, 1) *
                           np.clip((margin - 1) / 0.5, 0, 1))
    c = cam.centre
    problems = []
    if out.coverage < MIN_COVERAGE:
        problems.append(f"only {100 * out.coverage:.0f} % of the visible court lines found")
    if not rms_w <= MAX_LINE_RMS:
        problems.append(f"line pixels {out.line_rms_px:.1f} px from the fitted lines")
    if min(out.lines_supported) < MIN_LINES_PER_KIND:
        problems.append(f"too few lines supported ({out.lines_supported[0]} across, {out.lines_supported[1]} along)")
    if not best.net_found:
        problems.append(f"the net is not where the fit puts it ({100 * best.net_coverage:.0f} % found)")
    min_margin = MIN_MARGIN if best.confused is None else MIN_MARGIN_RAIL
    if margin < min_margin:
        problems.append(f"another placement of the court fits almost as well (margin {margin:.2f})")
    if best.confused is not None and not _near_pinned(best, model, ev):
        problems.append("the near service line runs along the near wall's top rail in the image and neither is "
                        f"found along {100 * MIN_PINNED:.0f} % of its length, so nothing pins the near court")
    if confused.any() and best.confused is None:
        problems.append(f"{int(confused.sum())} painted line(s) run along the near wall's top rail in the image, so "
                        "the fit cannot tell the paint from the rail")
    out.unexplained = unexplained_share(cam, court, ev)
    if out.unexplained > MAX_UNEXPLAINED:
        problems.append(f"{100 * out.unexplained:.0f} % of the line pixels on the fitted court's floor lie on none "
                        "of its lines (the court may be placed on the walls' rails)")
    near = _near_line_check(best, model, pixels, ev)
    out.near_check_px = near / ev.scale
    if near > MAX_NEAR_CHECK_PX:
        problems.append(f"the nearest painted line across is {out.near_check_px:.0f} px from where the "
                        "other lines and the net put it (it may be fitted on a rail or the fence's wires)")
    if not (c[2] > 1.0 and c[1] < court.net_y):
        problems.append(f"implausible camera position {np.round(c, 1).tolist()}")
    elif elevation_deg(c, np.asarray(court.size[:2], float) / 2) < MIN_ELEVATION_DEG:
        problems.append(f"the camera would see the floor at under {MIN_ELEVATION_DEG:.0f}° (from "
                        f"{np.round(c, 1).tolist()}): the court is laid on upright structure seen edge-on")
    out.accepted = not problems
    out.reason = "; ".join(problems)
    cam.source = "auto"
    cam.meta["auto"] = out.meta()


def _near_line_check(best: _Candidate, model: CourtLines, pixels: np.ndarray, ev: LineEvidence) -> float:
    """Leave-one-out check of the near court (working px): the camera refitted without the nearest painted
    transverse line in view, on the other lines and the net's tape; how far (max over its visible length)
    that line moves. The nearest line fixes the camera's depth more than any other, and a rail or a fence
    wire next to it can take its place; the rest of the court then puts it elsewhere. 0 when fewer than two
    transverse lines are in view."""
    cam = best.camera
    w, h = cam.image_size
    segs = model.segments_3d
    polys = _projected_polylines(cam, segs, 20)
    ok = np.isfinite(polys).all(2) & (polys[..., 0] >= 0) & (polys[..., 0] < w) & (polys[..., 1] >= 0) & \
        (polys[..., 1] < h)
    seen = [i for i, (a, b) in enumerate(segs) if abs(a[1] - b[1]) < 1e-9 and ok[i].sum() >= 5]
    if len(seen) < 2:
        return 0.0
    i = min(seen, key=lambda k: segs[k, 0, 1])
    rest = np.concatenate([np.delete(segs, i, axis=0), _tape(model)])
    cam2, _, _ = refine_on_lines(cam, rest, pixels, ev.scale, n_dist=_n_dist(cam))
    after = _projected_polylines(cam2, segs[i : i + 1], 20)[0]
    return float(np.max(np.linalg.norm(after[ok[i]] - polys[i][ok[i]], axis=1)) * ev.scale)


def sample_frame_indices(n_frames: int, n: int = N_FRAMES, start: int = 0, stop: int | None = None) -> list[int]:
    """``n`` frame indices spread evenly over ``[start, stop)``."""
    stop = n_frames if stop is None else min(stop, n_frames)
    if stop <= start:
        raise ValueError(f"no frames between {start} and {stop}")
    return sorted({int(i) for i in np.linspace(start, stop - 1, min(n, stop - start))})


def fit_court(clip, court: Court, distortion: str = "auto", frames: list[int] | None = None) -> AutoFit:
    """Fit the court in a clip folder (:class:`inference.clipio.Clip`): the median of :data:`N_FRAMES`
    frames spread over the clip (or the given frame indices)."""
    t0 = time.process_time()
    idx = frames if frames is not None else sample_frame_indices(clip.n_frames)
    rects = clip_mask(clip)
    with clip.frames(cache_size=0) as src:
        images = [apply_mask(src.read(i), rects) for i in idx]
    fit = fit_court_frames(images, court, distortion=distortion, frame_indices=idx)
    fit.cpu_seconds = time.process_time() - t0
    if fit.camera is not None:
        fit.camera.meta["auto"] = fit.meta()
    return fit
