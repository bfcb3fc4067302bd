"""OpenCV renderer of synthetic rally frames (CPU only).

Per clip, :class:`CourtRenderer` ray-casts the static scene once, with analytic anti-aliasing: the floor
with its texture and painted lines, the venue around it, the padel glass (faint tint, Fresnel, panel
joints), the wire mesh, the net with its tape, and the metal frames. The result is a background image.
Every see-through panel is also kept as a cropped RGBA overlay.

Per frame it draws only what moves:

1. shadows darken the floor (players, the ball, stationary balls);
2. one depth-sorted pass, far to near, draws player capsules, rackets, the ball, its reflections in the
   glass and stationary balls. The ball is a disc swept over the exposure, so a fast ball is a streak.
   An object seen through a panel (a far player behind the net, a ball behind the near glass) gets that
   panel's overlay composited over its own pixels;
3. sensor noise is added from shifted, pre-generated tiles, followed by an optional JPEG round trip.

Grading (gain, gamma, colour cast, vignetting) is baked into the background and applied to each moving
object's colour, so no full-frame grading is left per frame.

Pixel ``(x, y)`` is the centre of column x, row y, as for :meth:`Camera.project` and cv2 drawing.

Example:
    >>> from inference.court import load_court
    >>> cam = Camera.from_look_at([5, -3, 6], [5, 9, 0], (1280, 720), fov_deg=80)
    >>> r = CourtRenderer(load_court("padel"), cam, Appearance.sample(np.random.default_rng(0)))
    >>> img, info = r.render(0, np.array([[5.0, 6.0, 1.0]]), poses=[], inactive_balls=[])
    >>> img.shape, info.ball.visibility
    ((720, 1280, 3), 1)
"""
from __future__ import annotations

import colorsys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import ClassVar

import cv2
import numpy as np

from inference.camera import Camera
from inference.court import Court, Plane, points_in_polygon
from synth.bodies import CAPSULE_MATERIALS, PlayerPose, capsules
from synth.types import BallPath, InactiveBall

Colour = tuple[int, int, int]
UP = np.array([0.0, 0.0, 1.0])
NEAR = 0.05  # m, near clipping distance
#: visibility 2 ("hard to see"): a ball under this projected radius (px) ...
HARD_RADIUS_PX = 1.0
#: ... or whose colour, diluted by its motion blur, differs from the background by less than this (RGB).
HARD_CONTRAST = 25.0
#: a ball behind structure (mesh wires, frame posts, net) this opaque (0–1) at its centre is occluded (3) ...
HIDDEN_COVER = 0.85
#: ... or hard to see (2) above this.
HARD_COVER = 0.5
SHIFT = 4  # cv2 sub-pixel bits
ONE = 1 << SHIFT
#: Drawing order bias (m) per material: clothes win over skin at equal depth.
MATERIAL_BIAS = {"shirt": 0.03, "shorts": 0.03, "hair": 0.0, "skin": 0.0, "shoes": 0.0}


# ======================================================================================================
# Appearance
# ======================================================================================================
def _jitter(rng: np.random.Generator, base: Sequence[int], spread: int) -> Colour:
    c = np.clip(np.asarray(base) + rng.integers(-spread, spread + 1, 3), 0, 255)
    return tuple(int(v) for v in c)


def _hsv(rng: np.random.Generator, h: tuple, s: tuple, v: tuple) -> Colour:
    rgb = colorsys.hsv_to_rgb(rng.uniform(*h) % 1.0, rng.uniform(*s), rng.uniform(*v))
    return tuple(round(255 * c) for c in rgb)


SKIN_TONES = ((255, 219, 172), (241, 194, 125), (224, 172, 105), (198, 134, 66), (141, 85, 36), (92, 58, 36))
HAIR = ((20, 16, 14), (60, 40, 25), (110, 75, 40), (200, 170, 110), (140, 140, 140))
PADEL_FLOORS = ((38, 92, 168), (48, 118, 72), (176, 88, 58), (40, 70, 130))
TENNIS_FLOORS = {  # court, surround, grass stripes
    "hard": ((42, 86, 150), (62, 118, 86), 0.0),
    "clay": ((186, 98, 62), (176, 92, 58), 0.0),
    "grass": ((78, 138, 60), (70, 125, 55), 0.05),
}


@dataclass(frozen=True)
class PlayerLook:
    """A player's colours (RGB)."""

    shirt: Colour = (200, 40, 40)
    shorts: Colour = (30, 30, 40)
    skin: Colour = (224, 172, 105)
    hair: Colour = (60, 40, 25)
    shoes: Colour = (235, 235, 235)
    racket: Colour = (30, 30, 30)
    grip: Colour = (20, 20, 20)

    @classmethod
    def sample(cls, rng: np.random.Generator, shirt: Colour | None = None) -> PlayerLook:
        return cls(
            shirt=shirt or _hsv(rng, (0, 1), (0.0, 0.9), (0.25, 1.0)),
            shorts=_hsv(rng, (0, 1), (0.0, 0.6), (0.08, 0.9)),
            skin=_jitter(rng, SKIN_TONES[rng.integers(len(SKIN_TONES))], 10),
            hair=HAIR[rng.integers(len(HAIR))],
            shoes=_hsv(rng, (0, 1), (0.0, 0.3), (0.5, 1.0)),
            racket=_hsv(rng, (0, 1), (0.2, 1.0), (0.1, 0.95)),
            grip=_hsv(rng, (0, 1), (0.0, 0.3), (0.05, 0.95)),
        )


def _default_looks() -> tuple[PlayerLook, ...]:
    return (PlayerLook((200, 40, 40)), PlayerLook((40, 60, 200)), PlayerLook((240, 240, 240)),
            PlayerLook((250, 140, 20)))


@dataclass(frozen=True)
class Appearance:
    """Everything about how a clip looks. The defaults are a clean test look (no noise, no JPEG, neutral
    grading); :meth:`sample` draws a random one.

    Colours are RGB. ``gain``, ``cast`` multiply linear intensities, ``gamma`` is the exponent on
    normalised intensities (> 1 darkens), ``vignette`` is the darkening at the corners (0-1),
    ``noise_sigma`` the sensor noise (grey levels), ``jpeg_quality`` None for no JPEG round trip,
    ``shutter`` the exposure as a fraction of the frame period, ``light_dir`` the direction the light
    travels (z < 0), ``reflection_strength`` the opacity of the ball's glass reflections (0 = none),
    ``glass_joints`` the opacity of the joints between glass panels (every 2 m).

    A tour event as broadcast (:meth:`tour`; the defaults leave every other look as it was):
    ``perimeter_paint`` False leaves the court's outline unpainted (the walls bound it); ``glass_base`` the
    colour of the profile under every glass panel, a band ``glass_base_width`` m wide on the floor just
    outside the court; ``posts`` frame posts every 2 m along the mesh panels; ``floor_logos`` text painted
    on the floor, ``(text, x0, y0, x1, y1)`` in court metres, in ``logo`` at opacity ``logo_alpha``;
    ``scoreboard`` a score box keyed into the picture, ``(x0, y0, x1, y1)`` normalised; ``near_board``
    ``(y, height)`` m of an advertising board across the view between the camera and the near glass
    (``board`` colour), which can hide the near baseline; ``tour_seed`` draws their text.
    """

    sport: str = "padel"
    floor: Colour = (38, 92, 168)
    surround: Colour = (70, 74, 80)
    line: Colour = (240, 240, 236)
    stripes: float = 0.0
    floor_texture: float = 0.0
    wall: Colour = (40, 44, 52)
    banners: tuple[Colour, ...] = ((200, 40, 40), (30, 60, 150), (230, 230, 230), (20, 20, 20))
    sky: Colour = (60, 62, 70)
    indoor: bool = True
    glass_tint: Colour = (165, 200, 205)
    glass_alpha: float = 0.07
    frame: Colour = (30, 30, 34)
    mesh: Colour = (25, 25, 28)
    mesh_alpha: float = 0.9
    net: Colour = (30, 30, 30)
    net_tape: Colour = (238, 238, 238)
    gain: float = 1.0
    gamma: float = 1.0
    cast: tuple[float, float, float] = (1.0, 1.0, 1.0)
    vignette: float = 0.0
    players: tuple[PlayerLook, ...] = field(default_factory=_default_looks)
    ball: Colour = (214, 232, 62)
    ball_shading: float = 0.0
    noise_sigma: float = 0.0
    jpeg_quality: int | None = None
    shutter: float = 0.5
    light_dir: tuple[float, float, float] = (0.15, 0.25, -1.0)
    shadow_strength: float = 0.45
    reflection_strength: float = 0.35
    lens_blur: float = 0.0
    texture_seed: int = 0
    glass_joints: float = 0.8
    # a tour event as broadcast (all off by default; :meth:`tour` turns them on)
    perimeter_paint: bool = True
    glass_base: Colour | None = None
    glass_base_width: float = 0.15
    posts: bool = False
    floor_logos: tuple[tuple[str, float, float, float, float], ...] = ()
    logo: Colour = (236, 236, 236)
    logo_alpha: float = 0.0
    scoreboard: tuple[float, float, float, float] | None = None
    near_board: tuple[float, float] | None = None
    board: Colour = (22, 26, 44)
    tour_seed: int = 0

    @classmethod
    def plain(cls, sport: str = "padel") -> Appearance:
        """The clean test look for ``sport``."""
        if sport == "tennis":
            court, surround, _ = TENNIS_FLOORS["hard"]
            return cls(sport=sport, floor=court, surround=surround, indoor=False, sky=(170, 195, 230))
        return cls(sport=sport)

    @classmethod
    def sample(cls, rng: np.random.Generator, sport: str = "padel") -> Appearance:
        """A random look: surfaces, venue, lighting, players, camera degradations."""
        if sport == "tennis":
            court, surround, stripes = TENNIS_FLOORS[("hard", "clay", "grass")[rng.integers(3)]]
            floor, surround = _jitter(rng, court, 14), _jitter(rng, surround, 14)
            indoor = bool(rng.random() < 0.2)
        else:
            floor, stripes = _jitter(rng, PADEL_FLOORS[rng.integers(len(PADEL_FLOORS))], 16), 0.0
            surround = _hsv(rng, (0, 1), (0, 0.3), (0.2, 0.55))
            indoor = bool(rng.random() < 0.7)
        sky = _hsv(rng, (0, 1), (0, 0.2), (0.12, 0.5)) if indoor else _jitter(rng, (165, 192, 228), 20)
        if sport == "tennis" or rng.random() < 0.5:  # same shirt colour per team (ids 0, 1 and 2, 3)
            looks = []
            for _ in range(2):
                shirt = _hsv(rng, (0, 1), (0.0, 0.9), (0.25, 1.0))
                looks += [PlayerLook.sample(rng, shirt), PlayerLook.sample(rng, shirt)]
        else:
            looks = [PlayerLook.sample(rng) for _ in range(4)]
        frame = ((25, 25, 28), (60, 62, 66), (190, 190, 196), (20, 40, 90))[rng.integers(4)]
        light = np.array([rng.uniform(-0.35, 0.35), rng.uniform(-0.35, 0.35), -1.0])
        return cls(
            sport=sport, floor=floor, surround=surround, line=_jitter(rng, (240, 240, 234), 12),
            stripes=stripes, floor_texture=float(rng.uniform(0.03, 0.12)),
            wall=_hsv(rng, (0, 1), (0, 0.5), (0.08, 0.45)),
            banners=tuple(_hsv(rng, (0, 1), (0.2, 1.0), (0.2, 1.0)) for _ in range(4)),
            sky=sky, indoor=indoor,
            glass_tint=_jitter(rng, (165, 200, 205), 15), glass_alpha=float(rng.uniform(0.04, 0.12)),
            frame=frame, mesh=_jitter(rng, frame, 10), mesh_alpha=float(rng.uniform(0.7, 1.0)),
            net=_jitter(rng, (30, 30, 30), 15), net_tape=_jitter(rng, (238, 238, 238), 12),
            gain=float(rng.uniform(0.8, 1.2)), gamma=float(rng.uniform(0.85, 1.2)),
            cast=tuple(float(c) for c in rng.uniform(0.92, 1.08, 3)), vignette=float(rng.uniform(0, 0.35)),
            players=tuple(looks), ball=_jitter(rng, (214, 232, 62), 14),
            ball_shading=float(rng.uniform(0.1, 0.3)),
            noise_sigma=float(rng.uniform(0.0, 5.0)),
            jpeg_quality=None if rng.random() < 0.2 else int(rng.integers(55, 96)),
            shutter=float(rng.uniform(0.25, 1.0)),
            light_dir=tuple(float(v) for v in light / np.linalg.norm(light)),
            shadow_strength=float(rng.uniform(0.25, 0.6)),
            reflection_strength=float(rng.uniform(0.15, 0.45)),
            lens_blur=float(rng.uniform(0.0, 0.8)),
            texture_seed=int(rng.integers(2**31)),
        )

    def tour(self, rng: np.random.Generator) -> Appearance:
        """This look at a tour event as broadcast (padel): bright top rails, frames and posts with a dark
        mesh, frameless glass (faint joints) standing on bright base profiles and the court's outline
        unpainted, logos painted on the floor, a score box in a corner of the picture, an advertising board
        across the bottom of the view that may hide the near baseline. Only the fields above change (the
        default draws are untouched). Measured on a real tour broadcast frame (issue 45): its side glass
        stands on light profiles about 17 cm wide, outside the court (the service lines' paint ends at
        their inner edge); its mesh is dark with light posts every 2 m."""
        frame = _jitter(rng, ((214, 204, 170), (228, 228, 222), (196, 198, 204))[rng.integers(3)], 12)
        logos = []
        words = ("MAJOR", "OPEN", "MASTER", "PADEL", "TOUR", "FINALS", "CUP", "SERIES")
        slots = [(7.6, 9.4), (10.6, 12.4), (0.9, 2.5), (17.5, 19.1)]
        for k in rng.permutation(len(slots))[: int(rng.integers(1, 4))]:
            y0, y1 = slots[k]
            x0 = float(rng.uniform(0.8, 2.5))
            n = int(rng.integers(1, 3))
            text = " ".join(words[i] for i in rng.integers(len(words), size=n))
            logos.append((text, x0, y0, float(10.0 - x0 + rng.uniform(-0.5, 0.5)), y1))
        corner = rng.integers(2)
        x0, y0 = float(rng.uniform(0.02, 0.06)), float(rng.uniform(0.03, 0.08))
        bw, bh = float(rng.uniform(0.14, 0.24)), float(rng.uniform(0.07, 0.12))
        box = (x0, y0, x0 + bw, y0 + bh) if corner == 0 else (1 - x0 - bw, y0, 1 - x0, y0 + bh)
        return replace(
            self, frame=frame, mesh=_jitter(rng, (28, 28, 32), 8), mesh_alpha=float(rng.uniform(0.75, 0.95)),
            glass_joints=float(rng.uniform(0.0, 0.25)), perimeter_paint=False,
            glass_base=_jitter(rng, frame, 10),
            glass_base_width=float(rng.uniform(0.08, 0.2)), posts=True, floor_logos=tuple(logos),
            logo=_jitter(rng, (236, 236, 236), 12), logo_alpha=float(rng.uniform(0.3, 0.75)),
            scoreboard=box, near_board=(float(rng.uniform(-3.0, -1.2)), float(rng.uniform(0.8, 1.6))),
            board=_hsv(rng, (0, 1), (0.2, 0.8), (0.08, 0.3)), tour_seed=int(rng.integers(2**31)))

    def shifted(self, rng: np.random.Generator) -> Appearance:
        """This look moved to another distribution than :meth:`sample` draws from (a stand-in for footage
        a model never saw): floors outside the usual palette, dim tinted light, stronger sensor noise,
        compression, motion and lens blur, a paler ball and stronger glass reflections."""
        floors = ((96, 98, 104), (32, 118, 126), (104, 62, 118), (138, 140, 64))
        return replace(
            self, floor=_jitter(rng, floors[rng.integers(len(floors))], 12),
            gain=float(rng.uniform(0.55, 0.8)), gamma=float(rng.uniform(1.1, 1.35)),
            cast=tuple(float(c) for c in rng.uniform(0.85, 1.15, 3)), vignette=float(rng.uniform(0.2, 0.5)),
            ball=_jitter(rng, (206, 214, 120), 12), noise_sigma=float(rng.uniform(5.0, 12.0)),
            jpeg_quality=int(rng.integers(35, 66)), shutter=float(rng.uniform(0.7, 1.0)),
            lens_blur=float(rng.uniform(0.6, 1.4)), reflection_strength=float(rng.uniform(0.4, 0.7)),
        )


