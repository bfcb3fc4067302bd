"""The events and 3D stages over the court-view scenes of a broadcast clip (``scenes.json``).

Across a cut the time is not continuous (a replay or a close-up sits between two court views), so each
court-view scene is handled as a clip of its own — its ball track, events and players cut out and renumbered
from 0 (:func:`inference.video.scenes.scene_rows`) — and the results are put back at the scene's frames. Frames
outside court views get no events and no 3D (segments.json's ``scenes`` says why).

Example:
    >>> result = events_per_scene(detector, ball, spans, n_frames, fps, width, height)
    >>> fit = reconstruct_per_scene(obs, spans, "joint")
"""
from __future__ import annotations

import dataclasses

import numpy as np

from inference.clipio import BallTrack, HitEvents
from inference.video.scenes import scene_rows

#: segments.json's reason for frames outside the court views
LEFT_OUT = "not reconstructed: outside a court view (a replay, close-up or other camera; scenes.json)"


class SceneFrames:
    """Frames ``start .. stop-1`` of a frame source, numbered from 0 (what a crop event model reads)."""

    def __init__(self, source, start: int, stop: int):
        self.source, self.start, self.stop = source, start, stop

    def __len__(self) -> int:
        return self.stop - self.start

    def iter(self, first: int = 0, last: int | None = None):
        last = len(self) if last is None else min(int(last), len(self))
        return self.source.iter(self.start + first, self.start + last)

    def read(self, i: int) -> np.ndarray:
        return self.source.read(self.start + int(i))


def events_per_scene(det, ball: BallTrack, spans: list[tuple[int, int]], n_frames: int, fps: float, width: int,
                    height: int, *, camera=None, players=None, frames=None, keep_all: bool = True):
    """:meth:`EventDetector.predict` on each court-view scene ``(start, stop)`` of ``spans``, the events put
    back at clip frames; the point (rally.yaml) is segmented once over the whole clip from all the events.

    Returns:
        an :class:`~inference.events.detector.EventResult` for the clip: ``probs`` (n_frames, C) is the
        background class outside the court views.
    """
    from inference.events.detector import EventResult
    from inference.events.features import dense_xy
    from inference.events.rally import segment_rally

    C = det.class_set.n
    probs = np.zeros((n_frames, C))
    probs[:, 0] = 1.0
    ev_f, ev_l, coarse, sigma, conf, quiets = [], [], [], [], [], []
    for a, b in spans:
        sub = scene_rows(ball, a, b)
        if not np.any(sub.visibility > 0):  # no ball in this view: nothing to decode
            continue
        r = det.predict(sub, fps, width, height, camera=camera,
                        players=scene_rows(players, a, b) if players is not None else None,
                        frames=SceneFrames(frames, a, b) if frames is not None else None, n_frames=b - a)
        probs[a:b] = r.probs
        ev_f.append(r.events.frame + a)
        ev_l.append(r.events.event)
        coarse += list(r.coarse)
        sigma.append(r.uncertainty)
        conf.append(r.confidence)
        quiets.append(tuple((qa + a, qb + a) for qa, qb in r.quiet))
    frame = np.concatenate(ev_f).astype(np.int64) if ev_f else np.zeros(0, np.int64)
    label = np.concatenate(ev_l) if ev_l else np.zeros(0, str)
    unc = np.concatenate(sigma) if sigma else np.zeros(0)
    cf = np.concatenate(conf) if conf else np.zeros(0)
    xy = dense_xy(ball, n_frames)
    off = np.ones(n_frames, bool)
    for a, b in spans:
        off[a:b] = False
    xy[off] = np.nan
    seg = segment_rally(xy, fps, frame, label, hits=det.class_set.rules.hits, aspect=width / height,
                        params=det.rally_params())
    outside = HitEvents(frame[~seg.inside], label[~seg.inside])
    keep = np.ones(len(frame), bool) if keep_all else seg.inside
    quiet = tuple(q for r in quiets for q in r)
    return EventResult(HitEvents(frame[keep], label[keep]), probs, det.class_set.classes,
                       tuple(c for c, k in zip(coarse, keep) if k), seg, outside, unc[keep], cf[keep], quiet)


