"""State → overlay geometry on the frame (pure functions), and pushing it to a client's scene.

Overlays are line segments and points lying just in front of the image plane (z < 0 is towards the camera),
so the frame's JPEG never has to be re-encoded for an overlay change and stays cacheable. Geometry is built
in image pixels and mapped to the scene by :class:`labeler.viewer_common.ImagePlane`.
"""
from __future__ import annotations

import math

import numpy as np

from .state import LabelSession
from .viewer_common import ImagePlane, boxes_overlap

OVERLAY_Z = -0.002
"""Scene z of the overlays (in front of the frame, seen from the camera on -z)."""

COLORS = {
    1: (80, 255, 80),      # visible
    2: (255, 230, 40),     # hard to see
    3: (255, 60, 255),     # occluded
    "proposal": (40, 220, 255),
    "unsure": (255, 60, 40),
    "trail": (255, 255, 255),
    "inactive": (150, 120, 255),
    "point": (255, 255, 0),
    "reprojected": (0, 255, 255),
    "residual": (255, 40, 40),
    "paint": (255, 255, 255),
    "net": (255, 220, 0),
    "glass": (120, 200, 255),
    "mesh": (170, 170, 170),
}


#: word → short form in a court point's label (the dropdown and the files keep the full name)
SHORT_WORDS = {"near": "N", "far": "F", "left": "L", "right": "R", "center": "C", "centre": "C",
               "service": "svc", "glass": "gl", "top": "top", "bottom": "bot", "high": "hi", "low": "lo",
               "net": "net", "post": "post", "step": "step", "mesh": "mesh", "baseline": "base", "line": ""}


def short_point_name(name: str) -> str:
    """``near_service_left`` → ``N svc L``: a court point's label on the frame (unknown words kept)."""
    words = [SHORT_WORDS.get(w, w) for w in str(name).split("_")]
    return " ".join(w for w in words if w) or str(name)


def layout_labels(points_px: dict[str, np.ndarray], texts: dict[str, str], char_px: float, line_px: float,
                  gap_px: float, rings: int = 8) -> dict[str, tuple[np.ndarray, bool]]:
    """Top-left corners of labels that overlap neither each other nor the other points: each label in turn
    (the order given) takes the first free place around its point — right-below first, then the 8 directions
    at growing distances. Returns ``{name: ((2,) corner px, moved)}``; ``moved``: beyond the first ring (draw
    a leader line). A label with no free place keeps the first.

    ``char_px``, ``line_px``: a character's width and a line's height in image pixels; ``gap_px``: the
    distance of the first ring."""
    boxes: list[tuple[float, float, float, float]] = []
    pts = {n: np.asarray(p, float) for n, p in points_px.items() if np.isfinite(np.asarray(p, float)).all()}
    r_pt = 0.6 * gap_px

    def free(box) -> bool:
        x0, y0, x1, y1 = box
        if any(boxes_overlap(box, b) for b in boxes):
            return False
        return not any(x0 - r_pt < q[0] < x1 + r_pt and y0 - r_pt < q[1] < y1 + r_pt for q in pts.values())

    dirs = [(1, 1), (1, -1), (-1, 1), (-1, -1), (1, 0), (-1, 0), (0, 1), (0, -1)]
    out: dict[str, tuple[np.ndarray, bool]] = {}
    for name, p in pts.items():
        w, h = char_px * max(1, len(texts.get(name, name))), line_px
        first = None
        for k in range(1, rings + 1):
            d = gap_px * (1.0 + 1.5 * (k - 1))
            for dx, dy in dirs:
                x0 = p[0] + dx * d if dx >= 0 else p[0] - d - w
                y0 = p[1] + dy * d if dy >= 0 else p[1] - d - h
                if dx == 0:
                    x0 = p[0] - w / 2
                if dy == 0:
                    y0 = p[1] - h / 2
                box = (x0, y0, x0 + w, y0 + h)
                first = first or box
                if free(box):
                    out[name] = (np.array(box[:2]), k > 1)
                    break
            if name in out:
                break
        if name not in out:
            out[name] = (np.array(first[:2]), False)
            box = first
        else:
            x0, y0 = out[name][0]
            box = (x0, y0, x0 + w, y0 + h)
        boxes.append(box)
    return out


def leader_segments(points_px: dict[str, np.ndarray], corners: dict[str, tuple[np.ndarray, bool]],
                    char_px: float, line_px: float, texts: dict[str, str]) -> np.ndarray:
    """``(M, 2, 2)`` pixel segments from each moved label's point to the nearest point of its box."""
    segs = []
    for name, (corner, moved) in corners.items():
        if not moved:
            continue
        p = np.asarray(points_px[name], float)
        w = char_px * max(1, len(texts.get(name, name)))
        q = np.clip(p, corner, corner + [w, line_px])
        segs.append([p, q])
    return np.asarray(segs, float).reshape(-1, 2, 2)