# ======================================================================================================
# Exposure
# ======================================================================================================
def exposure_times(frame_idx: int, fps: float, shutter: float, n: int = 11) -> np.ndarray:
    """(n,) times evenly spread over the exposure of frame ``frame_idx``, centred on ``frame_idx / fps``."""
    return frame_idx / fps + np.linspace(-0.5, 0.5, n) * shutter / fps


def ball_exposure(path: BallPath, frame_idx: int, fps: float, shutter: float,
                  n: int = 11) -> np.ndarray | None:
    """(n, 3) ball positions over the exposure of a frame (what :meth:`CourtRenderer.render` takes), or
    None when the frame time is outside the path."""
    t = frame_idx / fps
    if len(path.t) == 0 or t < path.t[0] or t > path.t[-1]:
        return None
    return path.sample(np.clip(exposure_times(frame_idx, fps, shutter, n), path.t[0], path.t[-1]))


# ======================================================================================================
# Geometry and coverage helpers
# ======================================================================================================
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def segment_distance(p0, p1, q0, q1) -> tuple[np.ndarray, np.ndarray]:
    """Closest distance between segments ``p0``-``p1`` and ``q0``-``q1``, broadcast over leading axes
    (..., 3).

    Returns:
        dist (...), s (...): the distance and the parameter in [0, 1] of the closest point along p.
    """
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.maximum(np.sum(d1 * d1, -1), 1e-12)
    e = np.maximum(np.sum(d2 * d2, -1), 1e-12)
    b, c, f = np.sum(d1 * d2, -1), np.sum(d1 * r, -1), np.sum(d2 * r, -1)
    denom = a * e - b * b
    s = np.where(denom > 1e-9 * a * e, np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0, 1), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    diff = (p0 + d1 * s[..., None]) - (q0 + d2 * t[..., None])
    return np.linalg.norm(diff, axis=-1), s


def _clip_near(camera: Camera, pts: np.ndarray, closed: bool) -> np.ndarray:
    """Clip a (M, 3) polyline/polygon to depth >= NEAR (Sutherland-Hodgman); returns (K, 3), maybe empty."""
    depth = camera.depth(pts)
    out = []
    m = len(pts) if closed else len(pts) - 1
    for i in range(len(pts)):
        a, da = pts[i], depth[i]
        if da >= NEAR:
            out.append(a)
        if i < m:
            j = (i + 1) % len(pts)
            b, db = pts[j], depth[j]
            if (da >= NEAR) != (db >= NEAR):
                out.append(a + (NEAR - da) / (db - da) * (b - a))
    return np.array(out).reshape(-1, 3)


def _densify(pts: np.ndarray, closed: bool, n: int = 8) -> np.ndarray:
    """Insert points along each edge (for lens distortion): (M, 3) → (M·n, 3)."""
    ends = np.roll(pts, -1, axis=0) if closed else pts[1:]
    starts = pts if closed else pts[:-1]
    f = np.linspace(0, 1, n, endpoint=False)[None, :, None]
    dense = (starts[:, None] + f * (ends - starts)[:, None]).reshape(-1, 3)
    return dense if closed else np.vstack([dense, pts[-1:]])


def _bbox(camera: Camera, pts: np.ndarray, closed: bool, pad: float) -> tuple[int, int, int, int] | None:
    """Pixel box ``(x0, y0, x1, y1)`` (x1, y1 exclusive) of 3D points' projection, clipped to the image."""
    pts = _clip_near(camera, np.asarray(pts, float), closed)
    if len(pts) < (3 if closed else 2):
        return None
    px = camera.project(_densify(pts, closed) if camera.dist is not None else pts)
    return _clip_box(np.nanmin(px, 0) - pad, np.nanmax(px, 0) + pad, camera.image_size)


def _clip_box(lo, hi, size) -> tuple[int, int, int, int] | None:
    w, h = size
    x0, y0 = max(int(np.floor(lo[0])), 0), max(int(np.floor(lo[1])), 0)
    x1, y1 = min(int(np.ceil(hi[0])) + 1, w), min(int(np.ceil(hi[1])) + 1, h)
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def _band_coverage(d: np.ndarray, half_width: float, fw: np.ndarray) -> np.ndarray:
    """Box-filtered coverage of the band ``|d| < half_width`` by pixels ``fw`` wide (same units as d)."""
    fw = np.maximum(fw, 1e-6)
    lo = np.maximum(d - fw / 2, -half_width)
    hi = np.minimum(d + fw / 2, half_width)
    return np.clip(hi - lo, 0, None) / fw


def _periodic_coverage(coord: np.ndarray, spacing: float, half_width: float, fw: np.ndarray) -> np.ndarray:
    """Coverage of parallel wires every ``spacing`` along ``coord``; tends to the mean density where
    several wires fall into one pixel."""
    d = np.abs((coord / spacing + 0.5) % 1.0 - 0.5) * spacing
    mix = np.clip((fw / spacing - 0.25) / 0.75, 0, 1)
    return (1 - mix) * _band_coverage(d, half_width, fw) + mix * min(1.0, 2 * half_width / spacing)


def _fwidth(f: np.ndarray) -> np.ndarray:
    """(h, w) field → |∂f/∂x| + |∂f/∂y| per pixel (central differences; NaN where undefined)."""
    if min(f.shape) < 2:
        return np.full_like(f, np.nan)
    gy, gx = np.gradient(f)
    return np.abs(gx) + np.abs(gy)


