"""The review's 3D scene: the court from its YAML, the ball, its trail, contact markers, players, camera presets.

The builders take a viser ``SceneApi`` (``server.scene`` for what every viewer shares, ``client.scene`` for
one viewer's moving parts), so the same code serves the live app and the ``.viser`` export.

Colours are chosen so a screenshot can be checked by pixels: the ball is a bright yellow-green that no viser
UI element uses, the padel floor a saturated blue, the tennis floor a green.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from inference.camera import Camera
from inference.court import Court, Plane
from inference.players.skeleton import COCO17_BONES
from labeler.viewer_common import boxes_overlap

BALL_RGB = (200, 255, 0)
FLOOR_RGB = {"padel": (30, 90, 200), "tennis": (50, 130, 80)}
GLASS_RGB = (170, 220, 235)
MESH_RGB = (90, 90, 90)
NET_RGB = (40, 40, 40)
LINE_RGB = {"paint": (255, 255, 255), "net": (30, 30, 30), "glass": (150, 210, 230), "mesh": (110, 110, 110)}
TEAM_RGB = {"near": (230, 70, 70), "far": (150, 70, 230), "": (200, 200, 200)}
CALL_RGB = {"in": (40, 200, 60), "out": (230, 40, 40), "fault": (230, 40, 40), "-": (160, 160, 160)}
SURFACE_RGB = (90, 200, 230)
DISPLAY_BALL_RADIUS = 0.12
"""The ball is drawn at least this big (m) so it stays visible from the broadcast camera."""
TRAIL_FRAMES = 20


# ------------------------------------------------------------------------------------------- geometry
def triangulate_polygon(poly: np.ndarray) -> np.ndarray:
    """Ear clipping of a simple polygon (M, 2) (either winding) → (M-2, 3) vertex indices."""
    pts = np.asarray(poly, float)
    idx = list(range(len(pts)))
    area = 0.5 * sum(pts[i, 0] * pts[(i + 1) % len(pts), 1] - pts[(i + 1) % len(pts), 0] * pts[i, 1]
                     for i in range(len(pts)))
    if area < 0:
        idx.reverse()

    def cross(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    def inside(p, a, b, c):
        return cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0

    tris = []
    guard = 0
    while len(idx) > 3 and guard < 10_000:
        guard += 1
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = pts[i0], pts[i1], pts[i2]
            if cross(a, b, c) <= 1e-12:
                continue  # reflex or degenerate corner
            if any(inside(pts[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
        else:
            raise ValueError("polygon is not simple (ear clipping found no ear)")
    tris.append(tuple(idx))
    return np.array(tris, dtype=np.int32)


def plane_mesh(plane: Plane, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A plane's polygon as a mesh: (M, 3) vertices (moved ``offset`` along the normal) and (T, 3) faces."""
    return plane.corners_3d() + offset * plane.normal, triangulate_polygon(plane.polygon)


def plane_kind(plane: Plane, court: Court) -> str:
    """``floor``, ``glass``, ``mesh`` or ``net`` (from the plane's event label and material)."""
    if plane.event == "ground":
        return "floor"
    if plane.event == "net":
        return "net"
    return "mesh" if plane.event == "mesh" or plane.material == "mesh" else "glass"


# ----------------------------------------------------------------------------------------- the court
def add_court(scene, court: Court, root: str = "/court") -> None:
    """Floor, translucent glass, mesh, net and every line layer of the court YAML under ``root``."""
    floor_rgb = FLOOR_RGB.get(court.sport, (90, 120, 160))
    for plane in court.planes:
        kind = plane_kind(plane, court)
        v, f = plane_mesh(plane)
        if kind == "floor":
            scene.add_mesh_simple(f"{root}/floor/{plane.name}", v, f, color=floor_rgb, side="double",
                                  flat_shading=True, cast_shadow=False)
        elif kind == "glass":
            scene.add_mesh_simple(f"{root}/glass/{plane.name}", v, f, color=GLASS_RGB, opacity=0.18,
                                  side="double", cast_shadow=False, receive_shadow=False)
        elif kind == "mesh":
            scene.add_mesh_simple(f"{root}/mesh/{plane.name}", v, f, color=MESH_RGB, opacity=0.12,
                                  side="double", cast_shadow=False, receive_shadow=False)
        else:
            scene.add_mesh_simple(f"{root}/net/{plane.name}", v, f, color=NET_RGB, opacity=0.45,
                                  side="double", cast_shadow=False, receive_shadow=False)
    for layer, segs in court.lines.items():
        segs = np.asarray(segs, float).copy()
        if layer == "paint":
            segs[..., 2] += 0.005  # above the floor, no z-fighting
        scene.add_line_segments(f"{root}/lines/{layer}", segs, LINE_RGB.get(layer, (255, 255, 255)),
                                thickness=0.05 if layer == "paint" else 0.03)