def reconstruct_per_scene(obs, spans: list[tuple[int, int]], method: str, n_frames: int | None = None):
    """:func:`inference.reconstruct.api.reconstruct` on each court-view scene of ``spans`` on its own; the
    flights come back at clip frames (a flight's ``index`` stays that of the clip's event it starts from, so
    the run-out of one scene and the run-in of the next share the index of the flight the cut broke).

    Returns:
        a :class:`~inference.reconstruct.results.RallyFit` whose ``extra["scenes"]`` lists every scene (court
        view or not, flights, reason when none) and whose plausibility covers the whole clip.
    """
    from inference.reconstruct.api import reconstruct
    from inference.reconstruct.observations import Observations
    from inference.reconstruct.plausibility import summary
    from inference.reconstruct.results import RallyFit

    n_frames = obs.n_frames if n_frames is None else n_frames
    segs, scenes, iterations, refits = [], [], [], []
    seconds = cpu = 0.0
    for a, b in spans:
        m = (obs.event_frames >= a) & (obs.event_frames < b)
        first = int(np.sum(obs.event_frames < a))  # the clip's index of the scene's first event
        entry = {"start_frame": a, "end_frame": b - 1, "court_view": True, "events": int(m.sum())}
        scenes.append(entry)
        if not m.any():
            entry.update(flights=0, reason="no events in this scene: nothing anchors a flight")
            continue
        sub = Observations(obs.court, obs.camera, obs.fps, obs.uv[a:b], obs.event_frames[m] - a,
                           [lab for lab, k in zip(obs.event_labels, m) if k],
                           scene_rows(obs.players, a, b) if obs.players is not None else None, obs.source,
                           obs.pixel_sigma)
        fit = reconstruct(sub, method)
        for s in fit.segments:
            seg = dataclasses.replace(s.segment, index=s.segment.index + first, start=s.segment.start + a,
                                      end=s.segment.end + a)
            segs.append(dataclasses.replace(s, segment=seg, frames=s.frames + a))
        entry.update(flights=len(fit.segments), reconstructed=sum(s.ok for s in fit.segments))
        if not fit.segments:
            entry["reason"] = f"{int(m.sum())} event(s) in this scene: no flight between two events"
        seconds += fit.seconds
        cpu += fit.cpu_seconds or 0.0
        iterations += fit.extra.get("iterations", [])
        refits += [f"frames {a}–{b - 1}: {n}" for n in fit.extra.get("refits", [])]
    court = {a for a, _ in spans}
    edges = sorted({0, n_frames, *[x for s in spans for x in s]})
    for a, b in zip(edges[:-1], edges[1:]):
        if a not in court:
            n_ev = int(np.sum((obs.event_frames >= a) & (obs.event_frames < b)))
            scenes.append({"start_frame": a, "end_frame": b - 1, "court_view": False, "events": n_ev, "flights": 0,
                           "reason": LEFT_OUT})
    scenes.sort(key=lambda e: e["start_frame"])
    out = RallyFit(method, obs.fps, segs, seconds, cpu_seconds=cpu,
                   extra={"scenes": scenes, **({"iterations": iterations} if iterations else {}),
                          **({"refits": refits} if refits else {})})
    out.extra["plausibility"] = summary(out, obs, _rms_limit(method, obs))
    return out


def _rms_limit(method: str, obs) -> float | None:
    """The RMS (px) above which the method fails a flight (the joint fit's, with the clip's measured 2D
    noise), for the clip's plausibility."""
    if method != "joint":
        return None
    from inference.reconstruct.joint import JointConfig

    cfg = JointConfig()
    return cfg.rms_fail_factor * max(cfg.pixel_sigma, obs.pixel_sigma or 0.0)
