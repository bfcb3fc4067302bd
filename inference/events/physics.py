"""A physics-aware hit-event detector without learning: kinks and speed jumps of the 2D track.

At every (reference-rate) frame the incoming and outgoing image velocities over ``span`` frames give
a *kink* score ``|v_out − v_in| / (|v_in| + |v_out|)`` in ``[0, 1]`` (0 on a straight, uniform path).
Each kink is assigned one class:

- a racket hit when the speed grows by ``hit_ratio`` or more (a racket adds energy, a bounce takes it):
  the near team sends the ball up the image (away from the camera), the far team down it;
- ``net`` when the speed falls below ``net_ratio`` of the incoming speed close to the net's image line;
- a bounce otherwise: ``wall_near`` when a ray through the ball can reach the near glass (the camera ray
  meets the plane of the near back wall inside the glass) and the ball turned back up the image;
  else the grouped floor / other-wall class.

The class's "probability" is the kink score; the decoder of :mod:`.decode` then picks events as for
the learned models. Parameters are tuned on validation data like the learned models' thresholds.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .classes import ClassSet


@dataclass(frozen=True)
class PhysicsParams:
    span: int = 3
    hit_ratio: float = 1.25
    net_ratio: float = 0.45
    net_band: float = 0.04
    min_speed: float = 1e-4

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _velocities(xy: np.ndarray, span: int) -> tuple[np.ndarray, np.ndarray]:
    """Incoming and outgoing mean velocities ``(T, 2)`` (NaN where the span is not fully known)."""
    T = len(xy)
    v_in = np.full((T, 2), np.nan)
    v_out = np.full((T, 2), np.nan)
    if T > span:
        v_in[span:] = (xy[span:] - xy[:-span]) / span
        v_out[:-span] = (xy[span:] - xy[:-span]) / span
    return v_in, v_out


def net_line_v(camera, court, u: np.ndarray) -> np.ndarray:
    """Image ``v`` of the net's foot line at image columns ``u`` (0.5 without a camera)."""
    if camera is None or court is None or "net_left" not in court.points:
        return np.full(len(u), 0.5)
    a, b = camera.project_normalized(court.point_array(["net_left", "net_right"]))
    if abs(b[0] - a[0]) < 1e-9:
        return np.full(len(u), 0.5 * (a[1] + b[1]))
    return a[1] + (u - a[0]) * (b[1] - a[1]) / (b[0] - a[0])


def near_glass_reachable(camera, court, uv: np.ndarray) -> np.ndarray:
    """``(N,) bool``: the line of sight through ``uv`` meets a plane labelled ``wall_near`` within its
    extent (False without a camera or for a court without one)."""
    if camera is None or court is None or not court.planes_for("wall_near"):
        return np.zeros(len(uv), bool)
    from inference.court.geometry import intersect_event

    ok = np.isfinite(uv).all(axis=1)
    out = np.zeros(len(uv), bool)
    if ok.any():
        o, d = camera.rays_normalized(uv[ok])
        out[ok] = intersect_event(o, d, court, "wall_near", offset=court.ball.radius).valid
    return out


def physics_probs(xy: np.ndarray, class_set: ClassSet, params: PhysicsParams, *, camera=None,
                  court=None) -> np.ndarray:
    """``(T, 2)`` positions (NaN missing) at the reference rate → ``(T, C)`` class scores."""
    T = len(xy)
    v_in, v_out = _velocities(xy, params.span)
    s_in, s_out = np.linalg.norm(v_in, axis=1), np.linalg.norm(v_out, axis=1)
    ok = np.isfinite(s_in) & np.isfinite(s_out) & ((s_in + s_out) > params.min_speed)
    kink = np.zeros(T)
    kink[ok] = np.linalg.norm(v_out[ok] - v_in[ok], axis=1) / (s_in[ok] + s_out[ok])
    ratio = np.where(ok, s_out / np.maximum(s_in, 1e-9), 1.0)
    probs = np.zeros((T, class_set.n))
    names = class_set.classes
    hit_near, hit_far = class_set.rules.hits
    bounce = next((c for c in names[1:] if c not in (hit_near, hit_far, "net", "wall_near")), None)
    u = np.nan_to_num(xy[:, 0], nan=0.5)
    near_net = np.abs(np.nan_to_num(xy[:, 1], nan=-1.0) - net_line_v(camera, court, u)) < params.net_band
    reach = near_glass_reachable(camera, court, xy)
    turned_up = np.nan_to_num(v_in[:, 1]) > 0
    turned_up &= np.nan_to_num(v_out[:, 1]) < 0
    for t in np.flatnonzero(ok):
        if ratio[t] >= params.hit_ratio:
            c = hit_near if v_out[t, 1] < 0 else hit_far
        elif "net" in names and ratio[t] <= params.net_ratio and near_net[t]:
            c = "net"
        elif "wall_near" in names and reach[t] and turned_up[t]:
            c = "wall_near"
        elif bounce is not None:
            c = bounce
        else:
            continue
        probs[t, names.index(c)] = kink[t]
    probs[:, 0] = 1.0 - probs[:, 1:].sum(axis=1)
    return probs
