"""Camera calibration from named court-point correspondences.

Normalised DLT (Hartley) for the 3×4 projection matrix, then Levenberg-Marquardt refinement of a
pinhole model (square pixels by default, optional radial distortion) on the reprojection error,
decomposition into K, R, t and the camera centre, and per-point residuals.

Example:
    >>> court = load_court("padel")
    >>> result = calibrate_court(court, {"near_left": (101.0, 650.2), ...}, image_size=(1280, 720))
    >>> result.camera.centre, result.rms_px, result.residuals_px["near_left"]
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from inference.camera import Camera, distort_normalized
from inference.court import Court

MIN_POINTS = 6
#: Points whose RMS distance from their best-fit plane is below this (metres) count as coplanar.
COPLANAR_TOL_M = 0.05
MODELS = ("square", "pinhole")


class CalibrationError(ValueError):
    """Calibration is impossible with the given points; the message says which points to add."""


@dataclass
class CalibrationResult:
    """The camera and how well it explains the clicked points.

    Attributes:
        camera: the refined camera (``camera.residuals_px`` and ``rms_px`` filled in).
        names: (N,) point names in input order.
        residuals_px: name → reprojection error in pixels.
        rms_px: root mean square of the residuals.
        suspect: names whose residual is far above the others (probably a wrong click).
    """

    camera: Camera
    names: list[str]
    residuals_px: dict[str, float]
    rms_px: float
    suspect: list[str] = field(default_factory=list)

    def table(self) -> str:
        """A printable per-point residual table."""
        width = max(12, *(len(n) for n in self.names))
        lines = [f"{'point':<{width}}  residual_px"]
        for n in self.names:
            flag = "  <- check this click" if n in self.suspect else ""
            lines.append(f"{n:<{width}}  {self.residuals_px[n]:11.2f}{flag}")
        lines.append(f"{'RMS':<{width}}  {self.rms_px:11.2f}")
        return "\n".join(lines)


def _normalising_transform(pts: np.ndarray) -> np.ndarray:
    """Similarity T (d+1 × d+1) moving the centroid to 0 and the mean distance to sqrt(d)."""
    d = pts.shape[1]
    c = pts.mean(axis=0)
    mean_dist = np.linalg.norm(pts - c, axis=1).mean()
    s = np.sqrt(d) / max(mean_dist, 1e-12)
    T = np.eye(d + 1)
    T[:d, :d] *= s
    T[:d, d] = -s * c
    return T


def dlt(world: np.ndarray, image: np.ndarray) -> np.ndarray:
    """Normalised direct linear transform.

    Args:
        world: (N, 3) court points, N ≥ 6, not coplanar.
        image: (N, 2) pixels.
    Returns:
        (3, 4) projection matrix, sign chosen so the points have positive depth.
    """
    T3 = _normalising_transform(world)
    T2 = _normalising_transform(image)
    Xn = (np.hstack([world, np.ones((len(world), 1))]) @ T3.T)
    xn = (np.hstack([image, np.ones((len(image), 1))]) @ T2.T)
    n = len(world)
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xn
    A[0::2, 8:12] = -xn[:, 0:1] * Xn
    A[1::2, 4:8] = Xn
    A[1::2, 8:12] = -xn[:, 1:2] * Xn
    _, _, Vt = np.linalg.svd(A)
    Pn = Vt[-1].reshape(3, 4)
    P = np.linalg.inv(T2) @ Pn @ T3
    depth = np.hstack([world, np.ones((n, 1))]) @ P[2]
    if np.median(depth) < 0:
        P = -P
    return P / np.linalg.norm(P)


def coplanarity_rms(world: np.ndarray) -> float:
    """RMS distance (metres) of (N, 3) points from their best-fit plane (0 for coplanar points)."""
    centred = world - world.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    return float(s[-1] / np.sqrt(len(world)))


def _check_geometry(world: np.ndarray, names: Sequence[str], suggest: Sequence[str]) -> None:
    hint = ""
    if suggest:
        hint = " Click some of these off-ground points too: " + ", ".join(suggest[:8]) + "."
    if len(world) < MIN_POINTS:
        raise CalibrationError(
            f"{len(world)} court points given ({', '.join(names)}); at least {MIN_POINTS} are needed, "
            f"not all on one plane.{hint}"
        )
    if coplanarity_rms(world) < COPLANAR_TOL_M:
        raise CalibrationError(
            f"the {len(world)} court points ({', '.join(names)}) all lie on one plane, so the camera "
            f"cannot be recovered (its height and focal length trade off).{hint}"
        )


def _pack(cam: Camera, model: str, n_dist: int) -> np.ndarray:
    K = cam.K
    intr = [0.5 * (K[0, 0] + K[1, 1])] if model == "square" else [K[0, 0], K[1, 1]]
    rvec = Rotation.from_matrix(cam.R).as_rotvec()
    dist = np.zeros(n_dist) if cam.dist is None else cam.dist[:n_dist]
    return np.concatenate([intr, K[:2, 2], rvec, cam.t, dist])


def _unpack(p: np.ndarray, model: str, n_dist: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    i = 1 if model == "square" else 2
    fx, fy = (p[0], p[0]) if model == "square" else (p[0], p[1])
    cx, cy = p[i : i + 2]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    R = Rotation.from_rotvec(p[i + 2 : i + 5]).as_matrix()
    t = p[i + 5 : i + 8]
    dist = np.zeros(5)
    dist[: min(n_dist, 2)] = p[i + 8 : i + 8 + min(n_dist, 2)]
    return K, R, t, dist


def _project_params(p: np.ndarray, world: np.ndarray, model: str, n_dist: int) -> np.ndarray:
    K, R, t, dist = _unpack(p, model, n_dist)
    Xc = world @ R.T + t
    xn = Xc[:, :2] / Xc[:, 2:3]
    if n_dist:
        xn = distort_normalized(xn, dist)
    return xn @ K[:2, :2].T + K[:2, 2]


def refine(cam: Camera, world: np.ndarray, image: np.ndarray, model: str = "square", n_dist: int = 0) -> Camera:
    """Minimise the reprojection error over intrinsics, pose and (optionally) k1[, k2].

    Args:
        cam: initial camera (e.g. from :func:`dlt`).
        world: (N, 3) court points; image: (N, 2) pixels.
        model: ``square`` (fx = fy, no skew) or ``pinhole`` (fx, fy free, no skew).
        n_dist: number of radial distortion coefficients to fit (0, 1 or 2).
    """
    if model not in MODELS:
        raise ValueError(f"unknown camera model {model!r}; choose one of {MODELS}")
    if n_dist not in (0, 1, 2):
        raise ValueError("n_dist must be 0, 1 or 2")
    p0 = _pack(cam, model, n_dist)
    if 2 * len(world) < len(p0):
        raise CalibrationError(f"{len(world)} points are too few for {len(p0)} camera parameters")

    def residuals(p):
        return (_project_params(p, world, model, n_dist) - image).ravel()

    sol = least_squares(residuals, p0, method="lm", x_scale="jac", max_nfev=2000)
    K, R, t, dist = _unpack(sol.x, model, n_dist)
    return Camera.from_krt(K, R, t, cam.image_size, dist=dist if n_dist else None)


def _suspects(res: np.ndarray, names: Sequence[str]) -> list[str]:
    """Points whose residual is well above the rest: > 3× the median and > 4 px."""
    if len(res) < MIN_POINTS + 1:
        return []
    med = float(np.median(res))
    return [n for n, r in zip(names, res) if r > max(3 * med, 4.0)]


def calibrate(
    world: np.ndarray,
    image_px: np.ndarray,
    image_size: tuple[int, int],
    names: Sequence[str] | None = None,
    model: str = "square",
    n_dist: int = 0,
    suggest: Sequence[str] = (),
) -> CalibrationResult:
    """Calibrate a camera from ≥ 6 non-coplanar 3D↔2D correspondences.

    Args:
        world: (N, 3) court-frame points, metres.
        image_px: (N, 2) their pixels.
        image_size: (W, H).
        names: (N,) point names for the report (default ``p0, p1, ...``).
        model: ``square`` or ``pinhole`` (see :func:`refine`).
        n_dist: radial distortion coefficients to fit (0–2; needs many well-spread points).
        suggest: point names to recommend when the input is degenerate.
    Raises:
        CalibrationError: too few points, coplanar points, or non-finite input.
    """
    world = np.asarray(world, dtype=float).reshape(-1, 3)
    image_px = np.asarray(image_px, dtype=float).reshape(-1, 2)
    names = list(names) if names is not None else [f"p{i}" for i in range(len(world))]
    if len(world) != len(image_px) or len(names) != len(world):
        raise ValueError(f"world {world.shape}, image {image_px.shape} and names ({len(names)}) differ")
    bad = [n for n, ok in zip(names, np.isfinite(world).all(1) & np.isfinite(image_px).all(1)) if not ok]
    if bad:
        raise CalibrationError(f"non-finite coordinates for points {bad}")
    _check_geometry(world, names, suggest)
    P = dlt(world, image_px)
    cam = Camera(P=P, image_size=image_size)
    cam = refine(cam, world, image_px, model=model, n_dist=n_dist)
    res = np.linalg.norm(cam.project(world) - image_px, axis=1)
    rms = float(np.sqrt(np.mean(res**2)))
    residuals = dict(zip(names, res.tolist()))
    cam.rms_px, cam.residuals_px, cam.source = rms, residuals, "calibrated"
    return CalibrationResult(cam, names, residuals, rms, _suspects(res, names))


def calibrate_court(
    court: Court,
    image_points: Mapping[str, Sequence[float]],
    image_size: tuple[int, int],
    model: str = "square",
    n_dist: int = 0,
) -> CalibrationResult:
    """Calibrate from clicked named points of ``court``.

    Args:
        court: the court model whose named points were clicked.
        image_points: point name → (x, y) pixels.
        image_size: (W, H).
    Raises:
        KeyError: a name is not a point of the court (the message lists the valid names).
        CalibrationError: degenerate input; the message names off-ground points to add.
    """
    names = list(image_points)
    world = court.point_array(names)
    image = np.array([image_points[n] for n in names], dtype=float).reshape(-1, 2)
    suggest = [n for n in court.off_ground_points() if n not in image_points]
    return calibrate(world, image, image_size, names=names, model=model, n_dist=n_dist, suggest=suggest)
