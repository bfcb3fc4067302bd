"""What the court allows, checked on a fitted rally: per-flight checks and the clip-level plausibility
summary written to segments.json.

A flight is *plausible* when its reprojection RMS is at most ``rms_fail_factor`` × the 2D noise, no frame
or contact of it lies more than 5 cm below the floor or behind a glass/mesh patch (padel's enclosure; the
open sides and the space above the walls are allowed) and it does not pass through the net without a net
event. An implausible flight is reported failed with its reason, never as reconstructed.

Example:
    >>> fit = reconstruct(obs)
    >>> fit.extra["plausibility"]        # {"plausible": True, "frames_inside_court": 1.0, ...}
"""
from __future__ import annotations

from collections import Counter

import numpy as np

from inference.court import Court

from .observations import Observations
from .results import RallyFit, SegmentFit

#: how deep (m) a frame may sink into the floor or a wall before the flight is implausible
PENETRATION_LIMIT_M = 0.05
#: tolerance (m) of the clip-level "inside the court" figure
INSIDE_TOLERANCE_M = 0.02


def court_walls(court: Court) -> list:
    """The surfaces the ball cannot pass through besides the floor: glass and mesh patches."""
    return [p for p in court.planes if not p.two_sided and p.event != "ground" and p.material in ("glass", "mesh")]


def penetration(court: Court, xyz: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """(M,) how deep (m, ≥ 0) each ball centre sinks below the floor or behind a wall patch (the ball's
    radius included), and the name of the surface for each (empty where none)."""
    r = court.ball.radius
    depth = np.maximum(r - xyz[:, 2], 0.0)
    where = np.where(depth > 0, "floor", "").astype(object)
    for wall in court_walls(court):
        d = np.maximum(r - (xyz - wall.origin) @ wall.normal, 0.0)
        d = np.where(wall.contains(xyz, tol=0.05), d, 0.0)
        deeper = d > depth
        depth = np.where(deeper, d, depth)
        where = np.where(deeper, wall.name, where)
    return depth, [str(w) for w in where]


def implausible(fit: SegmentFit, court: Court, rms_limit_px: float) -> str:
    """Why a reconstructed flight is physically impossible or does not explain its 2D track (empty when
    it is plausible): reprojection RMS above ``rms_limit_px``, a frame or a contact more than 5 cm below the
    floor or behind a glass/mesh patch, a pass through the net without a net event."""
    reasons = []
    if np.isfinite(fit.reproj_rms_px) and fit.reproj_rms_px > rms_limit_px:
        reasons.append(f"reprojection RMS {fit.reproj_rms_px:.1f} px > {rms_limit_px:g} px (the 2D track is not "
                       "one flight between these contacts: a missed or wrong event?)")
    pts = np.vstack([fit.xyz] + [p[None] for p in (fit.start, fit.end) if p is not None])
    depth, where = penetration(court, pts)
    k = int(np.argmax(depth)) if len(depth) else 0
    if len(depth) and depth[k] > PENETRATION_LIMIT_M:
        at = f"frame {fit.frames[k]}" if k < len(fit.frames) else "its contact"
        reasons.append(f"passes {depth[k]:.2f} m {'below the floor' if where[k] == 'floor' else 'behind the ' + where[k]}"
                       f" at {at}")
    if "net" not in (fit.segment.start_event, fit.segment.end_event):
        clearance = _net_clearance(court, fit.xyz)
        if clearance < -PENETRATION_LIMIT_M:
            reasons.append(f"passes through the net ({-clearance:.2f} m below its top)")
    return "; ".join(reasons)


def _net_clearance(court: Court, xyz: np.ndarray) -> float:
    from .joint import net_height  # joint imports this module

    nets = [p for p in court.planes if p.event == "net"]
    if not nets or len(xyz) < 2:
        return float("inf")
    net = nets[0]
    d = (xyz - net.origin) @ net.normal
    cross = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
    if not len(cross):
        return float("inf")
    k = int(cross[0])
    f = d[k] / (d[k] - d[k + 1])
    p = xyz[k] + f * (xyz[k + 1] - xyz[k])
    x = (p - net.origin) @ net.u
    if x < net.polygon[:, 0].min() or x > net.polygon[:, 0].max():
        return float("inf")                       # beside the net posts
    return float(p[2] - court.ball.radius - net_height(net, p))


# ---------------------------------------------------------------------------------------------------
# The clip-level summary
# ---------------------------------------------------------------------------------------------------
def summary(fit: RallyFit, obs: Observations, rms_limit_px: float | None = None) -> dict:
    """Clip-level plausibility of a reconstruction (segments.json's ``plausibility``): flights reconstructed
    and failed (with reasons), the share of frames inside the court, contacts below the floor, the worst
    reprojection RMS, flagged contacts, and ``plausible`` when nothing is off."""
    court = obs.court
    ok = [s for s in fit.segments if s.ok]
    b = fit.ball_3d()
    inside = 1.0
    if len(b):
        depth, _ = penetration(court, b.xyz)
        inside = float(np.mean(depth <= INSIDE_TOLERANCE_M))
    r = court.ball.radius
    contacts = [p for s in ok for p in (s.start, s.end) if p is not None]
    below = int(sum(float(p[2]) < r - INSIDE_TOLERANCE_M for p in contacts))
    rms = [s.reproj_rms_px for s in ok if np.isfinite(s.reproj_rms_px)]
    over = int(sum(x > rms_limit_px for x in rms)) if rms_limit_px else 0
    flags = [f for s in ok for f in s.figures.get("flags", [])]
    reasons = Counter(s.reason for s in fit.segments if not s.ok)
    out = {
        "flights": len(fit.segments), "reconstructed": len(ok), "failed": len(fit.segments) - len(ok),
        "failure_reasons": dict(reasons), "frames": len(b), "frames_inside_court": round(inside, 4),
        "contacts_below_floor": below, "max_reprojection_rms_px": round(max(rms), 2) if rms else None,
        "flags": flags,
    }
    if rms_limit_px:
        out["flights_over_rms_limit"] = over
    out["plausible"] = bool(ok) and inside >= 0.98 and below == 0 and over == 0
    return out