def ring(center_px, radius_px: float, n: int = 20) -> np.ndarray:
    """``(n, 2, 2)`` pixel segments of a circle around ``center_px``."""
    a = np.linspace(0, 2 * math.pi, n + 1)
    pts = np.stack([center_px[0] + radius_px * np.cos(a), center_px[1] + radius_px * np.sin(a)], axis=1)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def cross(center_px, half_px: float) -> np.ndarray:
    """``(2, 2, 2)`` pixel segments of an × around ``center_px``."""
    x, y = center_px
    return np.array([[[x - half_px, y - half_px], [x + half_px, y + half_px]],
                     [[x - half_px, y + half_px], [x + half_px, y - half_px]]], dtype=float)


def clip_segments(seg: np.ndarray, width: float, height: float) -> np.ndarray:
    """Clip ``(L, 2, 2)`` pixel segments to the image rectangle (Liang–Barsky); drops outside / NaN ones."""
    seg = np.asarray(seg, dtype=float).reshape(-1, 2, 2)
    seg = seg[np.isfinite(seg).all(axis=(1, 2))]
    p0, d = seg[:, 0], seg[:, 1] - seg[:, 0]
    t0, t1 = np.zeros(len(seg)), np.ones(len(seg))
    for p, q in ((-d[:, 0], p0[:, 0]), (d[:, 0], width - p0[:, 0]), (-d[:, 1], p0[:, 1]), (d[:, 1], height - p0[:, 1])):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = q / p
        parallel = p == 0
        t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
        t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
        t0 = np.where(parallel & (q < 0), 2.0, t0)  # parallel and outside
    keep = t0 < t1
    return np.stack([p0 + t0[:, None] * d, p0 + t1[:, None] * d], axis=1)[keep]


def court_segments(camera, court, samples: int = 8) -> dict[str, np.ndarray]:
    """The court YAML's line layers (paint, net, glass, mesh) reprojected: layer → ``(L, 2, 2)`` pixels.

    Each 3D segment is split into ``samples`` pieces so lens distortion bends it, then clipped to the image.
    """
    w, h = camera.image_size
    out = {}
    for layer, segs in court.lines.items():
        t = np.linspace(0.0, 1.0, samples + 1)
        pts = segs[:, :1, :] + t[None, :, None] * (segs[:, 1:, :] - segs[:, :1, :])  # (L, S+1, 3)
        px = camera.project(pts.reshape(-1, 3)).reshape(len(segs), samples + 1, 2)
        pieces = np.stack([px[:, :-1], px[:, 1:]], axis=2).reshape(-1, 2, 2)
        out[layer] = clip_segments(pieces, w, h)
    return out


def confidence_color(score: float | None) -> tuple[int, int, int]:
    """A proposal's colour: cyan when sure (or no score, e.g. interpolation), through orange to red when unsure."""
    if score is None:
        return COLORS["proposal"]
    t = float(min(max(score, 0.0), 1.0))
    lo, hi = np.array(COLORS["unsure"], float), np.array(COLORS["proposal"], float)
    return tuple(int(round(v)) for v in lo + t * (hi - lo))


def residual_segments(session: LabelSession) -> tuple[np.ndarray, np.ndarray]:
    """Clicked court points and their reprojections: ``(N, 2)`` clicked pixels, ``(N, 2)`` reprojected pixels."""
    size = np.array([session.width, session.height], float)
    names = list(session.points)
    clicked = np.array([session.points[n] for n in names], float).reshape(-1, 2) * size
    if session.calibration is None or not names:
        return clicked, np.full_like(clicked, np.nan)
    reproj = session.calibration.camera.project(session.court.point_array(names))
    return clicked, reproj