def add_full_path(scene, traj_xyz: np.ndarray, name: str = "/path") -> None:
    """The whole reconstructed path, thin and pale, for context."""
    if len(traj_xyz) >= 2:
        segs = np.stack([traj_xyz[:-1], traj_xyz[1:]], axis=1)
        scene.add_line_segments(name, segs, (235, 235, 200), thickness=0.015)


LABEL_CHAR_PX, LABEL_LINE_PX = 8.0, 22.0
"""Generous size of one character and of one line of a contact label on screen (px), for :func:`spread_labels`."""
LABEL_STEP_M = 0.3
"""How far a label is raised (m) each time it would cover another one."""


@dataclass(frozen=True)
class ContactLabel:
    """One label of the contact markers: its text, the 3D point it belongs to (3,) and its lift above it (m)."""

    name: str
    text: str
    anchor: np.ndarray
    lift: float


def spread_labels(anchors: np.ndarray, texts: list[str], project, *, base_lift: float = 0.2,
                  max_steps: int = 16) -> np.ndarray:
    """Lifts (N,) above ``anchors (N, 3)`` such that no two labels overlap on screen.

    ``project((K, 3)) -> (K, 2)`` pixels (e.g. the clip camera, the review's broadcast view). Labels are placed
    in order; each one is raised by :data:`LABEL_STEP_M` while its box (``len(text)`` ×
    :data:`LABEL_CHAR_PX` wide, :data:`LABEL_LINE_PX` high, bottom-centred) meets a box placed before it.
    """
    anchors = np.asarray(anchors, float).reshape(-1, 3)
    lifts = np.full(len(anchors), float(base_lift))
    boxes: list[tuple[float, float, float, float]] = []
    for i, (p, text) in enumerate(zip(anchors, texts)):
        half = 0.5 * LABEL_CHAR_PX * max(len(text), 1)
        for _ in range(max_steps):
            u, v = np.asarray(project((p + (0.0, 0.0, lifts[i]))[None]), float).reshape(2)
            box = (u - half, v - LABEL_LINE_PX, u + half, v)
            if not np.isfinite(box).all() or not any(boxes_overlap(box, b) for b in boxes):
                break
            lifts[i] += LABEL_STEP_M
        if np.isfinite(box).all():
            boxes.append(box)
    return lifts


def contact_labels(analysis, project=None) -> list[ContactLabel]:
    """The labels of every hit, floor bounce and wall/net contact: shot number, what, figures, frame.

    With ``project`` (3D → pixels of the default view) they are lifted apart so none covers another.
    """
    items: list[tuple[str, str, np.ndarray]] = []
    for s in analysis.shots:
        if s.hit.known:
            speed = "" if not math.isfinite(s.launch_speed_kmh) else f" {s.launch_speed_kmh:.0f} km/h"
            items.append((f"hit{s.index}", f"{s.index}: {'serve' if s.serve else 'hit'} {s.team}{speed} "
                          f"@{s.hit.frame}", np.asarray(s.hit.position, float)))
        calls = {b.frame: b for b in s.bounces}
        for k, c in enumerate(s.contacts):
            if not c.known:
                continue
            if c.event == "ground":
                b = calls.get(c.frame)
                call = b.call if b else "-"
                txt = call if b is None or not math.isfinite(b.distance_cm) else f"{call} {b.distance_cm:+.0f} cm"
                txt = txt if s.has_3d else "no 3D"  # a shot over a failed flight: no call
                anchor = np.array([c.position[0], c.position[1], 0.01])
            else:
                txt, anchor = c.surface, np.asarray(c.position, float)
            items.append((f"s{s.index}c{k}", f"{s.index}: {txt} @{c.frame}", anchor))
    if not items:
        return []
    anchors = np.stack([a for *_, a in items])
    texts = [t for _, t, _ in items]
    lifts = spread_labels(anchors, texts, project) if project is not None else np.full(len(items), 0.2)
    return [ContactLabel(n, t, a, float(h)) for (n, t, a), h in zip(items, lifts)]