def _simplify_path(px: np.ndarray, tol: float = 0.3) -> list[int]:
    """Indices of a (K, 2) polyline kept by Douglas-Peucker with tolerance ``tol`` pixels."""
    keep = {0, len(px) - 1}
    stack = [(0, len(px) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = px[i], px[j]
        ab = b - a
        rel = px[i + 1:j] - a
        n = np.linalg.norm(ab)
        dev = np.abs(ab[0] * rel[:, 1] - ab[1] * rel[:, 0]) / n if n > 1e-9 else np.linalg.norm(rel, axis=1)
        k = int(np.argmax(dev))
        if dev[k] > tol:
            keep.add(i + 1 + k)
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return sorted(keep)


def swept_disc_coverage(gx: np.ndarray, gy: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                        aa: Sequence[float] = (-0.375, -0.125, 0.125, 0.375)) -> np.ndarray:
    """Motion-blurred disc: the fraction of the exposure during which each grid point is inside a disc
    moving piecewise-linearly through ``centres`` (K, 2), evenly spaced in time, with ``radii`` (K,).

    Args:
        gx, gy: (h, w) grid coordinates (pixels, or floor metres for shadows).
        aa: radius offsets averaged for a soft edge (±0.5 px box filter by default).
    Returns:
        (h, w) float32 coverage in [0, 1].
    """
    K = len(centres)
    idx = _simplify_path(centres) if K > 1 else [0]
    if len(idx) == 1:
        c0, c1 = centres[idx], centres[idx]
        rad, wt = radii[idx], np.ones(1)
    else:
        i, j = np.array(idx[:-1]), np.array(idx[1:])
        c0, c1 = centres[i], centres[j]
        rad = np.array([radii[a:b + 1].mean() for a, b in zip(i, j)])
        wt = (j - i) / (K - 1)
    px = gx[None] - c0[:, 0, None, None]  # (M, h, w)
    py = gy[None] - c0[:, 1, None, None]
    D = c1 - c0
    dd = np.sum(D * D, 1)[:, None, None]
    pd = px * D[:, 0, None, None] + py * D[:, 1, None, None]
    pp = px * px + py * py
    cov = np.zeros(gx.shape, np.float32)
    for off in aa:
        rr = (np.maximum(rad + off, 0.0) ** 2)[:, None, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            disc = pd * pd - dd * (pp - rr)
            sq = np.sqrt(np.maximum(disc, 0))
            span = np.clip((pd + sq) / dd, 0, 1) - np.clip((pd - sq) / dd, 0, 1)
        frac = np.where(dd > 1e-12, np.where(disc > 0, span, 0.0), (pp < rr).astype(np.float32))
        cov += np.tensordot(wt, np.nan_to_num(frac), axes=1).astype(np.float32)
    return cov / len(aa)


def _composite(img: np.ndarray, x0: int, y0: int, alpha: np.ndarray, colour: np.ndarray) -> None:
    """Blend ``colour`` ((3,) or (h, w, 3)) into ``img[y0:y0+h, x0:x0+w]`` (uint8) with (h, w) ``alpha``."""
    h, w = alpha.shape
    roi = img[y0:y0 + h, x0:x0 + w]
    f = roi.astype(np.float32)
    f += (np.asarray(colour, np.float32) - f) * alpha[..., None]
    roi[:] = (f + 0.5).astype(np.uint8)


def _noise_tile(rng: np.random.Generator, n: int, cutoff: float) -> np.ndarray:
    """(n, n) periodic smooth noise in [-1, 1] (Gaussian low-pass in Fourier space, ``cutoff`` cycles)."""
    spec = np.fft.fft2(rng.standard_normal((n, n)))
    k = np.fft.fftfreq(n) * n
    spec *= np.exp(-(k[:, None] ** 2 + k[None, :] ** 2) / (2 * cutoff**2))
    tile = np.real(np.fft.ifft2(spec))
    return (tile / (np.abs(tile).max() + 1e-9)).astype(np.float32)


def _sample_tile(tile: np.ndarray, u: np.ndarray, v: np.ndarray, texel_m: float) -> np.ndarray:
    """Sample a periodic tile at metric coordinates (u, v) with ``texel_m`` metres per texel."""
    mx = np.nan_to_num(u / texel_m).astype(np.float32)
    my = np.nan_to_num(v / texel_m).astype(np.float32)
    return cv2.remap(tile, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _text_texture(text: str, width: int, height: int) -> np.ndarray:
    """(height, width) float32 coverage in [0, 1] of ``text`` in bold capitals filling the box."""
    width, height = max(width, 8), max(height, 8)
    font = cv2.FONT_HERSHEY_DUPLEX
    (tw, th), base = cv2.getTextSize(text, font, 1.0, 2)
    scale = min(0.92 * width / tw, 0.8 * height / (th + base))
    thick = max(1, int(round(2.2 * scale)))
    (tw, th), base = cv2.getTextSize(text, font, scale, thick)
    img = np.zeros((height, width), np.uint8)
    cv2.putText(img, text, ((width - tw) // 2, (height + th) // 2), font, scale, 255, thick, cv2.LINE_AA)
    return cv2.GaussianBlur(img.astype(np.float32) / 255.0, (0, 0), 0.7)


def _score_box(app: Appearance, size: tuple[int, int]) -> tuple[int, int, np.ndarray, np.ndarray] | None:
    """The broadcast's score box (``scoreboard``): its top-left pixel, premultiplied colour (h, w, 3) and
    alpha (h, w): a dark panel with a light header, two rows of names and games, and rules between them."""
    if app.scoreboard is None:
        return None
    w, h = size
    x0, y0 = int(app.scoreboard[0] * w), int(app.scoreboard[1] * h)
    x1, y1 = int(app.scoreboard[2] * w), int(app.scoreboard[3] * h)
    bw, bh = max(x1 - x0, 20), max(y1 - y0, 12)
    rng = np.random.default_rng([app.tour_seed, 3])
    colour = np.zeros((bh, bw, 3), np.float32)
    colour[:] = (18, 20, 30)
    head = max(2, bh // 5)
    colour[:head] = (235, 235, 235)
    for k in range(2):
        top = head + k * (bh - head) // 2
        if k:
            colour[top:top + max(1, bh // 40)] = (200, 200, 200)
        row = np.zeros((bh, bw), np.uint8)
        name = "".join(chr(65 + int(c)) for c in rng.integers(26, size=int(rng.integers(5, 9))))
        name += " / " + "".join(chr(65 + int(c)) for c in rng.integers(26, size=int(rng.integers(5, 9))))
        sub = _text_texture(name, int(0.75 * bw), (bh - head) // 2)
        row[top:top + sub.shape[0], 4:4 + sub.shape[1]] = (255 * sub[: bh - top, : bw - 4]).astype(np.uint8)
        score = _text_texture(str(int(rng.integers(7))), int(0.12 * bw), (bh - head) // 2)
        sw = score.shape[1]
        row[top:top + score.shape[0], bw - sw - 3:bw - 3] = (255 * score[: bh - top]).astype(np.uint8)
        a = row.astype(np.float32)[..., None] / 255.0
        colour = colour * (1 - a) + 245.0 * a
    colour[:, :2] = colour[:, -2:] = (235, 235, 235)
    alpha = np.full((bh, bw), 0.92, np.float32)
    return x0, y0, colour * alpha[..., None], alpha


# ======================================================================================================
# Grading
# ======================================================================================================
class _Grade:
    """Gain, colour cast, gamma and vignetting, for whole images (once) and single colours (per object)."""

    def __init__(self, app: Appearance, size: tuple[int, int]):
        w, h = size
        self.mult = np.float32(app.gain) * np.asarray(app.cast, np.float32)
        self.gamma = np.float32(app.gamma)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
        self.vignette = (1.0 - np.float32(app.vignette) * r2).astype(np.float32)

    def tone(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) linear colours 0-255 → graded, without vignetting."""
        x = np.clip(np.asarray(rgb, np.float32) * (self.mult / 255.0), 0.0, 1.0)
        return 255.0 * (x if self.gamma == 1 else x**self.gamma)

    def image(self, raw: np.ndarray, x0: int = 0, y0: int = 0) -> np.ndarray:
        """(h, w, 3) float32 raw image whose top-left is (x0, y0) → graded float32."""
        h, w = raw.shape[:2]
        return self.tone(raw) * self.vignette[y0:y0 + h, x0:x0 + w, None]

    def colours(self, tones: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Apply the vignetting at pixels ``xy`` (N, 2) to already toned colours (N, 3)."""
        h, w = self.vignette.shape
        xy = np.nan_to_num(np.asarray(xy, float))
        x = np.clip(xy[:, 0], 0, w - 1).astype(int)
        y = np.clip(xy[:, 1], 0, h - 1).astype(int)
        return (tones * self.vignette[y, x][:, None]).astype(np.float32)


# ======================================================================================================
# Static scene (ray-cast once per clip)
# ======================================================================================================
@dataclass
class _Overlay:
    """A see-through layer cropped to its box: premultiplied colour (h, w, 3) and alpha (h, w). It is a
    panel (``plane``) or a frame tube (``tube``: its segment ends (2, 3) and radius)."""

    x0: int
    y0: int
    colour: np.ndarray
    alpha: np.ndarray
    distance: float  # from the camera, for far-to-near compositing
    plane: Plane | None = None
    tube: tuple[np.ndarray, float] | None = None

    @property
    def box(self) -> tuple[int, int, int, int]:
        return self.x0, self.y0, self.x0 + self.alpha.shape[1], self.y0 + self.alpha.shape[0]

    def over(self, canvas: np.ndarray, cx0: int, cy0: int) -> None:
        """Composite onto a float32 (H', W', 3) ``canvas`` whose top-left pixel is (cx0, cy0), in place."""
        ch, cw = canvas.shape[:2]
        h, w = self.alpha.shape
        x0, y0 = max(self.x0, cx0), max(self.y0, cy0)
        x1, y1 = min(self.x0 + w, cx0 + cw), min(self.y0 + h, cy0 + ch)
        if x1 <= x0 or y1 <= y0:
            return
        dst = canvas[y0 - cy0:y1 - cy0, x0 - cx0:x1 - cx0]
        a = self.alpha[y0 - self.y0:y1 - self.y0, x0 - self.x0:x1 - self.x0, None]
        dst *= 1.0 - a
        dst += self.colour[y0 - self.y0:y1 - self.y0, x0 - self.x0:x1 - self.x0]

    def graded(self, grade: _Grade) -> _Overlay:
        """The same layer with its colour graded (for compositing over graded objects)."""
        a = self.alpha[..., None]
        straight = self.colour / np.maximum(a, 1e-6)
        return replace(self, colour=(grade.image(straight, self.x0, self.y0) * a).astype(np.float32))


def _crop(x0: int, y0: int, colour: np.ndarray, alpha: np.ndarray, distance: float,
          **what) -> _Overlay | None:
    """An overlay from straight colour and alpha on a box, cropped to where alpha > 0."""
    alpha = np.nan_to_num(alpha).astype(np.float32)
    rows, cols = np.flatnonzero(alpha.max(1) > 1e-3), np.flatnonzero(alpha.max(0) > 1e-3)
    if len(rows) == 0:
        return None
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    a = alpha[r0:r1, c0:c1]
    col = (np.asarray(colour, np.float32)[r0:r1, c0:c1] * a[..., None]).astype(np.float32)
    return _Overlay(x0 + int(c0), y0 + int(r0), col, a, distance, **what)


def _over_straight(c_back, a_back, c_front, a_front):
    """Composite straight-alpha layers (colours (..., 3), alphas (...)) → straight colour, alpha."""
    a = a_front + a_back * (1 - a_front)
    c = c_front * a_front[..., None] + c_back * (a_back * (1 - a_front))[..., None]
    c = c / np.maximum(a, 1e-6)[..., None]
    return c, a


@dataclass
class _PanelHits:
    """Where the pixels of a panel's box hit its plane: |cos| of the incidence (h, w), horizontal and
    vertical coordinates h, z (m, h from the panel's start), their pixel footprints fw_h, fw_z (m) and
    the plane coordinates uv (h, w, 2)."""

    plane: Plane
    cos_incidence: np.ndarray
    h: np.ndarray
    z: np.ndarray
    fw_h: np.ndarray
    fw_z: np.ndarray
    uv: np.ndarray


def _grid_coverage(hits: _PanelHits, spacing: float, half_width: float) -> np.ndarray:
    """Coverage of a square grid of wires (horizontal and vertical) on a panel."""
    return 1 - (1 - _periodic_coverage(hits.h, spacing, half_width, hits.fw_h)) * (
        1 - _periodic_coverage(hits.z, spacing, half_width, hits.fw_z))


def _exit_distance(c: float, d: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Ray parameter where rays from ``c`` with direction component ``d`` leave the slab [lo, hi]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 1e-9, (hi - c) / d, np.where(d < -1e-9, (lo - c) / d, np.inf))


def _on_floor(seg: np.ndarray) -> bool:
    return bool(abs(seg[0, 2]) < 1e-6 and abs(seg[1, 2]) < 1e-6)


class _SceneBuilder:
    """Ray-casts the static court once: the raw (ungraded) background and the see-through overlays."""

    LINE_HALF_WIDTH = 0.025  # m, painted lines are 5 cm wide
    #: frame tube radius (m) per line layer
    TUBES: ClassVar[dict[str, float]] = {"glass": 0.035, "mesh": 0.03, "net": 0.035, "paint": 0.025}

    def __init__(self, court: Court, camera: Camera, app: Appearance):
        self.court, self.camera, self.app = court, camera, app
        self.w, self.h = camera.image_size
        self.C = camera.centre
        self.f = float(camera.K[0, 0])
        xs, ys = np.meshgrid(np.arange(self.w, dtype=float), np.arange(self.h, dtype=float))
        _, d = camera.rays(np.stack([xs.ravel(), ys.ravel()], 1))
        self.rays = d.reshape(self.h, self.w, 3)
        rng = np.random.default_rng(app.texture_seed)
        self.tex_low, self.tex_grain = _noise_tile(rng, 64, 4.0), _noise_tile(rng, 128, 40.0)
        self.banner_offset = float(rng.uniform(0, 10))
        self.banner_width = float(rng.uniform(2.5, 6.0))
        # floor coordinates of every pixel (NaN where the ray misses the floor)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(self.rays[..., 2] < -1e-9, -self.C[2] / self.rays[..., 2], np.nan)
        self.floor_t = t
        self.floor_x = (self.C[0] + t * self.rays[..., 0]).astype(np.float32)
        self.floor_y = (self.C[1] + t * self.rays[..., 1]).astype(np.float32)

    # --- raw scene ----------------------------------------------------------------------------------
    def venue_box(self) -> tuple[float, float, float, float, float]:
        """x0, x1, y0, y1 of the venue walls around the floor (containing the camera) and their height."""
        floor = self.court.planes_for("ground")[0].corners_3d()
        margin = 3.0 if self.court.sport == "padel" else 1.0
        lo = np.minimum(floor[:, :2].min(0) - margin, self.C[:2] - 1.0)
        hi = np.maximum(floor[:, :2].max(0) + margin, self.C[:2] + 1.0)
        height = 7.0 if self.app.indoor else 4.0
        return lo[0], hi[0], lo[1], hi[1], height

    def raw_scene(self) -> np.ndarray:
        """(H, W, 3) float32: venue walls, sky/ceiling, textured floor with painted lines."""
        d, C = self.rays, self.C
        x0, x1, y0, y1, wall_h = self.venue_box()
        tx, ty = _exit_distance(C[0], d[..., 0], x0, x1), _exit_distance(C[1], d[..., 1], y0, y1)
        t_wall = np.minimum(tx, ty)
        on_floor = np.nan_to_num(self.floor_t, nan=np.inf) <= t_wall
        wall_s = np.where(tx < ty, C[1] + t_wall * d[..., 1], C[0] + t_wall * d[..., 0])
        wall_z = C[2] + t_wall * d[..., 2]
        img = self._walls(wall_s, wall_z, wall_h, d[..., 2])
        floor = self._floor()
        img = np.where(on_floor[..., None], floor, img)
        return img.astype(np.float32)

    def _walls(self, s: np.ndarray, z: np.ndarray, wall_h: float, dz: np.ndarray) -> np.ndarray:
        """(H, W, 3) venue walls (s: horizontal coordinate, z: height of the hit) with a band of banners
        at the bottom, and the sky or ceiling above them (dz: the rays' vertical component)."""
        app = self.app
        low = _sample_tile(self.tex_low, s, z, 0.8)
        wall = np.asarray(app.wall, np.float32) * (0.85 + 0.25 * low)[..., None]
        wall *= (1.0 - 0.3 * np.clip(z / wall_h, 0, 1))[..., None]
        idx = np.floor(np.nan_to_num((s + self.banner_offset) / self.banner_width)).astype(int)
        idx %= len(app.banners)
        banner = np.asarray(app.banners, np.float32)[idx]
        wall = np.where(((z > 0.15) & (z < 1.05))[..., None], banner, wall)
        sky = np.asarray(app.sky, np.float32) * (0.8 + 0.4 * np.clip(dz, 0, 1))[..., None]
        return np.where((z > wall_h)[..., None], sky, wall)

    def _floor(self) -> np.ndarray:
        """(H, W, 3) floor colour (court / surround, texture, stripes, painted lines)."""
        app, X, Y = self.app, self.floor_x, self.floor_y
        sx, sy = self.court.size
        sd = np.maximum(np.maximum(-X, X - sx), np.maximum(-Y, Y - sy))  # < 0 inside the court
        inside = np.clip(0.5 - sd / np.maximum(np.nan_to_num(_fwidth(sd), nan=1.0), 1e-6), 0, 1)[..., None]
        base = inside * np.asarray(app.floor, np.float32)
        base += (1 - inside) * np.asarray(app.surround, np.float32)
        tex = 0.6 * _sample_tile(self.tex_low, X, Y, 0.7) + 0.4 * _sample_tile(self.tex_grain, X, Y, 0.02)
        stripes = np.tanh(4 * np.sin(np.pi * np.nan_to_num(Y) / 2.0))  # 2 m bands (mowed grass)
        shade = 1.0 + app.floor_texture * tex + app.stripes * stripes
        colour = base * shade[..., None]
        cov = self._paint_coverage()
        colour = colour * (1 - cov[..., None]) + np.asarray(app.line, np.float32) * cov[..., None]
        for tint, c in ((app.glass_base, self._glass_base_coverage()), (app.logo, self._logo_coverage())):
            if c is not None:
                colour = colour * (1 - c[..., None]) + np.asarray(tint, np.float32) * c[..., None]
        return colour

    def _glass_base_coverage(self) -> np.ndarray | None:
        """(H, W) coverage of the profiles the glass panels stand on: a band ``glass_base_width`` m wide on
        the floor along the bottom edge of every glass panel, on its outer side (the court's outline stays
        where it is), or None without them."""
        if self.app.glass_base is None:
            return None
        sx, sy = self.court.size
        width = self.app.glass_base_width
        X, Y = self.floor_x, self.floor_y
        fw = np.nan_to_num(_fwidth(X) + _fwidth(Y), nan=1.0)
        cov = np.zeros((self.h, self.w), np.float32)
        for plane in self.court.planes:
            if plane.material != "glass":
                continue
            pts = plane.corners_3d()
            for a, b in zip(pts, np.roll(pts, -1, axis=0)):
                if abs(a[2]) > 1e-6 or abs(b[2]) > 1e-6 or np.linalg.norm(b[:2] - a[:2]) < 1e-6:
                    continue
                ab = (b - a)[:2]
                L = float(np.linalg.norm(ab))
                u = ab / L
                n = np.array([-u[1], u[0]])
                if n @ (np.array([sx / 2, sy / 2]) - a[:2]) > 0:
                    n = -n  # outwards
                rel_x, rel_y = X - a[0], Y - a[1]
                along = rel_x * u[0] + rel_y * u[1]
                across = rel_x * n[0] + rel_y * n[1]
                inside = np.clip(np.minimum(along, L - along) / np.maximum(fw, 1e-6) + 0.5, 0, 1)
                c = np.nan_to_num(_band_coverage(across - width / 2, width / 2, fw) * inside)
                cov = np.maximum(cov, c)
        return cov

    def _logo_coverage(self, px_per_m: float = 40.0) -> np.ndarray | None:
        """(H, W) opacity of the text painted on the floor (``floor_logos``), or None without any."""
        app = self.app
        if not app.floor_logos or app.logo_alpha <= 0:
            return None
        X, Y = self.floor_x, self.floor_y
        cov = np.zeros((self.h, self.w), np.float32)
        for text, x0, y0, x1, y1 in app.floor_logos:
            tex = _text_texture(text, int(round((x1 - x0) * px_per_m)), int(round((y1 - y0) * px_per_m)))
            mx = np.nan_to_num((X - x0) * px_per_m - 0.5, nan=-10).astype(np.float32)
            # the text reads from the near side: its top row at the far edge
            my = np.nan_to_num((y1 - Y) * px_per_m - 0.5, nan=-10).astype(np.float32)
            cov = np.maximum(cov, cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                            borderValue=0))
        return cov * np.float32(app.logo_alpha)

    def _floor_segments(self) -> list[np.ndarray]:
        segs = [s for s in self.court.lines.get("paint", np.zeros((0, 2, 3))) if _on_floor(s)]
        if not self.app.perimeter_paint:  # the walls bound the court: its outline is not painted
            sx, sy = self.court.size
            edges = ((0, 0.0), (0, sx), (1, 0.0), (1, sy))
            segs = [s for s in segs if not any(np.allclose(s[:, k], v) for k, v in edges)]
        return segs

    def _paint_coverage(self) -> np.ndarray:
        """(H, W) coverage of the painted floor lines, box-filtered with the floor's pixel footprint."""
        cov = np.zeros((self.h, self.w), np.float32)
        gy_x, gx_x = np.gradient(self.floor_x)
        gy_y, gx_y = np.gradient(self.floor_y)
        hw = self.LINE_HALF_WIDTH
        for seg in self._floor_segments():
            depth = max(float(min(self.camera.depth(seg))), NEAR)
            box = _bbox(self.camera, seg, closed=False, pad=3 + self.f * hw / depth)
            if box is None:
                continue
            x0, y0, x1, y1 = box
            sl = (slice(y0, y1), slice(x0, x1))
            a, b = seg[0, :2], seg[1, :2]
            ab = b - a
            L2 = float(ab @ ab)
            px, py = self.floor_x[sl] - a[0], self.floor_y[sl] - a[1]
            t = np.clip((px * ab[0] + py * ab[1]) / L2, 0, 1)
            dist = np.hypot(px - t * ab[0], py - t * ab[1])
            n = np.array([-ab[1], ab[0]]) / np.sqrt(L2)
            fw = np.abs(n[0] * gx_x[sl] + n[1] * gx_y[sl]) + np.abs(n[0] * gy_x[sl] + n[1] * gy_y[sl])
            c = np.nan_to_num(_band_coverage(dist, hw, fw))
            cov[sl] = np.maximum(cov[sl], c)
        return cov

    # --- overlays -----------------------------------------------------------------------------------
    def overlays(self) -> list[_Overlay]:
        """All see-through panels (glass, mesh, net) and frame tubes, far to near."""
        panels = [self._panel(p) for p in self.court.planes if p.material in ("glass", "mesh", "net")]
        board = self.near_board()
        if board is not None:
            panels.append(self._panel(board))
        out = [o for o in panels + self._tubes() if o is not None]
        return sorted(out, key=lambda o: -o.distance)

    def near_board(self) -> Plane | None:
        """The advertising board across the view (``near_board``) as an opaque panel, when the camera stands
        behind it (at least 1 m)."""
        if self.app.near_board is None:
            return None
        y, height = self.app.near_board
        if self.C[1] > y - 1.0:
            return None
        sx = self.court.size[0]
        polygon = np.array([[0, 0], [0, sx + 16], [height, sx + 16], [height, 0]])
        return Plane("near_board", "board", "board", np.array([-8.0, y, 0.0]), np.array([0.0, 0.0, 1.0]),
                     np.array([1.0, 0.0, 0.0]), polygon)

    def _panel(self, plane: Plane) -> _Overlay | None:
        """Ray-cast one glass, mesh or net plane inside its polygon."""
        box = _bbox(self.camera, plane.corners_3d(), closed=True, pad=2)
        if box is None:
            return None
        x0, y0, x1, y1 = box
        d = self.rays[y0:y1, x0:x1]
        n = plane.normal
        dn = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((plane.origin - self.C) @ n) / dn
        hit = np.isfinite(t) & (t > NEAR)
        P = self.C + np.where(hit, t, 0.0)[..., None] * d
        uv = plane.to_plane_coords(P.reshape(-1, 3))
        inside = hit & points_in_polygon(uv, plane.polygon).reshape(hit.shape)
        horiz = np.cross(n, UP)
        horiz = horiz / np.linalg.norm(horiz) if np.linalg.norm(horiz) > 1e-9 else plane.u
        h = (P - plane.origin) @ horiz
        h -= float(((plane.corners_3d() - plane.origin) @ horiz).min())  # from the panel's start
        z = P[..., 2]
        hits = _PanelHits(plane, np.abs(dn), h, z, np.nan_to_num(_fwidth(h), nan=1.0),
                          np.nan_to_num(_fwidth(z), nan=1.0), uv.reshape(*hit.shape, 2))
        colour, alpha = {"glass": self._glass, "mesh": self._mesh, "net": self._net,
                         "board": self._board}[plane.material](hits)
        centroid = plane.corners_3d().mean(0)
        return _crop(x0, y0, colour, np.where(inside, alpha, 0.0), float(np.linalg.norm(centroid - self.C)),
                     plane=plane)

    def _glass(self, hits: _PanelHits):
        """Tinted glass, more reflective at grazing angles (Schlick's Fresnel), dark joints every 2 m."""
        app = self.app
        fres = (1.0 - hits.cos_incidence) ** 5
        alpha = app.glass_alpha + (0.5 - app.glass_alpha) * fres
        sky = np.asarray(app.sky, np.float32) * 1.3
        colour = np.asarray(app.glass_tint, np.float32) * (1 - fres[..., None]) + sky * fres[..., None]
        joints = app.glass_joints * _periodic_coverage(hits.h, 2.0, 0.008, hits.fw_h)
        joint_colour = np.broadcast_to(np.asarray(app.frame, np.float32) * 0.8, colour.shape)
        return _over_straight(colour, alpha, joint_colour, joints)

    def _board(self, hits: _PanelHits):
        """An opaque advertising board: its colour with light lettering every few metres."""
        px_per_m = 30.0
        height = float(hits.plane.polygon[:, 0].max())
        width = float(hits.plane.polygon[:, 1].max())
        rng = np.random.default_rng(self.app.tour_seed)
        tex = np.zeros((int(height * px_per_m), int(width * px_per_m)), np.float32)
        x = float(rng.uniform(0, 2))
        while x < width - 2:
            w = float(rng.uniform(1.5, 3.5))
            word = "".join(chr(65 + int(c)) for c in rng.integers(26, size=int(rng.integers(4, 9))))
            sub = _text_texture(word, int(w * px_per_m), int(0.45 * height * px_per_m))
            r0, c0 = int(0.3 * height * px_per_m), int(x * px_per_m)
            tex[r0:r0 + sub.shape[0], c0:c0 + sub.shape[1]] = sub[: tex.shape[0] - r0, : tex.shape[1] - c0]
            x += w + float(rng.uniform(0.8, 2.5))
        mx = np.nan_to_num(hits.h * px_per_m - 0.5).astype(np.float32)
        my = np.nan_to_num((height - hits.z) * px_per_m - 0.5).astype(np.float32)
        text = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        light = np.asarray((225, 225, 225), np.float32)
        colour = np.asarray(self.app.board, np.float32) * (1 - text[..., None]) + light * text[..., None]
        return colour, np.ones(text.shape, np.float32)

    def _mesh(self, hits: _PanelHits):
        """Welded wire mesh, 5 cm squares of 4 mm wire."""
        cov = _grid_coverage(hits, 0.05, 0.002)
        colour = np.broadcast_to(np.asarray(self.app.mesh, np.float32), (*cov.shape, 3))
        return colour, self.app.mesh_alpha * cov

    def _net(self, hits: _PanelHits):
        """Net mesh (4.5 cm squares) with a 5.5 cm white tape along its top edge."""
        app = self.app
        cov = _grid_coverage(hits, 0.045, 0.0018)
        colour = np.broadcast_to(np.asarray(app.net, np.float32), (*cov.shape, 3))
        tape_half = 0.0275
        d_top = self._distance_to_top_edges(hits.plane, hits.uv)
        tape = _band_coverage(np.abs(d_top - tape_half), tape_half, hits.fw_z)
        tape_colour = np.broadcast_to(np.asarray(app.net_tape, np.float32), colour.shape)
        return _over_straight(colour, 0.85 * cov, tape_colour, tape)

    @staticmethod
    def _distance_to_top_edges(plane: Plane, uv: np.ndarray) -> np.ndarray:
        """(h, w) distance (m) from plane points to the polygon edges that bound it from above."""
        up = np.array([plane.u[2], plane.v[2]])
        up = up / max(np.linalg.norm(up), 1e-9)
        poly = plane.polygon
        best = np.full(uv.shape[:2], np.inf)
        for a, b in zip(poly, np.roll(poly, -1, axis=0)):
            m = 0.5 * (a + b)
            below, above = points_in_polygon(np.stack([m - 0.01 * up, m + 0.01 * up]), poly, tol=0)
            if not (below and not above):
                continue
            ab = b - a
            rel = uv - a
            t = np.clip((rel @ ab) / max(ab @ ab, 1e-12), 0, 1)
            best = np.minimum(best, np.linalg.norm(rel - t[..., None] * ab, axis=-1))
        return best

    def _tubes(self) -> list[_Overlay | None]:
        """Frames, posts and net cords: every non-floor line segment as a shaded cylinder."""
        app = self.app
        out = []
        for layer, segs in self.court.lines.items():
            radius = self.TUBES.get(layer, 0.02)
            for seg in segs:
                if layer == "paint" and _on_floor(seg):
                    continue
                vertical = abs(seg[1, 2] - seg[0, 2]) > 0.9 * np.linalg.norm(seg[1] - seg[0])
                if layer == "net" and not vertical:
                    colour, r = app.net_tape, 0.012
                else:
                    colour, r = (app.line if layer == "paint" else app.frame), radius
                out.append(self._tube(seg[0], seg[1], r, colour))
        for a, b in self._posts():
            out.append(self._tube(a, b, self.TUBES["mesh"], app.frame))
        return out

    def _posts(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Frame posts every 2 m along the mesh panels (``posts``): the mesh above the back glass and the side
        mesh between the glass ends."""
        if not self.app.posts:
            return []
        out = []
        for plane in self.court.planes:
            if plane.material != "mesh":
                continue
            pts = plane.corners_3d()
            lo, hi = pts.min(0), pts.max(0)
            k = 0 if hi[0] - lo[0] > hi[1] - lo[1] else 1  # the horizontal axis along the panel
            for s in np.arange(np.ceil(lo[k] / 2.0) * 2.0, hi[k] + 1e-6, 2.0):
                a, b = lo.copy(), hi.copy()
                a[k] = b[k] = s
                out.append((a, b))
        return out

    def _tube(self, a: np.ndarray, b: np.ndarray, radius: float, colour: Colour) -> _Overlay | None:
        seg = _clip_near(self.camera, np.stack([a, b]), closed=False)
        if len(seg) < 2:
            return None
        a, b = seg[0], seg[-1]
        depth = float(min(self.camera.depth(seg)))
        box = _bbox(self.camera, seg, closed=False, pad=self.f * radius / max(depth, NEAR) + 3)
        if box is None:
            return None
        x0, y0, x1, y1 = box
        d = self.rays[y0:y1, x0:x1]
        far = 1e3
        dist, s = segment_distance(self.C, self.C + far * d, a, b)
        fp = np.maximum(s * far, NEAR) / self.f
        cov = _band_coverage(dist, radius, fp)
        shade = 0.7 + 0.3 * np.sqrt(np.clip(1 - (dist / radius) ** 2, 0, 1))
        col = np.asarray(colour, np.float32) * shade[..., None]
        return _crop(x0, y0, col, cov, float(np.linalg.norm(0.5 * (a + b) - self.C)) - 0.3,
                     tube=(np.stack([a, b]), radius))


# ======================================================================================================
# Per-frame drawables
# ======================================================================================================
class _CapsuleSet:
    """M projected capsules prepared once (vectorised) as cv2 fixed-point primitives: each capsule is two
    anti-aliased discs joined by their tangent quad; capsules thinner than 0.75 px are a 1-px line.

    Args:
        pa, pb: (M, 2) end centres (image pixels); ra, rb: (M,) radii (pixels).
    """

    def __init__(self, pa: np.ndarray, pb: np.ndarray, ra: np.ndarray, rb: np.ndarray):
        d = pb - pa
        n = np.linalg.norm(d, axis=1, keepdims=True)
        perp = np.where(n > 1e-6, np.c_[-d[:, 1], d[:, 0]] / np.maximum(n, 1e-9), 0.0)
        quads = np.stack([pa + perp * ra[:, None], pb + perp * rb[:, None], pb - perp * rb[:, None],
                          pa - perp * ra[:, None]], axis=1)
        self.quads = _fixed(quads, (0, 0))
        self.ca, self.cb = _fixed(pa, (0, 0)).tolist(), _fixed(pb, (0, 0)).tolist()
        self.ra, self.rb = np.round(ra * ONE).astype(int).tolist(), np.round(rb * ONE).astype(int).tolist()
        self.thin = (np.maximum(ra, rb) < 0.75).tolist()
        self.lo = np.minimum(pa - ra[:, None], pb - rb[:, None])
        self.hi = np.maximum(pa + ra[:, None], pb + rb[:, None])

    def draw(self, canvas: np.ndarray, i: int, colour, origin: tuple[int, int] = (0, 0)) -> None:
        """Draw capsule ``i`` onto ``canvas`` whose top-left is image pixel ``origin``."""
        ox, oy = origin[0] * ONE, origin[1] * ONE
        a = (self.ca[i][0] - ox, self.ca[i][1] - oy)
        b = (self.cb[i][0] - ox, self.cb[i][1] - oy)
        if self.thin[i]:
            cv2.line(canvas, a, b, colour, 1, cv2.LINE_AA, SHIFT)
            return
        cv2.circle(canvas, a, self.ra[i], colour, -1, cv2.LINE_AA, SHIFT)
        cv2.circle(canvas, b, self.rb[i], colour, -1, cv2.LINE_AA, SHIFT)
        quad = self.quads[i] if not (ox or oy) else self.quads[i] - np.array([ox, oy], np.int32)
        cv2.fillConvexPoly(canvas, quad, colour, cv2.LINE_AA, SHIFT)

    def boxes(self, size, pad: float = 2.0) -> list[tuple[int, int, int, int] | None]:
        """Each capsule's pixel box clipped to the image (None when off-screen)."""
        return [_clip_box(lo - pad, hi + pad, size) for lo, hi in zip(self.lo, self.hi)]


def _fixed(pts: np.ndarray, origin) -> np.ndarray:
    """(..., 2) image pixels → int32 fixed-point coordinates relative to ``origin`` for cv2 with SHIFT."""
    return np.round(np.clip(np.asarray(pts, float) - origin, -1e5, 1e5) * ONE).astype(np.int32)


def fill_capsule(canvas: np.ndarray, pa: np.ndarray, pb: np.ndarray, ra: float, rb: float, colour,
                 origin: tuple[int, int] = (0, 0)) -> None:
    """Draw one projected capsule (anti-aliased, sub-pixel) onto ``canvas`` ((h, w, 3) or (h, w) uint8)
    whose top-left is image pixel ``origin``; ``pa``, ``pb`` (2,) end centres, ``ra``, ``rb`` radii (px)."""
    caps = _CapsuleSet(np.atleast_2d(pa), np.atleast_2d(pb), np.array([float(ra)]), np.array([float(rb)]))
    caps.draw(canvas, 0, colour, origin)


@dataclass(eq=False)
class _Item:
    """Something drawn in the depth-sorted pass.

    Attributes:
        depth: distance from the camera (m); far items are drawn first.
        anchor: (3,) point tested against the see-through panels and frame tubes.
        colour: (3,) graded colour.
        box: its pixel box (x0, y0, x1, y1), clipped to the image.
        exclude: name of a plane not to composite over it (a reflection's own mirror).
        panels: overlays (panels, frame tubes) in front of it, far to near (filled in by the painter).
    """

    depth: float
    anchor: np.ndarray
    colour: np.ndarray
    box: tuple[int, int, int, int] | None
    exclude: str | None = None
    panels: list = field(default_factory=list)

    def coverage(self) -> tuple[int, int, np.ndarray]:
        """(x0, y0, alpha (h, w) float32) over :attr:`box`."""
        raise NotImplementedError

    def draw_direct(self, img: np.ndarray) -> None:
        x0, y0, alpha = self.coverage()
        _composite(img, x0, y0, alpha, self.colour)

    def paint(self, img: np.ndarray) -> None:
        """Draw into ``img``; with panels in front, composite them over the item's own pixels."""
        if not self.panels:
            self.draw_direct(img)
            return
        x0, y0, alpha = self.coverage()
        colour = np.empty((*alpha.shape, 3), np.float32)
        colour[:] = self.colour
        for p in self.panels:
            p.over(colour, x0, y0)
        _composite(img, x0, y0, alpha, colour)


@dataclass(eq=False)
class _Vector(_Item):
    """Vector shapes in one colour: capsule ``index`` of a :class:`_CapsuleSet`, filled convex polygons
    and closed outlines ``(points (N, 2), thickness px)``."""

    capsules: _CapsuleSet | None = None
    index: int = 0
    polygons: list = field(default_factory=list)
    rings: list = field(default_factory=list)

    def _draw(self, canvas: np.ndarray, colour, origin: tuple[int, int]) -> None:
        if self.capsules is not None:
            self.capsules.draw(canvas, self.index, colour, origin)
        for poly in self.polygons:
            cv2.fillConvexPoly(canvas, _fixed(poly, origin), colour, cv2.LINE_AA, SHIFT)
        for pts, thick in self.rings:
            cv2.polylines(canvas, [_fixed(pts, origin)], True, colour, round(thick), cv2.LINE_AA, SHIFT)

    def draw_direct(self, img: np.ndarray) -> None:
        self._draw(img, self.colour.tolist(), (0, 0))

    def coverage(self):
        x0, y0, x1, y1 = self.box
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        self._draw(mask, 255, (x0, y0))
        return x0, y0, mask.astype(np.float32) * np.float32(1.0 / 255.0)


@dataclass(eq=False)
class _Sprite(_Item):
    """A precomputed coverage patch (blurred ball, reflection) at the top-left of :attr:`box`."""

    alpha: np.ndarray | None = None

    def coverage(self):
        return self.box[0], self.box[1], self.alpha


def _points_box(pts: np.ndarray, pad: float, size) -> tuple[int, int, int, int] | None:
    return _clip_box(pts.min(0) - pad, pts.max(0) + pad, size)


# ======================================================================================================
# Frame info
# ======================================================================================================
@dataclass
class BallInfo:
    """The ball at the frame time: pixel centre, projected radius, ball.csv visibility (docs/formats.md:
    0 outside the image, 1 visible, 2 hard to see, 3 occluded by a player), the blur streak length and the
    occluder."""

    x: float
    y: float
    radius_px: float
    visibility: int
    streak_px: float
    occluded_by: int | None = None


@dataclass
class PlayerInfo:
    """A player's 2D COCO-17 keypoints (17, 2) px with visibility (17,) (2 visible, 1 hidden by another
    player, 0 outside the image) and the body's pixel box (x0, y0, x1, y1) or None when off-screen."""

    player_id: int
    team: str
    keypoints: np.ndarray
    keypoint_vis: np.ndarray
    bbox: tuple[float, float, float, float] | None


@dataclass
class MarkInfo:
    """A stationary ball (``key`` = its ball_no) or a reflection (``key`` = the glass plane's name,
    ``source`` = None for the ball in play, else the stationary ball's ball_no) in pixels."""

    key: int | str
    x: float
    y: float
    in_image: bool
    source: int | None = None


@dataclass
class FrameInfo:
    ball: BallInfo | None
    players: list[PlayerInfo]
    inactive_balls: list[MarkInfo]
    reflections: list[MarkInfo]


# ======================================================================================================
# The renderer
# ======================================================================================================
@dataclass
class _BodyView:
    """One player in one frame: its M capsules (a, b (M, 3), r (M,)) and their projection
    (pa, pb (M, 2), ra, rb (M,) px); ``ok`` (M,) marks capsules in front of the camera."""

    pose: PlayerPose
    frame: int
    a: np.ndarray
    b: np.ndarray
    r: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    ok: np.ndarray


class CourtRenderer:
    """Renders frames of a rally seen by ``camera`` on ``court`` with ``appearance``.

    Args:
        court, camera, appearance: the scene; the static background is built here (about a second).
        seed: seeds the sensor noise (a frame's noise depends only on ``seed`` and its index).
        profile: accumulate the time per step in :attr:`timings` (seconds).
    """

    STEPS = ("copy", "bodies", "shadows", "items", "paint", "noise", "jpeg", "info")
    NOISE_PAD = 64
    RACKET_HANDLE_RADIUS = 0.014  # m

    def __init__(self, court: Court, camera: Camera, appearance: Appearance, *, seed: int = 0,
                 profile: bool = False):
        self.court, self.camera, self.app, self.seed = court, camera, appearance, seed
        self.w, self.h = camera.image_size
        self.C = camera.centre
        self.f = float(camera.K[0, 0])
        self.ball_radius = court.ball.radius
        self.light = _unit(np.asarray(appearance.light_dir, float))
        self.grade = _Grade(appearance, camera.image_size)
        self.profile = profile
        self.timings = dict.fromkeys(self.STEPS, 0.0)
        builder = _SceneBuilder(court, camera, appearance)
        self.floor_x, self.floor_y = builder.floor_x, builder.floor_y
        raw = builder.raw_scene()
        overlays = builder.overlays()
        for o in overlays:
            o.over(raw, 0, 0)
        bg = self.grade.image(raw)
        if appearance.lens_blur > 0:
            bg = cv2.GaussianBlur(bg, (0, 0), appearance.lens_blur)
        self._background = np.clip(bg + 0.5, 0, 255).astype(np.uint8)
        self.overlays = [o.graded(self.grade) for o in overlays]  # far to near
        self._tubes = [(k, o) for k, o in enumerate(self.overlays) if o.tube is not None]
        self._tube_boxes = np.array([o.box for _, o in self._tubes]).reshape(-1, 4)
        self.glass = [p for p in court.planes if p.material == "glass"]
        self.looks = [self._tones(look) for look in appearance.players]
        self.ball_tone = self.grade.tone(appearance.ball)
        self._noise = self._noise_tiles(appearance.noise_sigma)
        self._score = _score_box(appearance, camera.image_size)
        self._material_bias = np.array([MATERIAL_BIAS[m] for m in CAPSULE_MATERIALS])

    # --- setup --------------------------------------------------------------------------------------
    def _tones(self, look: PlayerLook) -> dict:
        """Graded colours of a look: ``capsules`` (n_capsules, 3) in CAPSULE_MATERIALS order, plus the
        racket and grip (3,)."""
        return {"capsules": self.grade.tone(np.array([getattr(look, m) for m in CAPSULE_MATERIALS], float)),
                "racket": self.grade.tone(look.racket), "grip": self.grade.tone(look.grip)}

    def _noise_tiles(self, sigma: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Positive and negative parts (uint8) of a Gaussian noise tile a little larger than the frame."""
        if sigma <= 0:
            return None
        rng = np.random.default_rng([self.seed, 7919])
        shape = (self.h + self.NOISE_PAD, self.w + self.NOISE_PAD, 3)
        n = np.round(rng.standard_normal(shape, dtype=np.float32) * sigma)
        return np.clip(n, 0, 255).astype(np.uint8), np.clip(-n, 0, 255).astype(np.uint8)

    def background(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB: the empty court, graded, without noise."""
        return self._background.copy()

    # --- per frame ----------------------------------------------------------------------------------
    def render(self, frame_idx: int, ball_samples: np.ndarray | None, poses: Sequence[PlayerPose],
               inactive_balls: Sequence[InactiveBall] = ()) -> tuple[np.ndarray, FrameInfo]:
        """Render one frame.

        Args:
            frame_idx: the frame (indexes the poses; seeds the noise).
            ball_samples: (S, 3) ball centres evenly spaced over the exposure, centred on the frame time
                (see :func:`ball_exposure`); None when no ball is in play.
            poses: the players (their frame ``frame_idx``).
            inactive_balls: stationary balls; those with ``first <= frame_idx <= last`` are drawn.
        Returns:
            image (H, W, 3) uint8 RGB and the frame's :class:`FrameInfo`.
        """
        tick = self._ticker()
        img = self._background.copy()
        tick("copy")
        bodies = [self._body_view(p, frame_idx) for p in poses]
        tick("bodies")
        still = [b for b in inactive_balls if b.first <= frame_idx <= b.last]
        balls = [] if ball_samples is None else [np.atleast_2d(np.asarray(ball_samples, float))]
        sources: list[int | None] = [] if ball_samples is None else [None]
        balls += [np.asarray(b.position, float)[None] for b in still]
        sources += [b.ball_no for b in still]
        for body in bodies:
            self._player_shadow(img, body)
        for samples in balls:
            self._ball_shadow(img, samples)
        tick("shadows")
        items: list[_Item] = [it for body in bodies for it in self._body_items(body)]
        reflections: list[MarkInfo] = []
        for samples, source in zip(balls, sources):
            items += self._ball_items(samples)
            refl_items, marks = self._reflection_items(samples, source)
            items += refl_items
            reflections += marks
        tick("items")
        self._paint(img, items)
        tick("paint")
        self._add_noise(img, frame_idx)
        if self._score is not None:  # keyed into the picture after the camera: no noise, then compressed
            x0, y0, colour, alpha = self._score
            h, w = alpha.shape
            roi = img[y0:y0 + h, x0:x0 + w].astype(np.float32)
            img[y0:y0 + h, x0:x0 + w] = np.clip(roi * (1 - alpha[..., None]) + colour + 0.5, 0,
                                                 255).astype(np.uint8)
        tick("noise")
        img = self._jpeg(img)
        tick("jpeg")
        occluders = self._occluders(bodies)
        info = FrameInfo(
            ball=None if ball_samples is None else self._ball_info(balls[0], occluders),
            players=[self._player_info(b, occluders) for b in bodies],
            inactive_balls=[self._mark(b.ball_no, np.asarray(b.position, float)) for b in still],
            reflections=reflections,
        )
        tick("info")
        return img, info

    def _ticker(self):
        last = [time.perf_counter()]

        def tick(step: str) -> None:
            if self.profile:
                now = time.perf_counter()
                self.timings[step] += now - last[0]
                last[0] = now

        return tick

    # --- the one place where draw order is decided ----------------------------------------------------
    def _paint(self, img: np.ndarray, items: list[_Item]) -> None:
        """Draw ``items`` far to near (painter's algorithm on camera distance), each with the see-through
        panels and frame tubes that lie between it and the camera composited over its own pixels."""
        items = [it for it in items if it.box is not None]
        self._assign_panels(items)
        for it in sorted(items, key=lambda it: -it.depth):
            it.paint(img)

    def _assign_panels(self, items: list[_Item]) -> None:
        """Fill each item's ``panels`` (far to near) with the overlays in front of it."""
        if not items or not self.overlays:
            return
        exclude = [it.exclude for it in items]
        front = self._front_overlays(np.array([it.anchor for it in items]), np.array([it.box for it in items]),
                                     exclude)
        for it, row in zip(items, front):
            it.panels = [self.overlays[k] for k in np.flatnonzero(row)]

    def _front_overlays(self, X: np.ndarray, boxes: np.ndarray, exclude: Sequence[str | None] = ()) -> np.ndarray:
        """(N, 3) anchors with (N, 4) pixel boxes → (N, K) whether overlay k lies in front of anchor n: the
        panels whose polygon the line of sight crosses (except a plane named in ``exclude[n]``, for mirror
        images), and the frame tubes that overlap the box and come closer to the line of sight."""
        front = np.zeros((len(X), len(self.overlays)), bool)
        for k, overlay in enumerate(self.overlays):
            if overlay.plane is not None:
                mirror = np.array([e == overlay.plane.name for e in exclude], bool) if len(exclude) else False
                front[:, k] = self._behind_plane(X, overlay.plane) & ~mirror
        if self._tubes:
            front[:, [k for k, _ in self._tubes]] = self._behind_tubes(X, boxes)
        return front

    def _structure_cover(self, X: np.ndarray, xy: np.ndarray) -> float:
        """Opacity (0–1) of the glass, mesh, net and frames between the camera and point ``X`` (3,) at its
        pixel ``xy`` (2,): 1 - Π(1 - alpha) of the overlays in front of it."""
        if not self.overlays:
            return 0.0
        x, y = int(round(float(xy[0]))), int(round(float(xy[1])))
        front = self._front_overlays(X[None], np.array([[x - 1, y - 1, x + 2, y + 2]]))[0]
        clear = 1.0
        for k in np.flatnonzero(front):
            o = self.overlays[k]
            x0, y0, x1, y1 = o.box
            if x0 <= x < x1 and y0 <= y < y1:
                clear *= 1.0 - float(o.alpha[y - y0, x - x0])
        return 1.0 - clear

    def _behind_plane(self, X: np.ndarray, plane: Plane) -> np.ndarray:
        """(N, 3) points → (N,) whether the line of sight to each crosses the plane inside its polygon."""
        n = plane.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((plane.origin - self.C) @ n) / ((X - self.C) @ n)
        out = np.isfinite(s) & (s > 1e-6) & (s < 1 - 1e-6)
        if out.any():
            idx = np.flatnonzero(out)
            out[idx] = plane.contains(self.C + s[idx, None] * (X[idx] - self.C))
        return out

    def _behind_tubes(self, X: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        """(N, 3) anchors with (N, 4) pixel boxes → (N, K) whether frame tube k is in front of item n."""
        tb = self._tube_boxes
        overlap = ((boxes[:, None, 0] < tb[None, :, 2]) & (tb[None, :, 0] < boxes[:, None, 2])
                   & (boxes[:, None, 1] < tb[None, :, 3]) & (tb[None, :, 1] < boxes[:, None, 3]))
        n_idx, k_idx = np.nonzero(overlap)
        if len(n_idx):
            ends = np.array([o.tube[0] for _, o in self._tubes])
            _, s = segment_distance(self.C, X[n_idx], ends[k_idx, 0], ends[k_idx, 1])
            overlap[n_idx, k_idx] = s < 1 - 1e-6
        return overlap

    # --- players --------------------------------------------------------------------------------------
    def _body_view(self, pose: PlayerPose, frame_idx: int) -> _BodyView:
        k = int(np.clip(frame_idx, 0, pose.n_frames - 1))
        caps = capsules(pose, k)
        a = np.array([c[0] for c in caps])
        b = np.array([c[1] for c in caps])
        r = np.array([c[2] for c in caps])
        m = len(caps)
        ends = np.vstack([a, b])
        depth = self.camera.depth(ends)
        px = np.nan_to_num(self.camera.project(ends), nan=-1e5)
        rad = self.f * np.concatenate([r, r]) / np.maximum(depth, NEAR)
        ok = (depth[:m] > NEAR) & (depth[m:] > NEAR)
        return _BodyView(pose, k, a, b, r, px[:m], px[m:], rad[:m], rad[m:], ok)

    def _body_items(self, body: _BodyView) -> list[_Item]:
        """One item per capsule in front of the camera (shaded brighter towards the top), plus the racket."""
        tones = self.looks[body.pose.player_id % len(self.looks)]
        idx = np.flatnonzero(body.ok)
        mids = 0.5 * (body.a[idx] + body.b[idx])
        depth = np.linalg.norm(mids - self.C, axis=1) - self._material_bias[idx]
        mid_px = 0.5 * (body.pa[idx] + body.pb[idx])
        shade = 0.8 + 0.2 * np.clip(mids[:, 2] / body.pose.height, 0, 1)
        colours = self.grade.colours(tones["capsules"][idx] * shade[:, None], mid_px)
        caps = _CapsuleSet(body.pa[idx], body.pb[idx], body.ra[idx], body.rb[idx])
        boxes = caps.boxes((self.w, self.h))
        items: list[_Item] = [_Vector(float(depth[i]), mids[i], colours[i], boxes[i], capsules=caps, index=i)
                              for i in range(len(idx))]
        return items + self._racket_items(body, tones)

    def _racket_items(self, body: _BodyView, tones: dict) -> list[_Item]:
        """The handle (a thin capsule) and the head: a solid ellipse (padel) or a rim (tennis strings are
        see-through)."""
        pose, k = body.pose, body.frame
        handle, head = pose.racket[k]
        u = _unit(head - handle)
        v = _unit(np.cross(pose.racket_normal[k], u))
        semi_a, semi_b = pose.racket_spec.head_semi_axes
        theta = np.linspace(0, 2 * np.pi, 20, endpoint=False)
        rim = head + np.cos(theta)[:, None] * semi_a * u + np.sin(theta)[:, None] * semi_b * v
        pts = np.vstack([handle, head - semi_a * u, rim])
        depth = self.camera.depth(pts)
        if (depth <= NEAR).any():
            return []
        px = self.camera.project(pts)
        size = (self.w, self.h)
        r_px = self.f * self.RACKET_HANDLE_RADIUS / depth[:2]
        stick = _CapsuleSet(px[:1], px[1:2], r_px[:1], r_px[1:2])
        mid = 0.5 * (handle + head)
        colours = self.grade.colours(np.stack([tones["grip"], tones["racket"]]), px[:2])
        items: list[_Item] = [_Vector(float(np.linalg.norm(mid - self.C)), mid, colours[0],
                                      stick.boxes(size)[0], capsules=stick)]
        head_depth = float(np.linalg.norm(head - self.C))
        if pose.racket_spec.see_through:
            thick = max(1.0, self.f * 0.012 / float(depth[1]))
            items.append(_Vector(head_depth, head, colours[1], _points_box(px[2:], thick + 2, size),
                                 rings=[(px[2:], thick)]))
        else:
            items.append(_Vector(head_depth, head, colours[1], _points_box(px[2:], 2, size),
                                 polygons=[px[2:]]))
        return items

    def _player_shadow(self, img: np.ndarray, body: _BodyView) -> None:
        """Darken the floor under the capsules projected along the light onto z = 0 (soft edges)."""
        L = self.light
        if L[2] > -1e-3 or not body.ok.any():
            return
        a, b, r = body.a[body.ok], body.b[body.ok], body.r[body.ok]
        ends = np.vstack([a, b])
        ends = ends - (ends[:, 2] / L[2])[:, None] * L
        ends[:, 2] = 0.0
        depth = self.camera.depth(ends)
        if (depth <= NEAR).any():
            return
        px = self.camera.project(ends)
        rad = self.f * np.concatenate([r, r]) / depth
        blur = 1.0 + 0.5 * float(np.median(rad))
        box = _clip_box((px - rad[:, None]).min(0) - 3 * blur, (px + rad[:, None]).max(0) + 3 * blur,
                        (self.w, self.h))
        if box is None:
            return
        x0, y0, x1, y1 = box
        m = len(a)
        caps = _CapsuleSet(px[:m] - (x0, y0), px[m:] - (x0, y0), rad[:m], rad[m:])
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        for i in range(m):
            caps.draw(mask, i, 255)
        alpha = cv2.GaussianBlur(mask, (0, 0), blur).astype(np.float32)
        alpha *= np.float32(self.app.shadow_strength / 255.0)
        _composite(img, x0, y0, alpha, np.zeros(3, np.float32))

    # --- balls ----------------------------------------------------------------------------------------
    def _ball_shadow(self, img: np.ndarray, samples: np.ndarray) -> None:
        """A soft dark disc on the floor where the light through the ball meets it; fainter and softer the
        higher the ball. Computed in floor coordinates, so it is a correct perspective ellipse."""
        L = self.light
        height = samples[:, 2]
        if L[2] > -1e-3 or (height < -self.ball_radius).all():
            return
        floor = samples - (height / L[2])[:, None] * L
        floor[:, 2] = 0.0
        h_mid = float(np.clip(np.median(height), 0, None))
        radius = self.ball_radius * (1.0 + 0.3 * h_mid)
        soft = 0.004 + 0.03 * h_mid
        ring = np.c_[np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4), np.zeros(8)]
        outline = (floor[[0, -1], None, :] + (radius + soft) * ring[None]).reshape(-1, 3)
        if (self.camera.depth(outline) <= NEAR).any():
            return
        box = _points_box(self.camera.project(outline), 2, (self.w, self.h))
        if box is None:
            return
        x0, y0, x1, y1 = box
        gx, gy = self.floor_x[y0:y1, x0:x1], self.floor_y[y0:y1, x0:x1]
        radii = np.full(len(floor), radius)
        cov = swept_disc_coverage(gx, gy, floor[:, :2], radii, np.linspace(-soft, soft, 4))
        opacity = self.app.shadow_strength * float(np.clip(1.2 / (1.0 + 2.0 * h_mid), 0.15, 1.0))
        _composite(img, x0, y0, np.nan_to_num(cov) * np.float32(opacity), np.zeros(3, np.float32))

    def _sprite(self, samples: np.ndarray, radius_scale: float = 1.0, offset_px=(0.0, 0.0),
                blur: float = 0.0):
        """A ball moving through ``samples`` (S, 3): (box, alpha (h, w)) or None when off-screen."""
        depth = self.camera.depth(samples)
        keep = depth > NEAR
        if not keep.any():
            return None
        px = self.camera.project(samples[keep]) + np.asarray(offset_px)
        rad = radius_scale * self.f * self.ball_radius / depth[keep]
        box = _points_box(px, rad.max() + 2 + 3 * blur, (self.w, self.h))
        if box is None:
            return None
        x0, y0, x1, y1 = box
        gx, gy = np.meshgrid(np.arange(x0, x1, dtype=np.float32), np.arange(y0, y1, dtype=np.float32))
        cov = swept_disc_coverage(gx, gy, px, rad)
        if blur > 0:
            cov = cv2.GaussianBlur(cov, (0, 0), blur)
        return box, cov

    def _ball_items(self, samples: np.ndarray) -> list[_Item]:
        """The ball over its exposure, and a highlight when it is shaded."""
        mid = samples[len(samples) // 2]
        sprite = self._sprite(samples)
        if sprite is None:
            return []
        depth = float(np.linalg.norm(mid - self.C))
        xy = self.camera.project(mid[None])
        colour = self.grade.colours(self.ball_tone[None] * (1 - self.app.ball_shading), xy)[0]
        items: list[_Item] = [_Sprite(depth, mid, colour, sprite[0], alpha=sprite[1])]
        r_px = self.f * self.ball_radius / max(float(self.camera.depth(mid[None])[0]), NEAR)
        if self.app.ball_shading > 0 and r_px >= 2.5:
            hl = self._sprite(samples, 0.55, (-0.25 * r_px, -0.3 * r_px))
            if hl is not None:
                hl_tone = self.ball_tone[None] * (1 + 0.5 * self.app.ball_shading)
                hl_colour = self.grade.colours(hl_tone, xy)[0]
                items.append(_Sprite(depth - 1e-4, mid, hl_colour, hl[0], alpha=hl[1] * np.float32(0.7)))
        return items

    def mirror_views(self, point: np.ndarray) -> list[tuple[Plane, float]]:
        """Glass planes in which the camera sees a reflection of ``point`` (3,), with the point's distance
        to each. The point must be on the court side of the glass and within 3 m of it, the camera on the
        same side (the mirrored point is then behind the glass), and the line of sight to the mirrored
        point must cross the glass inside its polygon."""
        out = []
        for plane in self.glass:
            n = plane.normal
            dist = float((point - plane.origin) @ n)
            if not 0 < dist < 3.0 or float((self.C - plane.origin) @ n) <= 0:
                continue
            virtual = point - 2 * dist * n
            s = float(((plane.origin - self.C) @ n) / ((virtual - self.C) @ n))
            if 0 < s < 1 and plane.contains((self.C + s * (virtual - self.C))[None])[0]:
                out.append((plane, dist))
        return out

    def _reflection_items(self, samples: np.ndarray,
                          source: int | None) -> tuple[list[_Item], list[MarkInfo]]:
        """The ball mirrored in each glass wall it is seen in: fainter, tinted and slightly blurred."""
        strength = self.app.reflection_strength
        if strength <= 0:
            return [], []
        mid = samples[len(samples) // 2]
        items, marks = [], []
        tint = self.grade.tone(self.app.glass_tint)
        for plane, dist in self.mirror_views(mid):
            n = plane.normal
            virtual = samples - 2 * ((samples - plane.origin) @ n)[:, None] * n
            v_mid = virtual[len(virtual) // 2]
            marks.append(replace(self._mark(plane.name, v_mid), source=source))
            sprite = self._sprite(virtual, blur=0.8)
            if sprite is None:
                continue
            opacity = np.float32(strength * np.exp(-dist / 1.5))
            tone = (0.8 * self.ball_tone + 0.2 * tint)[None]
            colour = self.grade.colours(tone, self.camera.project(v_mid[None]))[0]
            items.append(_Sprite(float(np.linalg.norm(v_mid - self.C)), v_mid, colour, sprite[0],
                                 exclude=plane.name, alpha=sprite[1] * opacity))
        return items, marks

    # --- finishing ------------------------------------------------------------------------------------
    def _add_noise(self, img: np.ndarray, frame_idx: int) -> None:
        """Add the noise tile at a random offset (seeded by the frame index), with saturation."""
        if self._noise is None:
            return
        pos, neg = self._noise
        oy, ox = np.random.default_rng([self.seed, int(frame_idx)]).integers(0, self.NOISE_PAD, 2)
        cv2.add(img, pos[oy:oy + self.h, ox:ox + self.w], dst=img)
        cv2.subtract(img, neg[oy:oy + self.h, ox:ox + self.w], dst=img)

    def _jpeg(self, img: np.ndarray) -> np.ndarray:
        q = self.app.jpeg_quality
        if q is None:
            return img
        bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        _, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
        return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)

    # --- info ------------------------------------------------------------------------------------------
    def _in_image(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) pixels → (...) bool inside the image (NaN: outside)."""
        x, y = np.nan_to_num(xy[..., 0], nan=-1.0), np.nan_to_num(xy[..., 1], nan=-1.0)
        return (x >= -0.5) & (x < self.w - 0.5) & (y >= -0.5) & (y < self.h - 0.5)

    def _mark(self, key, point: np.ndarray) -> MarkInfo:
        xy = self.camera.project(point[None])[0]
        return MarkInfo(key, float(xy[0]), float(xy[1]), bool(self._in_image(xy)))

    @staticmethod
    def _occluders(bodies: list[_BodyView]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """All players' capsules stacked: a, b (N, 3), r (N,), owner (N,) player ids."""
        if not bodies:
            return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, int)
        owner = np.concatenate([np.full(len(b.r), b.pose.player_id) for b in bodies])
        return (np.vstack([b.a for b in bodies]), np.vstack([b.b for b in bodies]),
                np.concatenate([b.r for b in bodies]), owner)

    def _hidden_by(self, points: np.ndarray, occluders, margin: float) -> np.ndarray:
        """(P, 3) points → (P, N) bool: capsule n crosses the line of sight to point p, more than
        ``margin`` metres in front of it."""
        a, b, r, _ = occluders
        dist, s = segment_distance(self.C, points[:, None, :], a[None], b[None])
        length = np.linalg.norm(points - self.C, axis=1)[:, None]
        return (dist < r[None]) & (s * length < length - margin)

    def _ball_info(self, samples: np.ndarray, occluders) -> BallInfo:
        mid = samples[len(samples) // 2]
        xy = self.camera.project(mid[None])[0]
        depth = float(self.camera.depth(mid[None])[0])
        r_px = self.f * self.ball_radius / depth if depth > NEAR else 0.0
        px = self.camera.project(samples[self.camera.depth(samples) > NEAR])
        streak = float(np.sum(np.linalg.norm(np.diff(px, axis=0), axis=1))) if len(px) > 1 else 0.0
        hidden = self._hidden_by(mid[None], occluders, self.ball_radius)[0]
        occluder = int(occluders[3][np.argmax(hidden)]) if hidden.any() else None
        peak = min(1.0, 2 * r_px / max(streak, 1e-9))  # the blur spreads the ball: its strongest coverage
        cover = self._structure_cover(mid, xy) if depth > NEAR and self._in_image(xy) else 0.0
        if depth <= NEAR or not self._in_image(xy):
            vis = 0
        elif occluder is not None or cover > HIDDEN_COVER:
            vis = 3
        elif r_px < HARD_RADIUS_PX or cover > HARD_COVER or self._low_contrast(xy, peak * (1 - cover)):
            vis = 2
        else:
            vis = 1
        return BallInfo(float(xy[0]), float(xy[1]), float(r_px), vis, streak, occluder)

    def _low_contrast(self, xy: np.ndarray, peak: float, threshold: float = HARD_CONTRAST) -> bool:
        """Whether the ball's colour, at ``peak`` coverage (< 1 when blur spreads it), differs from the
        background at ``xy`` by less than ``threshold`` (RGB distance)."""
        x, y = round(float(xy[0])), round(float(xy[1]))
        bg = self._background[y, x].astype(np.float32)
        ball = self.grade.colours(self.ball_tone[None], xy[None])[0]
        return peak * float(np.linalg.norm(ball - bg)) < threshold

    def _player_info(self, body: _BodyView, occluders) -> PlayerInfo:
        pose = body.pose
        joints = pose.joints[body.frame]
        xy = self.camera.project(joints)
        shown = self._in_image(xy) & (self.camera.depth(joints) > NEAR)
        hidden = (self._hidden_by(joints, occluders, 0.02) & (occluders[3] != pose.player_id)[None]).any(1)
        vis = np.where(shown, np.where(hidden, 1, 2), 0).astype(np.int8)
        bbox = None
        if body.ok.any():
            pts = np.vstack([body.pa[body.ok], body.pb[body.ok]])
            rad = np.concatenate([body.ra[body.ok], body.rb[body.ok]])[:, None]
            lo = np.maximum((pts - rad).min(0), 0)
            hi = np.minimum((pts + rad).max(0), [self.w - 1, self.h - 1])
            if (hi > lo).all():
                bbox = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        return PlayerInfo(pose.player_id, pose.team, xy, vis, bbox)


__all__ = [
    "Appearance", "BallInfo", "CourtRenderer", "FrameInfo", "MarkInfo", "PlayerInfo", "PlayerLook",
    "ball_exposure", "exposure_times", "fill_capsule", "segment_distance", "swept_disc_coverage",
]
