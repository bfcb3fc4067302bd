"""A calibrated pinhole camera: projection, back-projection to lines of sight, camera.yaml I/O.

Conventions: ``P = K [R | t]`` maps homogeneous court-frame points (metres) to pixels; a camera-frame
point is ``R X + t`` with z forward; the camera centre is ``C = -Rᵀ t``. Optional lens distortion uses
OpenCV's ``(k1, k2, p1, p2, k3)`` model applied to normalised camera coordinates; ``P`` then maps to
*undistorted* pixels.

Example:
    >>> cam = Camera.from_look_at(eye=[5, -3, 6], target=[5, 10, 0], image_size=(1280, 720), fov_deg=70)
    >>> px = cam.project([[5, 10, 0]])           # (1, 2) pixels, the image centre
    >>> origin, direction = cam.rays(px)          # (1, 3), (1, 3) unit
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from inference.clipio.atomic import atomic_write_text
from inference.clipio.errors import FormatError
from inference.clipio.structured import load_yaml


def decompose_projection(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a 3×4 projection matrix into ``K`` (upper triangular, positive diagonal, K[2,2] = 1),
    a rotation ``R`` (det +1) and ``t`` with ``P ∝ K [R | t]``.

    The sign of P is chosen so that points in front of the camera have positive depth.
    """
    P = np.asarray(P, dtype=float)
    M = P[:, :3]
    if not np.all(np.isfinite(M)) or abs(np.linalg.det(M)) <= 1e-12 * np.linalg.norm(M) ** 3:
        raise ValueError("degenerate projection matrix: its left 3×3 block is singular")
    import scipy.linalg  # here, not at the top: `rally3d --help` must not load scipy

    K, R = scipy.linalg.rq(M)
    S = np.diag(np.sign(np.diag(K)))
    K, R = K @ S, S @ R
    scale = K[2, 2]
    P = P / scale
    K = K / scale
    if np.linalg.det(R) < 0:  # P was defined up to sign: -P gives the proper rotation
        R = -R
        P = -P
    t = np.linalg.solve(K, P[:, 3])
    return K, R, t


