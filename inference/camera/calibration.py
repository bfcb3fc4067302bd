"""Camera calibration from named court-point correspondences.

Two starts, one refinement:

* **points on one plane** (the floor corners, service lines and net ends that most users and court-line
  tools give): the plane's homography, the focal length from Zhang's single-view constraints (square
  pixels, no skew, principal point at the image centre) and the pose from the homography;
* **points off the plane too**: a normalised DLT (Hartley) for the 3×4 projection matrix, and the plane
  start on the floor subset when it has ≥ 4 points.

Each start is refined by Levenberg-Marquardt on the reprojection error of *all* points over f, R, t
(optionally radial distortion k1[, k2]); the principal point is fixed at the image centre for coplanar
points and otherwise free under a Gaussian prior centred on the image centre (σ = 2 % of the larger image
side) that is used only when it explains the points clearly better, so a few off-plane points cannot buy a principal point far from the centre. The result carries
per-point residuals, a 1-σ uncertainty of the camera centre and focal length (from the Gauss-Newton
covariance), and warnings about weak geometry.

Example:
    >>> court = load_court("padel")
    >>> result = calibrate_court(court, {"near_left": (101.0, 650.2), ...}, image_size=(1280, 720))
    >>> result.camera.centre, result.rms_px, result.residuals_px["near_left"], result.centre_sigma_m
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
#: ``prior``: principal point free under a prior at the image centre (coplanar points: fixed there);
#: ``centre``: fixed at the image centre; ``free``: free without a prior (the plain DLT behaviour).
PRINCIPAL_POINT_MODES = ("prior", "centre", "free")
#: 1-σ of the principal-point prior as a fraction of the larger image side.
PP_SIGMA_FRAC = 0.02
#: Noise floor (px) of the covariance: clicks are never better than this, even when the fit is exact.
NOISE_FLOOR_PX = 0.5
#: RMS (px) above which a fit without lens distortion says that the lens may bend straight lines: careful
#: clicks miss by about 1 px, and a lens with k1 ≈ −0.1 already leaves ~3 px on a 1080p court.
DISTORTION_HINT_RMS_PX = 2.0
#: Horizontal fields of view (degrees) tried as starts besides Zhang's closed form.
FOV_STARTS_DEG = (15.0, 30.0, 45.0, 60.0, 80.0, 100.0)


class CalibrationError(ValueError):
    """Calibration is impossible with the given points; the message says which points to add."""


@dataclass
class CalibrationResult:
    """The camera and how well it explains the clicked points.

    Attributes:
        camera: the refined camera (``camera.residuals_px``, ``rms_px`` and ``meta`` filled in).
        names: (N,) point names in input order.
        residuals_px: name → reprojection error in pixels.
        rms_px: root mean square of the residuals.
        suspect: names whose residual is far above the others (probably a wrong click).
        method: ``plane`` (all points on one plane) or ``general`` (points off the plane too).
        centre_sigma_m: (3,) 1-σ uncertainty of the camera centre (court metres).
        focal_sigma_px: 1-σ uncertainty of the focal length.
        warnings: weak-geometry warnings, each a sentence that says what to do.
    """

    camera: Camera
    names: list[str]
    residuals_px: dict[str, float]
    rms_px: float
    suspect: list[str] = field(default_factory=list)
    method: str = "general"
    centre_sigma_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    focal_sigma_px: float = float("nan")
    warnings: list[str] = field(default_factory=list)

    def table(self) -> str:
        """A printable per-point residual table, the uncertainty of the camera and the warnings."""
        width = max(12, *(len(n) for n in self.names))
        lines = [f"{'point':<{width}}  residual_px"]
        for n in self.names:
            flag = "  <- check this click" if n in self.suspect else ""
            lines.append(f"{n:<{width}}  {self.residuals_px[n]:11.2f}{flag}")
        lines.append(f"{'RMS':<{width}}  {self.rms_px:11.2f}")
        s = self.centre_sigma_m
        lines.append(f"camera centre ± (1σ, m): x {s[0]:.3f}  y {s[1]:.3f}  z {s[2]:.3f};  "
                     f"focal ± {self.focal_sigma_px:.1f} px  ({self.method} calibration)")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


# ------------------------------------------------------------------------------------- linear starts
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


def _homogeneous(a: np.ndarray) -> np.ndarray:
    return np.hstack([a, np.ones((len(a), 1))])


def _dlt_solve(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The (3, d+1) matrix M with ``dst ~ M [src; 1]`` from (N, d) ↔ (N, 2) pairs: Hartley-normalised DLT."""
    T1, T2 = _normalising_transform(src), _normalising_transform(dst)
    a = _homogeneous(src) @ T1.T
    b = _homogeneous(dst) @ T2.T
    k = a.shape[1]
    A = np.zeros((2 * len(src), 3 * k))
    A[0::2, 0:k] = a
    A[0::2, 2 * k :] = -b[:, 0:1] * a
    A[1::2, k : 2 * k] = a
    A[1::2, 2 * k :] = -b[:, 1:2] * a
    _, _, Vt = np.linalg.svd(A)
    return np.linalg.inv(T2) @ Vt[-1].reshape(3, k) @ T1