def add_contacts(scene, analysis, ball_radius: float, root: str = "/contacts", project=None) -> None:
    """Markers at every hit, bounce and wall contact, with labels (:func:`contact_labels`) that do not overlap
    in the view of ``project`` (3D → pixels; the clip camera)."""
    r = max(ball_radius, DISPLAY_BALL_RADIUS) * 0.8
    for s in analysis.shots:
        if s.hit.known:
            scene.add_icosphere(f"{root}/hit{s.index}", r, TEAM_RGB[s.team], position=tuple(s.hit.position),
                                subdivisions=1)
        calls = {b.frame: b for b in s.bounces}
        for k, c in enumerate(s.contacts):
            if not c.known:
                continue
            name = f"{root}/s{s.index}c{k}"
            if c.event == "ground":
                b = calls.get(c.frame)
                scene.add_cylinder(name, r * 1.6, 0.01, CALL_RGB[b.call if b else "-"],
                                   position=(c.position[0], c.position[1], 0.01))
            else:
                scene.add_icosphere(name, r * 0.8, SURFACE_RGB, position=tuple(c.position), subdivisions=1)
    for lab in contact_labels(analysis, project):
        scene.add_label(f"{root}/labels/{lab.name}", lab.text, position=tuple(lab.anchor + (0.0, 0.0, lab.lift)),
                        anchor="bottom-center", font_screen_scale=0.7)
    for k, b in enumerate(analysis.pre_serve):
        if np.isfinite(b.xy).all():
            scene.add_cylinder(f"{root}/pre{k}", r * 1.6, 0.01, CALL_RGB["-"], position=(b.xy[0], b.xy[1], 0.01))


@dataclass
class BallNodes:
    """The moving parts of one viewer's scene: ball and trail."""

    ball: object
    trail: object


def add_ball(scene, radius: float, root: str = "/live") -> BallNodes:
    """The ball (yellow-green icosphere) and its fading trail, hidden until the first update."""
    ball = scene.add_icosphere(f"{root}/ball", max(radius, DISPLAY_BALL_RADIUS), BALL_RGB, subdivisions=3,
                               visible=False, cast_shadow=False)
    trail = scene.add_line_segments(f"{root}/trail", np.zeros((1, 2, 3)), BALL_RGB, thickness=0.04, visible=False)
    return BallNodes(ball, trail)


def trail_segments(xyz: np.ndarray, bg=(235, 235, 235)) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) path → (K-1, 2, 3) segments and (K-1, 2, 3) uint8 colours fading from ``bg`` (oldest) to the
    ball's colour (newest)."""
    segs = np.stack([xyz[:-1], xyz[1:]], axis=1)
    w = np.linspace(0.0, 1.0, len(xyz))[:, None]
    cols = (np.asarray(bg, float) * (1 - w) + np.asarray(BALL_RGB, float) * w).astype(np.uint8)
    return segs, np.stack([cols[:-1], cols[1:]], axis=1)


def update_ball(nodes: BallNodes, xyz: np.ndarray, trail_xyz: np.ndarray, *, move_ball: bool = True) -> None:
    """Move the ball to ``xyz`` (hidden when NaN) and redraw the trail (only the trail when ``move_ball`` is
    False: the page's player moves the ball with the video frame)."""
    if not move_ball:
        pass
    elif np.isfinite(xyz).all():
        nodes.ball.position = tuple(float(v) for v in xyz)
        nodes.ball.visible = True
    else:
        nodes.ball.visible = False
    if len(trail_xyz) >= 2:
        segs, cols = trail_segments(trail_xyz)
        nodes.trail.points = segs.astype(np.float32)
        nodes.trail.colors = cols
        nodes.trail.visible = True
    else:
        nodes.trail.visible = False