def rotation_look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World→camera rotation (rows: camera x right, y down, z forward) looking from eye to target."""
    eye, target, up = (np.asarray(a, dtype=float) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look-at direction is parallel to the up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


@dataclass
class Camera:
    """A calibrated camera.

    Attributes:
        P: (3, 4) projection matrix in pixels.
        image_size: (W, H) in pixels.
        K: (3, 3) intrinsics; R: (3, 3) world→camera rotation; t: (3,) translation.
            Derived from P when not given.
        dist: (5,) OpenCV distortion ``k1, k2, p1, p2, k3`` or None.
        rms_px: reprojection RMS of the calibration, pixels (None for ground truth).
        residuals_px: point name → reprojection error in pixels.
        source: ``calibrated``, ``auto`` (found by the automatic court fit), ``ground_truth`` ... free text.
        meta: further camera.yaml keys, kept on a round trip: ``method``, ``centre_sigma_m``,
            ``focal_sigma_px``, ``warnings`` (from the calibration) and ``auto`` (the automatic fit's
            confidence and residuals); see docs/formats.md §11.
    """

    P: np.ndarray
    image_size: tuple[int, int]
    K: np.ndarray | None = None
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    dist: np.ndarray | None = None
    rms_px: float | None = None
    residuals_px: dict[str, float] = field(default_factory=dict)
    source: str = "calibrated"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.P = np.asarray(self.P, dtype=float)
        if self.P.shape != (3, 4) or not np.all(np.isfinite(self.P)):
            raise ValueError(f"P must be a finite (3, 4) matrix, got shape {self.P.shape}")
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ValueError(f"image_size must be positive (W, H), got {self.image_size}")
        self.image_size = (w, h)
        if self.K is None or self.R is None or self.t is None:
            self.K, self.R, self.t = decompose_projection(self.P)
            self.P = self.K @ np.hstack([self.R, self.t[:, None]])
        self.K, self.R, self.t = (np.asarray(a, dtype=float) for a in (self.K, self.R, self.t))
        if self.dist is not None:
            d = np.zeros(5)
            given = np.asarray(self.dist, dtype=float).ravel()
            if len(given) > 5 or not np.all(np.isfinite(given)):
                raise ValueError("dist must be up to 5 finite numbers (k1, k2, p1, p2, k3)")
            d[: len(given)] = given
            self.dist = None if not np.any(d) else d

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def from_krt(cls, K, R, t, image_size, dist=None, **kw) -> Camera:
        K, R, t = (np.asarray(a, dtype=float) for a in (K, R, t))
        P = K @ np.hstack([R, t.reshape(3, 1)])
        return cls(P=P, image_size=image_size, K=K, R=R, t=t.reshape(3), dist=dist, **kw)

    @classmethod
    def from_look_at(cls, eye, target, image_size, fov_deg: float = 60.0, dist=None, **kw) -> Camera:
        """A square-pixel camera at ``eye`` looking at ``target`` with horizontal field of view."""
        w, h = image_size
        f = 0.5 * w / np.tan(np.radians(fov_deg) / 2)
        K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
        R = rotation_look_at(np.asarray(eye, float), np.asarray(target, float))
        t = -R @ np.asarray(eye, dtype=float)
        return cls.from_krt(K, R, t, image_size, dist=dist, **kw)

    # --- geometry -----------------------------------------------------------------------------
    @property
    def centre(self) -> np.ndarray:
        """(3,) camera centre in court coordinates."""
        return -self.R.T @ self.t

    def depth(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N,) depth along the optical axis (positive = in front)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return X @ self.R[2] + self.t[2]

    def project(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) court-frame points → (N, 2) pixels; NaN for points behind the camera."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        Xc = X @ self.R.T + self.t
        z = Xc[:, 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = Xc[:, :2] / z
        if self.dist is not None:
            xn = distort_normalized(xn, self.dist)
        px = xn @ self.K[:2, :2].T + self.K[:2, 2]
        px[(z[:, 0] <= 0)] = np.nan
        return px

    def project_normalized(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) points → (N, 2) normalised image coordinates u = x/W, v = y/H."""
        return self.project(X) / np.asarray(self.image_size, dtype=float)

    def rays(self, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) pixels → lines of sight: origins (N, 3) (the camera centre) and unit directions (N, 3)."""
        px = np.atleast_2d(np.asarray(px, dtype=float))
        xn = (px - self.K[:2, 2]) @ np.linalg.inv(self.K[:2, :2]).T
        if self.dist is not None:
            xn = undistort_normalized(xn, self.dist)
        d_cam = np.hstack([xn, np.ones((len(xn), 1))])
        d = d_cam @ self.R  # R^T d_cam, row-wise
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.centre, d.shape).copy(), d

    def rays_normalized(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`rays` for normalised image coordinates."""
        return self.rays(np.atleast_2d(uv) * np.asarray(self.image_size, dtype=float))

    # --- pose uncertainty -----------------------------------------------------------------------
    def perturbed(self, dq: np.ndarray) -> Camera:
        """The camera moved by ``dq`` (7,) in the parameters of :data:`POSE_PARAMETERS`: its centre by
        ``dq[:3]`` m, its orientation by the rotation vector ``dq[3:6]`` rad (about the court axes: R' = R
        exp([dq[3:6]]×)), its focal length by ``dq[6]`` px (both axes, in proportion); distortion kept."""
        dq = np.asarray(dq, dtype=float).reshape(7)
        R = self.R @ _rodrigues(dq[3:6])
        K = self.K.copy()
        K[:2, :2] *= (K[0, 0] + dq[6]) / K[0, 0]
        return Camera.from_krt(K, R, -R @ (self.centre + dq[:3]), self.image_size, dist=self.dist)

    def pose_difference(self, other: Camera) -> np.ndarray:
        """(7,) the ``dq`` with ``self.perturbed(dq)`` ≈ ``other`` (small differences)."""
        W = self.R.T @ other.R                                      # exp([w]×)
        w = 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])   # small-angle log
        return np.concatenate([other.centre - self.centre, w, [other.K[0, 0] - self.K[0, 0]]])

    def pose_covariance(self) -> np.ndarray | None:
        """(7, 7) covariance of the calibration over :data:`POSE_PARAMETERS` (camera.yaml ``pose_cov``; made
        symmetric, negative eigenvalues from rounding set to 0), or None when the camera has none (ground
        truth, an automatic fit, an older file) or it is not a finite 7×7 matrix."""
        c = self.meta.get("pose_cov")
        if c is None:
            return None
        try:
            c = np.asarray(c, dtype=float)
        except (TypeError, ValueError):
            return None
        if c.shape != (7, 7) or not np.all(np.isfinite(c)):
            return None
        w, V = np.linalg.eigh(0.5 * (c + c.T))
        return (V * np.maximum(w, 0.0)) @ V.T

    # --- camera.yaml ----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = {
            "image_size": list(self.image_size),
            "P": self.P.tolist(),
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "centre": self.centre.tolist(),
            "dist": None if self.dist is None else self.dist.tolist(),
            "source": self.source,
        }
        if self.rms_px is not None:
            d["rms_px"] = float(self.rms_px)
        if self.residuals_px:
            d["points_used"] = list(self.residuals_px)
            d["residuals_px"] = {k: round(float(v), 4) for k, v in self.residuals_px.items()}
        d.update({k: v for k, v in self.meta.items() if k not in d})
        return d

    def save(self, path: str | Path) -> Path:
        """Write camera.yaml atomically."""
        text = "# rally3d camera: P = K [R | t] maps court-frame metres to pixels\n"
        text += yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None)
        return atomic_write_text(path, text)

    @classmethod
    def load(cls, path: str | Path) -> Camera:
        """Read camera.yaml; malformed files raise FormatError naming the key and the fix."""
        path = Path(path)
        if not path.is_file():
            raise FormatError(path, "camera file not found", fix="run `rally3d calibrate <clip>` first")
        d = load_yaml(path, fix="re-run `rally3d calibrate <clip>`")
        if not isinstance(d, dict) or "P" not in d or "image_size" not in d:
            raise FormatError(path, "needs the keys `image_size: [W, H]` and `P` (3×4)")
        try:
            K = d.get("K")
            R = d.get("R")
            t = d.get("t")
            krt = {} if K is None or R is None or t is None else {"K": K, "R": R, "t": t}
            return cls(
                P=np.asarray(d["P"], dtype=float),
                image_size=tuple(d["image_size"]),
                dist=d.get("dist"),
                rms_px=d.get("rms_px"),
                residuals_px=dict(d.get("residuals_px") or {}),
                source=str(d.get("source", "calibrated")),
                meta={k: v for k, v in d.items() if k not in _CAMERA_KEYS},
                **krt,
            )
        except (TypeError, ValueError) as e:
            raise FormatError(path, f"invalid camera: {e}", fix="re-run `rally3d calibrate <clip>`") from None