def dlt(world: np.ndarray, image: np.ndarray) -> np.ndarray:
    """Normalised direct linear transform.

    Args:
        world: (N, 3) court points, N ≥ 6, not coplanar.
        image: (N, 2) pixels.
    Returns:
        (3, 4) projection matrix, sign chosen so the points have positive depth.
    """
    P = _dlt_solve(world, image)
    if np.median(_homogeneous(world) @ P[2]) < 0:
        P = -P
    return P / np.linalg.norm(P)


def homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Normalised DLT homography ``dst ~ H src`` from (N ≥ 4, 2) point pairs; (3, 3), ‖H‖ = 1."""
    H = _dlt_solve(src, dst)
    return H / np.linalg.norm(H)


def focal_from_homography(H: np.ndarray, principal_point: Sequence[float], scale: float) -> float | None:
    """Zhang's single-view constraints for a square-pixel, zero-skew camera with a known principal point.

    With ``ω = K⁻ᵀK⁻¹ = diag(w, w, 1)`` (w = 1/f², pixels shifted to the principal point and divided by
    ``scale``) the columns h1, h2 of the plane's homography satisfy ``h1ᵀωh2 = 0`` and
    ``h1ᵀωh1 = h2ᵀωh2``; both are linear in w and solved together by least squares.

    Args:
        H: (3, 3) plane → pixel homography (plane axes orthonormal, metres).
        principal_point: (cx, cy) pixels; scale: pixel scale (e.g. the larger image side).
    Returns:
        the focal length in pixels, or None where the constraints give no positive solution (a camera
        looking straight at the plane, for instance).
    """
    S = np.array([[1 / scale, 0, -principal_point[0] / scale], [0, 1 / scale, -principal_point[1] / scale],
                  [0, 0, 1.0]])
    Hn = S @ H
    Hn = Hn / np.linalg.norm(Hn[:, :2])
    (a1, b1, c1), (a2, b2, c2) = Hn[:, 0], Hn[:, 1]
    A = np.array([a1 * a2 + b1 * b2, a1 * a1 + b1 * b1 - a2 * a2 - b2 * b2])
    B = np.array([c1 * c2, c1 * c1 - c2 * c2])
    if A @ A < 1e-18:
        return None
    w = -(A @ B) / (A @ A)
    if not np.isfinite(w) or w <= 0:
        return None
    return float(scale / np.sqrt(w))


def pose_from_homography(H: np.ndarray, K: np.ndarray, plane: PlaneFrame,
                         plane_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World → camera rotation R (3, 3) and translation t (3,) from a plane homography and intrinsics.

    ``K⁻¹H ∝ [R u, R v, R o + t]`` for the plane's origin o and in-plane axes u, v; the scale's sign puts the
    plane's points (``plane_uv``, (N, 2)) in front of the camera; R is the nearest rotation.
    """
    M = np.linalg.solve(K, H)
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    M = M * lam
    if np.median(_homogeneous(plane_uv) @ M[2]) < 0:
        M = -M
    r1, r2 = M[:, 0], M[:, 1]
    Rp = np.stack([r1, r2, np.cross(r1, r2)], axis=1)
    U, _, Vt = np.linalg.svd(Rp)
    Rp = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    R = Rp @ plane.basis.T
    t = M[:, 2] - R @ plane.origin
    return R, t


# ------------------------------------------------------------------------------------------- planes
@dataclass(frozen=True)
class PlaneFrame:
    """A plane through points: origin (3,), orthonormal basis (3, 3) with columns u, v, normal."""

    origin: np.ndarray
    basis: np.ndarray
    rms_m: float
    spread_m: float  # RMS extent along the plane's weaker in-plane axis (0 for collinear points)

    def to_plane(self, world: np.ndarray) -> np.ndarray:
        """(N, 3) points → (N, 2) in-plane coordinates."""
        return (world - self.origin) @ self.basis[:, :2]


