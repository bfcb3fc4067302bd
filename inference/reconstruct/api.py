"""One entry point for every reconstruction method, plus the per-shot figures every method reports."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from inference.court import Court

from .observations import Observations
from .plausibility import net_clearance, summary
from .results import RallyFit, SegmentFit

#: The default and the four published methods, in the order of the thesis's tables.
METHOD_NAMES = ("gravity", "drag_shooting", "reprojection", "players", "joint")
DEFAULT_METHOD = "joint"


def methods() -> dict[str, Callable[[Observations], RallyFit]]:
    """Method name → ``fn(obs) -> RallyFit``."""
    from .baselines import fit_rally
    from .joint import fit_joint  # here: the CLI reads METHOD_NAMES without loading scipy

    out: dict[str, Callable[[Observations], RallyFit]] = {
        name: (lambda obs, _n=name: fit_rally(obs, _n)) for name in METHOD_NAMES if name != "joint"}
    out["joint"] = fit_joint
    return out


def reconstruct(obs: Observations, method: str = DEFAULT_METHOD) -> RallyFit:
    """Reconstruct a rally with ``method`` (see :data:`METHOD_NAMES`) and add the per-shot figures."""
    table = methods()
    if method not in table:
        raise ValueError(f"unknown reconstruction method {method!r}; choose one of {', '.join(METHOD_NAMES)}")
    fit = table[method](obs)
    for seg in fit.segments:
        if seg.ok:
            seg.figures.update(shot_figures(seg, obs.court, obs.fps))
    if "plausibility" not in fit.extra:
        fit.extra["plausibility"] = summary(fit, obs)
    return fit


def shot_figures(seg: SegmentFit, court: Court, fps: float) -> dict:
    """Net clearance (m, where the flight crosses the net plane); for a flight ending on the floor, the
    bounce position (m) and the speed at the bounce (km/h)."""
    out: dict = {}
    clearance = net_clearance(court, seg.xyz, beside_ok=False)
    if np.isfinite(clearance):
        out["net_clearance_m"] = round(clearance, 3)
    if seg.end_plane is not None and seg.end is not None:
        plane = court.plane(seg.end_plane)
        if plane.event == "ground":
            out["bounce_position_m"] = [round(float(v), 3) for v in seg.end[:2]]
            speed = np.linalg.norm(seg.xyz[-1] - seg.xyz[-2]) * fps if len(seg.xyz) > 1 else np.nan
            out["bounce_speed_kmh"] = round(float(speed) * 3.6, 1)
    return out