# ------------------------------------------------------------------------------------------- players
class PlayerNodes:
    """Players of one viewer: a box per player at its court position, or a skeleton where 3D joints exist."""

    def __init__(self, scene, root: str = "/live/players"):
        self.scene = scene
        self.root = root
        self.nodes: dict[str, object] = {}

    def update(self, players) -> None:
        seen = set()
        if players is not None:
            for k in range(len(players)):
                pid, team = int(players.player_id[k]), str(players.team[k])
                j3 = players.joints_3d[k]
                if np.isfinite(j3).all(axis=1).sum() >= 8:
                    name = f"{self.root}/skel{pid}"
                    ok = np.isfinite(j3).all(axis=1)
                    bones = np.array([(a, b) for a, b in COCO17_BONES if ok[a] and ok[b]])
                    segs = np.stack([j3[bones[:, 0]], j3[bones[:, 1]]], axis=1).astype(np.float32)
                    node = self.nodes.get(name)
                    if node is None:
                        self.nodes[name] = self.scene.add_line_segments(name, segs, TEAM_RGB.get(team, TEAM_RGB[""]),
                                                                        thickness=0.05)
                    else:
                        node.points = segs
                        node.visible = True
                    seen.add(name)
                elif np.isfinite(players.court_xy[k]).all():
                    name = f"{self.root}/box{pid}"
                    x, y = players.court_xy[k]
                    node = self.nodes.get(name)
                    if node is None:
                        self.nodes[name] = self.scene.add_box(name, TEAM_RGB.get(team, TEAM_RGB[""]),
                                                              dimensions=(0.5, 0.3, 1.8), position=(x, y, 0.9),
                                                              opacity=0.6)
                    else:
                        node.position = (float(x), float(y), 0.9)
                        node.visible = True
                    seen.add(name)
        for name, node in self.nodes.items():
            if name not in seen:
                node.visible = False


# ----------------------------------------------------------------------------------- camera presets
@dataclass(frozen=True)
class CameraPose:
    """A viewer camera: position, look-at point and up vector in court metres, vertical fov (rad)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float = math.radians(50)


def broadcast_pose(camera: Camera, court: Court) -> CameraPose:
    """The clip's own camera (camera.yaml): its centre, optical axis, image-up and vertical field of view."""
    centre = camera.centre
    target_dist = float(np.linalg.norm(np.array([court.size[0] / 2, court.net_y, 0.0]) - centre))
    look = centre + camera.R[2] * target_dist
    up = -camera.R[1]
    fov = 2 * math.atan(camera.image_size[1] / 2 / camera.K[1, 1])
    return CameraPose(tuple(centre), tuple(look), tuple(up), fov)


def camera_presets(camera: Camera, court: Court) -> dict[str, CameraPose]:
    """``broadcast`` (the clip's camera), ``top``, ``behind near team``, ``behind far team``."""
    cx, L = float(court.size[0]) / 2, float(court.size[1])
    mid = (cx, float(court.net_y), 0.0)
    return {
        "broadcast": broadcast_pose(camera, court),
        "top": CameraPose((cx, float(court.net_y) - 0.01, 1.35 * L), mid, (0.0, 1.0, 0.0), math.radians(50)),
        "behind near team": CameraPose((cx, -0.35 * L, 0.3 * L), (cx, 0.6 * L, 0.0)),
        "behind far team": CameraPose((cx, 1.35 * L, 0.3 * L), (cx, 0.4 * L, 0.0)),
    }


def apply_pose(client, pose: CameraPose) -> None:
    """Set a client's camera to ``pose``."""
    with client.atomic():
        client.camera.fov = pose.fov
        client.camera.up_direction = pose.up
        client.camera.position = pose.position
        client.camera.look_at = pose.look_at