class Overlay:
    """Draws a session's annotations of the current frame into one client's scene (call inside ``atomic()``)."""

    def __init__(self, scene, plane: ImagePlane, root: str = "/overlay"):
        self.scene, self.plane, self.root = scene, plane, root
        self._handles: dict[str, object] = {}
        self._labels: dict[str, tuple[object, tuple]] = {}  # court point → (label handle, its position)

    def handles(self) -> list:
        return list(self._handles.values()) + [h for h, _ in self._labels.values()]

    def point_labels(self, points_px: dict[str, np.ndarray], names: list[str], offset_px: float) -> None:
        """Court point names (short: :func:`short_point_name`) beside their clicked positions, laid out so
        that none covers another or a point (:func:`layout_labels`), a leader line to each moved one (text
        drawn by the browser, never as HTML)."""
        for name in list(self._labels):
            if name not in points_px:
                self._labels.pop(name)[0].remove()
        texts = {n: short_point_name(n) for n in points_px}
        order = sorted(points_px, key=lambda n: names.index(n) if n in names else len(names))
        char_px, line_px = 1.0 * offset_px, 2.0 * offset_px   # the label's size at the fitted view
        corners = layout_labels({n: points_px[n] for n in order}, texts, char_px, line_px, offset_px)
        self.lines("point_leaders", leader_segments(points_px, corners, char_px, line_px, texts),
                   COLORS["point"], 1.0)
        for name, (corner, _) in corners.items():
            pos = tuple(np.round(self.plane.pixel_to_scene(corner[None], z=OVERLAY_Z)[0], 6))
            old = self._labels.get(name)
            if old is not None and old[1] == pos:
                continue
            if old is not None:
                old[0].remove()
            index = names.index(name) if name in names else len(names)
            handle = self.scene.add_label(f"{self.root}/point_names/{index}", texts[name], position=pos,
                                          font_screen_scale=0.8, anchor="top-left")
            self._labels[name] = (handle, pos)

    def _scene_segments(self, seg_px: np.ndarray) -> np.ndarray:
        seg = np.asarray(seg_px, float).reshape(-1, 2)
        return self.plane.pixel_to_scene(seg, z=OVERLAY_Z).reshape(-1, 2, 3).astype(np.float32)

    def lines(self, name: str, seg_px: np.ndarray, color, thickness: float = 2.0) -> None:
        """Replace the line layer ``name`` (hide it when ``seg_px`` is empty)."""
        path = f"{self.root}/{name}"
        seg_px = np.asarray(seg_px, float).reshape(-1, 2, 2)
        handle = self._handles.get(path)
        if not len(seg_px):
            if handle is not None and handle.visible:
                handle.visible = False
            return
        self._handles[path] = self.scene.add_line_segments(
            path, self._scene_segments(seg_px), colors=color, thickness=thickness, thickness_units="screen")

    def clear(self, name: str) -> None:
        self.lines(name, np.empty((0, 2, 2)), (0, 0, 0))

    FRAME_LAYERS = ("ball", "proposal", "trail", "inactive")
    """The layers that belong to one frame (:meth:`draw` draws them again)."""

    def hide_frame_layers(self) -> None:
        """Hide the layers of one frame (:data:`FRAME_LAYERS`; messages only for those still shown)."""
        for name in self.FRAME_LAYERS:
            self.clear(name)

    def draw(self, session: LabelSession, frame: int, *, mode: str, trail_length: int = 15,
             show_court: bool = True, selected_point: str | None = None) -> None:
        """All overlays of ``frame``: ball, proposal, trail, stationary balls, court model and residuals."""
        size = np.array([session.width, session.height], float)
        r = max(6.0, 0.008 * session.width)
        row = session.ball.get(frame)
        if row is not None and row[0] > 0:
            self.lines("ball", ring(np.array(row[1:]) * size, r), COLORS[row[0]], 2.5)
        else:
            self.clear("ball")
        prop = session.ball_proposals.get(frame)
        if prop is not None and prop[0] > 0:
            c = np.array(prop[1:]) * size
            self.lines("proposal", np.concatenate([ring(c, r * 1.4, 12)[::2], cross(c, r * 0.5)]),
                       confidence_color(session.ball_scores.get(frame)), 2.0)
        else:
            self.clear("proposal")
        trail = session.trail(frame, trail_length)
        if len(trail) >= 2:
            px = trail[:, 1:] * size
            self.lines("trail", np.stack([px[:-1], px[1:]], axis=1), COLORS["trail"], 1.5)
        else:
            self.clear("trail")
        still = session.inactive_at(frame)
        if still:
            segs = np.concatenate([cross(np.array(xy) * size, r * 0.7) for xy in still.values()])
            self.lines("inactive", segs, COLORS["inactive"], 2.5)
        else:
            self.clear("inactive")
        self._court(session, show_court or mode == "court", selected_point, r)

    def _court(self, session: LabelSession, show: bool, selected: str | None, r: float) -> None:
        if not show:
            for name in ("court_paint", "court_net", "court_glass", "court_mesh", "points", "reprojected",
                         "residuals", "selected", "point_leaders"):
                self.clear(name)
            self.point_labels({}, [], 0.0)
            return
        if session.calibration is not None:
            for layer, segs in court_segments(session.calibration.camera, session.court).items():
                self.lines(f"court_{layer}", segs, COLORS.get(layer, (255, 255, 255)), 1.5)
        else:
            for layer in ("paint", "net", "glass", "mesh"):
                self.clear(f"court_{layer}")
        clicked, reproj = residual_segments(session)
        self.point_labels(dict(zip(session.points, clicked)), session.court.point_names, r * 0.8)
        pts = [ring(c, r * 0.6, 8) for c in clicked]
        self.lines("points", np.concatenate(pts) if pts else np.empty((0, 2, 2)), COLORS["point"], 2.0)
        ok = np.isfinite(reproj).all(axis=1)
        rep = [cross(c, r * 0.4) for c in reproj[ok]]
        self.lines("reprojected", np.concatenate(rep) if rep else np.empty((0, 2, 2)), COLORS["reprojected"], 2.0)
        self.lines("residuals", np.stack([clicked[ok], reproj[ok]], axis=1), COLORS["residual"], 2.0)
        if selected and session.calibration is not None and selected in session.court.points:
            guess = session.calibration.camera.project(session.court.points[selected][None])[0]
            self.lines("selected", ring(guess, r * 1.2, 16), COLORS["reprojected"], 1.0)
        else:
            self.clear("selected")