def fit_plane(world: np.ndarray) -> PlaneFrame:
    """The best-fit plane of (N, 3) points. Its normal points up (+z) when it is not vertical."""
    origin = world.mean(axis=0)
    _, s, Vt = np.linalg.svd(world - origin)
    u, v, n = Vt
    if n[2] < 0 or (abs(n[2]) < 1e-9 and n @ (origin - world[0]) < 0):
        n, v = -n, -v  # keep the basis right-handed
    basis = np.stack([u, v, n], axis=1)
    if np.linalg.det(basis) < 0:
        basis[:, 1] *= -1
    k = np.sqrt(len(world))
    return PlaneFrame(origin, basis, float(s[-1] / k) if len(s) == 3 else 0.0, float(s[1] / k))


def coplanarity_rms(world: np.ndarray) -> float:
    """RMS distance (metres) of (N, 3) points from their best-fit plane (0 for coplanar points)."""
    return fit_plane(np.asarray(world, dtype=float)).rms_m


# ------------------------------------------------------------------------------------ refinement
@dataclass(frozen=True)
class CameraLayout:
    """Which camera parameters are free: ``[f | fx, fy] [cx, cy] rotvec(3) t(3) [k1[, k2]]``."""

    model: str
    free_pp: bool
    n_dist: int
    centre: tuple[float, float]
    pp_weight: float  # prior weight: the click noise (px) over the prior's σ (px); 0: no prior

    @property
    def n_f(self) -> int:
        return 1 if self.model == "square" else 2

    def pack(self, cam: Camera) -> np.ndarray:
        K = cam.K
        f = [0.5 * (K[0, 0] + K[1, 1])] if self.model == "square" else [K[0, 0], K[1, 1]]
        pp = list(K[:2, 2]) if self.free_pp else []
        dist = np.zeros(self.n_dist) if cam.dist is None else cam.dist[: self.n_dist]
        return np.concatenate([f, pp, Rotation.from_matrix(cam.R).as_rotvec(), cam.t, dist])

    def unpack(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        i = self.n_f
        fx, fy = (p[0], p[0]) if self.model == "square" else (p[0], p[1])
        if self.free_pp:
            cx, cy = p[i : i + 2]
            i += 2
        else:
            cx, cy = self.centre
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
        R = Rotation.from_rotvec(p[i : i + 3]).as_matrix()
        t = p[i + 3 : i + 6]
        dist = np.zeros(5)
        dist[: self.n_dist] = p[i + 6 : i + 6 + self.n_dist]
        return K, R, t, dist

    def camera(self, p: np.ndarray, size: tuple[int, int]) -> Camera:
        """The :class:`Camera` of parameter vector ``p``."""
        K, R, t, dist = self.unpack(p)
        return Camera.from_krt(K, R, t, size, dist=dist if self.n_dist else None)

    def centre_of(self, p: np.ndarray) -> np.ndarray:
        i = self.n_f + (2 if self.free_pp else 0)
        return -Rotation.from_rotvec(p[i : i + 3]).as_matrix().T @ p[i + 3 : i + 6]

    def project(self, p: np.ndarray, world: np.ndarray) -> np.ndarray:
        """(N, 2) pixels of (N, 3) court points under the parameters ``p`` (lens distortion included)."""
        K, R, t, dist = self.unpack(p)
        Xc = world @ R.T + t
        z = Xc[:, 2:3]
        xn = Xc[:, :2] / np.where(np.abs(z) < 1e-9, 1e-9, z)
        if self.n_dist:
            xn = distort_normalized(xn, dist)
        return xn @ K[:2, :2].T + K[:2, 2]

    def residuals(self, p: np.ndarray, world: np.ndarray, image: np.ndarray,
                  lines: LineClicks | None = None) -> np.ndarray:
        K = self.unpack(p)[0]
        r = (self.project(p, world) - image).ravel()
        if lines is not None and len(lines):
            r = np.concatenate([r, lines.residuals(lambda X: self.project(p, X))])
        if self.free_pp and self.pp_weight > 0:
            r = np.concatenate([r, self.pp_weight * (K[:2, 2] - np.asarray(self.centre))])
        return r


#: a click along a court line farther than this from the line as the calibrated camera draws it is flagged
LINE_CLICK_OFF_PX = 8.0


@dataclass(frozen=True)
class LineClicks:
    """Pixels clicked somewhere along straight court lines (a bent side line under a wide-angle lens).

    Attributes:
        start, end: (M, 3) court points at the two ends of each click's line; xy: (M, 2) its pixel.
    """

    start: np.ndarray
    end: np.ndarray
    xy: np.ndarray
    samples: int = 96

    def __len__(self) -> int:
        return len(self.xy)

    def residuals(self, project) -> np.ndarray:
        """(M,) pixel distance of each click from its line as ``project`` draws it (a polyline of ``samples``
        points, so the lens bends it)."""
        s = np.linspace(-0.1, 1.1, self.samples)  # a little beyond the ends: a click on the line's tip
        M, S = len(self.xy), len(s)
        world = self.start[:, None, :] + s[None, :, None] * (self.end - self.start)[:, None, :]  # (M, S, 3)
        poly = project(world.reshape(-1, 3)).reshape(M, S, 2)
        seg, d = poly[:, 1:] - poly[:, :-1], self.xy[:, None, :] - poly[:, :-1]  # (M, S - 1, 2)
        u = np.clip(np.sum(d * seg, axis=2) / np.maximum(np.sum(seg * seg, axis=2), 1e-12), 0.0, 1.0)
        return np.min(np.linalg.norm(d - u[..., None] * seg, axis=2), axis=1)


@dataclass
class _Fit:
    layout: CameraLayout
    p: np.ndarray
    cost: float
    jac: np.ndarray
    n_data: int  # residual rows that are pixel coordinates (the rest is the prior)

    def camera(self, size: tuple[int, int]) -> Camera:
        return self.layout.camera(self.p, size)


def _solve(layout: CameraLayout, p0: np.ndarray, world: np.ndarray, image: np.ndarray,
           nfev_per_param: int = 400, lines: LineClicks | None = None) -> _Fit | None:
    n_lines = len(lines) if lines is not None else 0
    if 2 * len(world) + n_lines < len(p0):
        raise CalibrationError(f"{len(world)} points are too few for {len(p0)} camera parameters")
    try:
        sol = least_squares(layout.residuals, p0, args=(world, image, lines), method="lm", x_scale="jac",
                            max_nfev=nfev_per_param * len(p0))
    except ValueError:
        return None
    if not np.all(np.isfinite(sol.x)) or sol.x[0] <= 0:
        return None
    K, R, t, _ = layout.unpack(sol.x)
    if np.median((world @ R.T + t)[:, 2]) <= 0:
        return None
    return _Fit(layout, sol.x, float(2 * sol.cost), sol.jac, 2 * len(world) + n_lines)


def refine(cam: Camera, world: np.ndarray, image: np.ndarray, model: str = "square", n_dist: int = 0,
           principal_point: str = "free") -> Camera:
    """Minimise the reprojection error over intrinsics, pose and (optionally) k1[, k2].

    Args:
        cam: initial camera (e.g. from :func:`dlt`).
        world: (N, 3) court points; image: (N, 2) pixels.
        model: ``square`` (fx = fy, no skew) or ``pinhole`` (fx, fy free, no skew).
        n_dist: number of radial distortion coefficients to fit (0, 1 or 2).
        principal_point: one of :data:`PRINCIPAL_POINT_MODES`.
    """
    layout = camera_layout(model, n_dist, principal_point, cam.image_size)
    fit = _solve(layout, layout.pack(cam), np.asarray(world, float), np.asarray(image, float))
    if fit is None:
        raise CalibrationError("the refinement did not converge to a camera in front of the points")
    return fit.camera(cam.image_size)


def camera_layout(model: str, n_dist: int, principal_point: str, size: tuple[int, int], noise_px: float = 1.0) -> CameraLayout:
    if model not in MODELS:
        raise ValueError(f"unknown camera model {model!r}; choose one of {MODELS}")
    if n_dist not in (0, 1, 2):
        raise ValueError("n_dist must be 0, 1 or 2")
    if principal_point not in PRINCIPAL_POINT_MODES:
        raise ValueError(f"unknown principal_point {principal_point!r}; choose one of {PRINCIPAL_POINT_MODES}")
    w, h = size
    weight = noise_px / (PP_SIGMA_FRAC * max(w, h)) if principal_point == "prior" else 0.0
    return CameraLayout(model, principal_point != "centre", n_dist, (w / 2, h / 2), weight)


# --------------------------------------------------------------------------------------- starts
def plane_starts(world: np.ndarray, image: np.ndarray, size: tuple[int, int],
                 plane: PlaneFrame | None = None) -> list[Camera]:
    """Square-pixel cameras with the principal point at the image centre that map ≥ 4 coplanar points
    close to their pixels: Zhang's closed-form focal length first, then a few fields of view."""
    plane = plane or fit_plane(world)
    uv = plane.to_plane(world)
    H = homography(uv, image)
    w, h = size
    pp = (w / 2, h / 2)
    focals = []
    f0 = focal_from_homography(H, pp, float(max(w, h)))
    if f0 is not None and 0.05 * w < f0 < 50 * w:
        focals.append(f0)
    focals += [0.5 * w / np.tan(np.radians(fov) / 2) for fov in FOV_STARTS_DEG]
    cams = []
    for f in focals:
        K = np.array([[f, 0, pp[0]], [0, f, pp[1]], [0, 0, 1.0]])
        R, t = pose_from_homography(H, K, plane, uv)
        cams.append(Camera.from_krt(K, R, t, size))
    return cams


def _dlt_starts(world: np.ndarray, image: np.ndarray, size: tuple[int, int]) -> list[Camera]:
    """The DLT camera as it comes, and with a square-pixel K and its principal point at the centre."""
    try:
        cam = Camera(P=dlt(world, image), image_size=size)
    except ValueError:
        return []
    w, h = size
    f = 0.5 * (abs(cam.K[0, 0]) + abs(cam.K[1, 1]))
    K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
    return [cam, Camera.from_krt(K, cam.R, cam.t, size)]


# ------------------------------------------------------------------------------------ diagnostics
def _suspects(res: np.ndarray, names: Sequence[str]) -> list[str]:
    """Points whose residual is well above the rest: > 3× the median and > 4 px."""
    if len(res) < MIN_POINTS + 1:
        return []
    med = float(np.median(res))
    return [n for n, r in zip(names, res) if r > max(3 * med, 4.0)]


def _uncertainty(fit: _Fit, size: tuple[int, int]) -> tuple[np.ndarray, float, np.ndarray]:
    """1-σ of the camera centre (3,) and of the focal length from the Gauss-Newton covariance, with the
    residual variance floored at :data:`NOISE_FLOOR_PX`², and the (7, 7) covariance of the pose parameters
    (:data:`inference.camera.POSE_PARAMETERS`: centre, rotation vector, focal; the lens distortion's own
    uncertainty is folded into them)."""
    J = fit.jac
    n_p = len(fit.p)
    dof = max(fit.n_data - n_p, 1)
    s2 = max(fit.cost / dof, NOISE_FLOOR_PX**2)
    cov = s2 * np.linalg.pinv(J.T @ J)
    eps = 1e-6 * np.maximum(np.abs(fit.p), 1.0)
    cam = fit.camera(size)
    Jq = np.zeros((7, n_p))
    for k in range(n_p):
        d = np.zeros(n_p)
        d[k] = eps[k]
        Jq[:, k] = (cam.pose_difference(fit.layout.camera(fit.p + d, size))
                    - cam.pose_difference(fit.layout.camera(fit.p - d, size))) / (2 * eps[k])
    cov_q = Jq @ cov @ Jq.T
    cov_q = 0.5 * (cov_q + cov_q.T)
    return np.sqrt(np.clip(np.diag(cov_q[:3, :3]), 0, None)), float(np.sqrt(max(cov_q[6, 6], 0.0))), cov_q


def _geometry_warnings(cam: Camera, image: np.ndarray, plane: PlaneFrame | None, n: int,
                       centre_sigma: np.ndarray, focal_sigma: float) -> list[str]:
    """Sentences about weak geometry: small image coverage, a plane seen head-on, few points, large σ."""
    import cv2

    out = []
    w, h = cam.image_size
    hull = cv2.convexHull(image.astype(np.float32))
    cover = float(cv2.contourArea(hull)) / (w * h)
    if cover < 0.10:
        out.append(f"the points cover only {100 * cover:.0f} % of the image: click points spread over the "
                   "whole court (far corners, both side lines)")
    if plane is not None:
        tilt = np.degrees(np.arccos(min(1.0, abs(float(cam.R[2] @ plane.basis[:, 2])))))
        if tilt < 20:
            out.append(f"the camera looks almost straight at the plane of the points ({tilt:.0f}° from its "
                       "normal): focal length and distance trade off; add points off that plane")
        if n < 8:
            out.append(f"only {n} points on one plane: a wrong click cannot be told apart; click more points")
    f = float(cam.K[0, 0])
    if np.isfinite(focal_sigma) and focal_sigma > 0.03 * f:
        out.append(f"the focal length is uncertain (± {100 * focal_sigma / f:.0f} %): spread the points "
                   "further, or add points off the floor (net-post tops, glass corners)")
    if np.isfinite(centre_sigma).all() and np.linalg.norm(centre_sigma) > 0.3:
        out.append(f"the camera position is uncertain (± {np.linalg.norm(centre_sigma):.2f} m): check the "
                   "clicks flagged above and add points")
    return out


# ------------------------------------------------------------------------------------------ calibrate
def calibrate(
    world: np.ndarray,
    image_px: np.ndarray,
    image_size: tuple[int, int],
    names: Sequence[str] | None = None,
    model: str = "square",
    n_dist: int = 0,
    suggest: Sequence[str] = (),
    principal_point: str = "prior",
    lines: LineClicks | None = None,
) -> CalibrationResult:
    """Calibrate a camera from ≥ 6 3D↔2D correspondences, all on one plane or not.

    Args:
        world: (N, 3) court-frame points, metres.
        image_px: (N, 2) their pixels.
        image_size: (W, H).
        names: (N,) point names for the report (default ``p0, p1, ...``).
        model: ``square`` or ``pinhole`` (see :func:`refine`; coplanar points always use ``square``).
        n_dist: radial distortion coefficients to fit (0–2; needs many well-spread points).
        suggest: point names to recommend when the input is degenerate.
        principal_point: one of :data:`PRINCIPAL_POINT_MODES` (coplanar points: always the centre).
        lines: pixels clicked along straight court lines (:class:`LineClicks`): each pulls the line, as the
            lens draws it, through its click — what pins the lens distortion of a wide-angle camera.
    Raises:
        CalibrationError: too few points, collinear points, non-finite input, or no fit converged.
    """
    world = np.asarray(world, dtype=float).reshape(-1, 3)
    image_px = np.asarray(image_px, dtype=float).reshape(-1, 2)
    names = list(names) if names is not None else [f"p{i}" for i in range(len(world))]
    if len(world) != len(image_px) or len(names) != len(world):
        raise ValueError(f"world {world.shape}, image {image_px.shape} and names ({len(names)}) differ")
    bad = [n for n, ok in zip(names, np.isfinite(world).all(1) & np.isfinite(image_px).all(1)) if not ok]
    if bad:
        raise CalibrationError(f"non-finite coordinates for points {bad}")
    hint = (" Click some of these points too: " + ", ".join(suggest[:8]) + ".") if suggest else ""
    if len(world) < MIN_POINTS:
        raise CalibrationError(f"{len(world)} court points given ({', '.join(names)}); at least {MIN_POINTS} "
                               f"are needed.{hint}")
    plane = fit_plane(world)
    if plane.spread_m < 0.5:
        raise CalibrationError(f"the {len(world)} court points ({', '.join(names)}) lie on one line, so the "
                               f"camera cannot be recovered.{hint}")
    size = (int(image_size[0]), int(image_size[1]))
    warnings: list[str] = []
    if plane.rms_m < COPLANAR_TOL_M:
        method = "plane"
        if model != "square":
            warnings.append(f"model {model!r} needs points off the plane; fitted square pixels instead")
        fit = _best_fit(camera_layout("square", n_dist, "centre", size), plane_starts(world, image_px, size, plane),
                        world, image_px, lines=lines)
    else:
        method, plane = "general", None
        starts = _dlt_starts(world, image_px, size)
        on_floor = np.abs(world[:, 2]) < COPLANAR_TOL_M
        if on_floor.sum() >= 4 and fit_plane(world[on_floor]).spread_m >= 0.5:
            starts += plane_starts(world[on_floor], image_px[on_floor], size)
        fit = _general_fit(model, n_dist, principal_point, size, starts, world, image_px, warnings, lines)
    if fit is None:
        raise CalibrationError(f"no camera fits the {len(world)} points: check that each name matches where it "
                               "was clicked")
    cam = fit.camera(size)
    res = np.linalg.norm(cam.project(world) - image_px, axis=1)
    rms = float(np.sqrt(np.mean(res**2)))
    residuals = dict(zip(names, res.tolist()))
    centre_sigma, focal_sigma, pose_cov = _uncertainty(fit, size)
    warnings += _geometry_warnings(cam, image_px, plane, len(world), centre_sigma, focal_sigma)
    if n_dist == 0 and rms > DISTORTION_HINT_RMS_PX:
        warnings.append(f"the points fit with an RMS of {rms:.1f} px, more than clicks miss by: a lens that bends "
                        "straight lines (wide angle) needs `--distortion 1` (or 2); if not, check the flagged "
                        "points — the camera's stated uncertainty holds only for a lens model that fits")
    if lines is not None and len(lines):
        off = lines.residuals(cam.project)
        far = off > LINE_CLICK_OFF_PX
        warnings += ([f"{int(far.sum())} of the {len(lines)} points along court lines lie off their line by more "
                      f"than {LINE_CLICK_OFF_PX:g} px (up to {off.max():.0f} px): check that each is on the line it "
                      "names (court_line_points.csv)"] if far.any() else [])
    cam.rms_px, cam.residuals_px, cam.source = rms, residuals, "calibrated"
    cam.meta.update(calibration_meta(method, centre_sigma, focal_sigma, warnings, pose_cov))
    return CalibrationResult(cam, names, residuals, rms, _suspects(res, names), method, centre_sigma,
                             focal_sigma, warnings)


def _best_fit(layout: CameraLayout, starts: Sequence[Camera], world: np.ndarray, image: np.ndarray,
              nfev_per_param: int = 400, lines: LineClicks | None = None) -> _Fit | None:
    """The lowest-cost refinement over the starts (None when none converges); with ``lines``, the best start
    on the named points alone is refined once more with them (they cost ~100 projections each)."""
    fits = [f for f in (_solve(layout, layout.pack(c), world, image, nfev_per_param) for c in starts)
            if f is not None]
    best = min(fits, key=lambda f: f.cost) if fits else None
    if best is None or lines is None or not len(lines):
        return best
    return _solve(layout, best.p, world, image, nfev_per_param, lines) or best


def coplanar_camera(world: np.ndarray, image_px: np.ndarray, image_size: tuple[int, int],
                    nfev_per_param: int = 400) -> Camera | None:
    """The camera of :func:`calibrate` for points on one plane, without its report (None when no start
    converges). ``nfev_per_param`` bounds each start's refinement: a caller that tries many guessed
    correspondences lowers it, since a start still wandering after ~50 evaluations per parameter is a
    wrong guess, not a slow right one."""
    world = np.asarray(world, dtype=float).reshape(-1, 3)
    image_px = np.asarray(image_px, dtype=float).reshape(-1, 2)
    size = (int(image_size[0]), int(image_size[1]))
    fit = _best_fit(camera_layout("square", 0, "centre", size),
                    plane_starts(world, image_px, size, fit_plane(world)), world, image_px, nfev_per_param)
    return None if fit is None else fit.camera(size)


def _general_fit(model: str, n_dist: int, principal_point: str, size: tuple[int, int], starts: list[Camera],
                 world: np.ndarray, image: np.ndarray, warnings: list[str],
                 lines: LineClicks | None = None) -> _Fit | None:
    """Points off the plane: the principal point at the centre, free, or free under the prior — and with the
    prior only when it explains the points clearly better (a BIC test for its two extra parameters) and
    stays within 4 σ of the centre."""
    if principal_point == "free":
        return _best_fit(camera_layout(model, n_dist, "free", size), starts, world, image, lines=lines)
    centred = _best_fit(camera_layout(model, n_dist, "centre", size), starts, world, image, lines=lines)
    if principal_point == "centre" or centred is None:
        return centred
    n_data = 2 * len(world) + (len(lines) if lines is not None else 0)
    sigma = max(np.sqrt(centred.cost / max(n_data - len(centred.p), 1)), NOISE_FLOOR_PX)
    layout = camera_layout(model, n_dist, "prior", size, noise_px=sigma)
    c = centred.camera(size)
    free = _best_fit(layout, [c, *starts], world, image, lines=lines)
    if free is None:
        return centred
    data_cost = float(np.sum(free.layout.residuals(free.p, world, image, lines)[:n_data] ** 2))
    s2 = max(data_cost / max(n_data - len(free.p), 1), NOISE_FLOOR_PX**2)
    if (centred.cost - data_cost) / s2 < 2 * np.log(n_data):
        return centred
    K = layout.unpack(free.p)[0]
    if np.any(np.abs(K[:2, 2] - np.asarray(size) / 2) > 4 * PP_SIGMA_FRAC * max(size)):
        warnings.append("the off-plane points pull the principal point far from the image centre; it was kept "
                        "at the centre (check the off-plane clicks)")
        return centred
    return free


def calibration_meta(method: str, centre_sigma: np.ndarray, focal_sigma: float, warnings: Sequence[str],
                     pose_cov: np.ndarray | None = None) -> dict:
    """The camera.yaml keys that describe a calibration's quality (docs/formats.md §11); ``pose_cov``: the
    (7, 7) covariance of the pose (:data:`inference.camera.POSE_PARAMETERS`), which the 3D reconstruction adds
    to its own uncertainty."""
    out = {"method": method, "centre_sigma_m": [round(float(v), 4) for v in centre_sigma],
           "focal_sigma_px": round(float(focal_sigma), 2), "warnings": list(warnings)}
    if pose_cov is not None and np.all(np.isfinite(pose_cov)):
        out["pose_cov"] = [[float(f"{v:.9g}") for v in row] for row in np.asarray(pose_cov, float)]
    return out


def calibrate_court(
    court: Court,
    image_points: Mapping[str, Sequence[float]],
    image_size: tuple[int, int],
    model: str = "square",
    n_dist: int = 0,
    principal_point: str = "prior",
    line_points: Sequence[tuple[str, str, Sequence[float]]] = (),
) -> CalibrationResult:
    """Calibrate from clicked named points of ``court`` (floor points alone suffice).

    Args:
        court: the court model whose named points were clicked.
        image_points: point name → (x, y) pixels.
        image_size: (W, H).
        line_points: ``(start, end, (x, y) pixels)``: a pixel clicked anywhere on the straight court line
            from the named point ``start`` to ``end`` (``court_line_points.csv``); several along a side line
            bent by a wide-angle lens give its distortion (with ``n_dist`` ≥ 1).
    Raises:
        KeyError: a name is not a point of the court (the message lists the valid names).
        CalibrationError: degenerate input; the message names points to add.
    """
    names = list(image_points)
    world = court.point_array(names)
    image = np.array([image_points[n] for n in names], dtype=float).reshape(-1, 2)
    off = court.off_ground_points()
    suggest = [n for n in off if n not in image_points] + [n for n in court.point_names
                                                           if n not in image_points and n not in off]
    lines = None
    if len(line_points):
        lines = LineClicks(court.point_array([a for a, _, _ in line_points]),
                           court.point_array([b for _, b, _ in line_points]),
                           np.array([xy for _, _, xy in line_points], dtype=float).reshape(-1, 2))
    return calibrate(world, image, image_size, names=names, model=model, n_dist=n_dist, suggest=suggest,
                     principal_point=principal_point, lines=lines)


def court_view_problems(camera: Camera, court: Court) -> list[str]:
    """What makes ``camera`` unusable for ``court`` ([] when none): the court behind the camera, no part of
    the court's floor inside the picture, a focal length no lens has, a camera under the floor.

    The floor is sampled on a 1 m grid over the playing area; a camera that sees none of it cannot place
    a ball or a player, whatever its residuals say.
    """
    w, h = (int(v) for v in camera.image_size)
    problems = []
    f = float(camera.K[0, 0])
    if not (0.1 * max(w, h) <= abs(f) <= 50.0 * max(w, h)):
        problems.append(f"its focal length is {f:.3g} px, which no lens gives on {w}×{h} frames "
                        f"(expected {0.1 * max(w, h):.0f}–{50 * max(w, h):.0f} px)")
    if camera.centre[2] <= 0:
        problems.append(f"it stands {camera.centre[2]:.2f} m high (under the floor: clicked points that are "
                        "mirrored — left and right, or near and far, swapped — put the camera there)")
    xs = np.linspace(0, court.size[0], max(2, int(np.ceil(court.size[0])) + 1))
    ys = np.linspace(0, court.size[1], max(2, int(np.ceil(court.size[1])) + 1))
    floor = np.array([(x, y, 0.0) for x in xs for y in ys])
    front = camera.depth(floor) > 0
    if not front.any():
        problems.append("the court is behind it (the camera looks away from the court)")
    else:
        px = camera.project(floor[front])
        inside = np.isfinite(px).all(1) & (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        if not inside.any():
            problems.append("no part of the court's floor falls inside the picture")
    return problems


def require_court_view(camera: Camera, court: Court, path) -> None:
    """Raise :class:`~inference.clipio.errors.FormatError` naming ``path`` when ``camera`` cannot see
    ``court`` (:func:`court_view_problems`)."""
    problems = court_view_problems(camera, court)
    if problems:
        from inference.clipio.errors import FormatError

        raise FormatError(path, "this camera cannot see the court: " + "; ".join(problems),
                          fix="check that the file belongs to this video, or calibrate again (rally3d calibrate "
                          "from clicked court points, or --court-points auto)")