#: the parameters of a camera's pose uncertainty (:meth:`Camera.perturbed`, camera.yaml ``pose_cov``)
POSE_PARAMETERS = ("centre_x_m", "centre_y_m", "centre_z_m", "rotation_x_rad", "rotation_y_rad", "rotation_z_rad",
                   "focal_px")


def _rodrigues(w: np.ndarray) -> np.ndarray:
    """(3, 3) exp([w]×): the rotation by the rotation vector ``w`` (3,) rad."""
    a = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if a < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(a) / a * k + (1.0 - np.cos(a)) / a**2 * (k @ k)


_CAMERA_KEYS = {"image_size", "P", "K", "R", "t", "centre", "dist", "source", "rms_px", "points_used",
                "residuals_px"}


def distort_normalized(xn: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Apply OpenCV's radial-tangential model to (N, 2) normalised camera coordinates."""
    k1, k2, p1, p2, k3 = dist
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=1)


def undistort_normalized(xd: np.ndarray, dist: np.ndarray, iterations: int = 100, tol: float = 1e-14) -> np.ndarray:
    """Invert :func:`distort_normalized` for (N, 2) points by fixed-point iteration."""
    k1, k2, p1, p2, k3 = dist
    x = xd.copy()
    for _ in range(iterations):
        u, v = x[:, 0], x[:, 1]
        r2 = u * u + v * v
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        dx = 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
        dy = p1 * (r2 + 2 * v * v) + 2 * p2 * u * v
        new = np.stack([(xd[:, 0] - dx) / radial, (xd[:, 1] - dy) / radial], axis=1)
        done = np.nanmax(np.abs(new - x), initial=0.0) < tol
        x = new
        if done:
            break
    return x
