"""Cameras for synthetic clips: presets for the common views and their randomisation.

Presets:
    ``padel_installed`` — the usual fixed padel camera, behind and above the near back glass.
    ``tennis_broadcast`` — the broadcast view from high behind the near baseline.
    ``padel_broadcast`` — a broadcast padel view: high (8 m) and well behind the near glass (8 m), the whole
    court in view (render it at 1080p with ``SynthConfig(width=1920, height=1080)`` or ``--size 1920x1080``).
    ``tennis_high`` — a higher, farther tennis view (14 m up, 18 m behind the baseline).
    ``padel_tv`` — a tour event's main padel camera: 7.5 m high and 13.5 m behind the near glass, a longer
    lens, the court in the upper part of the picture (an advertising board and a score box around it: render
    it with ``SynthConfig(venue="tour")``).
    ``tennis_tv`` — a tour event's main tennis camera: a long lens 18–40 m behind the near baseline and 8–14 m
    high (randomised over that range), the court with its run-off in view (about 4 m behind each baseline,
    1 m beside the doubles lines). Broadcast tennis is filmed so: the three real 1080p ATP broadcasts the
    project was checked on calibrate to 18–37 m behind and 8–10 m high, and on a real final's tracks the
    far players' hits sit at a quarter of the picture's height and the near ones at 0.7 (the close
    ``tennis_broadcast`` puts them at 0.21 and 0.81, and shows the far end 2.7 times smaller beside the
    near one than such a lens does).

Example:
    >>> spec = CameraSpec.preset("padel_installed").randomised(np.random.default_rng(0))
    >>> cam = spec.build(load_court("padel"))       # an inference.camera.Camera, fov fitted to the court
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from inference.camera import Camera, rotation_look_at
from inference.court import Court

FPS_CHOICES = (25.0, 30.0, 50.0, 60.0)
RESOLUTIONS = ((1280, 720), (1920, 1080), (960, 540))


@dataclass(frozen=True)
class CameraSpec:
    """A camera to render with.

    Attributes:
        width, height: image size in pixels; fps: frame rate.
        eye: (3,) camera centre in court metres; target: (3,) the point it looks at.
        fov_deg: horizontal field of view; None fits it so the court fills the image with ``margin``.
        roll_deg: rotation about the optical axis.
        dist: OpenCV ``(k1, k2, p1, p2, k3)`` lens distortion, or None.
        margin: fraction of the image kept free around the court when ``fov_deg`` is None.
        near_y: the fitted view keeps the floor from this y (m) on; installed padel cameras right behind
            the glass usually cut the near corners.
        run_off: ``(near, far, beside)`` metres of floor kept in view behind the near and the far baseline and
            beside each side line when ``fov_deg`` is None (a broadcast shows where the players stand);
            zeros: the lines.
        eye_spread: ``(x, y, z)`` half-ranges (m) of the eye's randomisation (:meth:`randomised`), instead of
            its ``jitter_m``: a preset that stands for a range of real camera positions; target_spread: ``(x, y)``
            half-ranges (m) of the aim's.
        elevation_deg: ``(lo, hi)``: :meth:`randomised` sets the eye's height from its horizontal distance to the
            target and an angle of depression drawn in this range (a camera farther back stands higher).
    """

    width: int = 1280
    height: int = 720
    fps: float = 30.0
    eye: tuple[float, float, float] = (5.0, -3.0, 6.0)
    target: tuple[float, float, float] = (5.0, 9.0, 0.0)
    fov_deg: float | None = None
    roll_deg: float = 0.0
    dist: tuple[float, ...] | None = None
    margin: float = 0.04
    near_y: float = 0.0
    run_off: tuple[float, float, float] = (0.0, 0.0, 0.0)
    eye_spread: tuple[float, float, float] | None = None
    target_spread: tuple[float, float] | None = None
    elevation_deg: tuple[float, float] | None = None

    @staticmethod
    def preset(name: str) -> CameraSpec:
        """A named preset (see the module docstring)."""
        presets = {
            "padel_installed": CameraSpec(eye=(5.0, -3.0, 6.0), target=(5.0, 9.5, 0.0), near_y=2.5),
            "tennis_broadcast": CameraSpec(eye=(5.485, -14.0, 9.0), target=(5.485, 10.5, 0.0), margin=0.08),
            "padel_broadcast": CameraSpec(eye=(5.0, -8.0, 8.0), target=(5.0, 9.0, 0.0), margin=0.05),
            "tennis_high": CameraSpec(eye=(5.485, -18.0, 14.0), target=(5.485, 11.0, 0.0), margin=0.06),
            "padel_tv": CameraSpec(eye=(5.0, -13.5, 7.5), target=(5.0, 8.0, 0.0), margin=0.06),
            "tennis_tv": CameraSpec(width=1920, height=1080, eye=(5.485, -29.0, 11.0), target=(5.485, 11.5, 0.0),
                                    margin=0.03, run_off=(2.5, 5.0, 1.0), eye_spread=(1.5, 11.0, 0.0),
                                    target_spread=(0.5, 2.5), elevation_deg=(10.0, 19.0)),
        }
        if name not in presets:
            raise KeyError(f"unknown camera preset {name!r}; presets: {sorted(presets)}")
        return presets[name]

    def randomised(self, rng: np.random.Generator, jitter_m: float = 0.6, distortion: bool = True) -> CameraSpec:
        """A random variation: position/aim jitter (``eye_spread`` where the preset has one), roll, resolution,
        fps and mild lens distortion; a run-off in view varies by ±1 m behind the baselines and ±0.5 m beside."""
        spread = np.array([jitter_m * 1.5, jitter_m, jitter_m]) if self.eye_spread is None else np.asarray(self.eye_spread)
        eye = np.asarray(self.eye) + rng.uniform(-1, 1, 3) * spread
        aim = np.array([0.5, 1.0, 0.0]) * jitter_m if self.target_spread is None else np.append(self.target_spread, 0.0)
        target = np.asarray(self.target) + rng.uniform(-1, 1, 3) * aim
        if self.elevation_deg is not None:
            eye[2] = target[2] + np.hypot(*(eye[:2] - target[:2])) * np.tan(np.radians(rng.uniform(*self.elevation_deg)))
        width, height = RESOLUTIONS[rng.integers(len(RESOLUTIONS))]
        dist = None
        if distortion and rng.random() < 0.5:
            dist = (float(rng.uniform(-0.18, 0.03)), float(rng.uniform(-0.02, 0.04)), 0.0, 0.0, 0.0)
        run_off = self.run_off
        if any(run_off):
            run_off = tuple(max(0.0, v + float(rng.uniform(-d, d))) for v, d in zip(run_off, (1.0, 1.0, 0.5)))
        return replace(self, eye=tuple(eye), target=tuple(target), width=int(width), height=int(height),
                       fps=float(FPS_CHOICES[rng.integers(len(FPS_CHOICES))]),
                       roll_deg=float(rng.uniform(-2.0, 2.0)), dist=dist,
                       margin=float(rng.uniform(0.02, 0.10)), run_off=run_off)

    def to_dict(self) -> dict:
        """The fields as a mapping (``clip.yaml``'s ``synth.camera``); the run-off and the spreads only when set, so
        a camera without them is written as before they existed."""
        d = asdict(self)
        for k, empty in (("run_off", (0.0, 0.0, 0.0)), ("eye_spread", None), ("target_spread", None),
                         ("elevation_deg", None)):
            if d[k] == empty or (empty is not None and tuple(d[k]) == empty):
                d.pop(k)
        return d

    def rotation(self) -> np.ndarray:
        """World→camera rotation including roll."""
        R = rotation_look_at(np.asarray(self.eye, float), np.asarray(self.target, float))
        a = np.radians(self.roll_deg)
        roll = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
        return roll @ R

    def build(self, court: Court) -> Camera:
        """The :class:`Camera`; with ``fov_deg`` None the focal length is fitted to the court."""
        R = self.rotation()
        eye = np.asarray(self.eye, dtype=float)
        t = -R @ eye
        w, h = self.width, self.height
        if self.fov_deg is not None:
            f = 0.5 * w / np.tan(np.radians(self.fov_deg) / 2)
        else:
            f = fit_focal(court, R, t, (w, h), self.margin, self.near_y, self.run_off)
        K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
        return Camera.from_krt(K, R, t, (w, h), dist=self.dist, source="ground_truth")


def court_extent_points(court: Court, near_y: float = 0.0,
                        run_off: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """(M, 3) points that should be in view: the floor from ``near_y`` on (and ``run_off`` = (near, far,
    beside) metres around the lines) and the far wall tops."""
    sx, sy = court.size
    bn, bf, s = (float(v) for v in run_off)
    pts = [[-s, near_y - bn, 0], [sx + s, near_y - bn, 0], [-s, sy + bf, 0], [sx + s, sy + bf, 0]]
    far_tops = [p for n, p in court.points.items() if p[1] >= sy - 1e-6 and p[2] > 0]
    return np.array(pts + [list(p) for p in far_tops], dtype=float)


def fit_focal(court: Court, R: np.ndarray, t: np.ndarray, size: tuple[int, int], margin: float,
              near_y: float = 0.0, run_off: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> float:
    """The largest focal length (px) that keeps the court's extent points inside the image margins."""
    w, h = size
    Xc = court_extent_points(court, near_y, run_off) @ R.T + t
    if np.any(Xc[:, 2] <= 0.1):
        raise ValueError("the court is behind the camera: check eye/target")
    xn, yn = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    half_w, half_h = (0.5 - margin) * w, (0.5 - margin) * h
    fx = half_w / max(np.abs(xn).max(), 1e-9)
    fy = half_h / max(np.abs(yn).max(), 1e-9)
    return float(min(fx, fy))
