"""Thin GUI builders of the review (viser ``GuiApi``: ``client.gui`` for one viewer). No state lives here:
each builder returns its handles; the session wires them to its :class:`~labeler.review.playback.Playback`."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .playback import SPEEDS
from .shots import RallyAnalysis, Shot


@dataclass
class PlaybackPanel:
    """Timeline (slider with event marks), play/pause, speed, frame stepping."""

    frame: object
    play: object
    speed: object
    prev: object
    next: object


def populate_playback(gui, first: int, last: int, marks: tuple[tuple[int, str], ...]) -> PlaybackPanel:
    with gui.add_folder("Timeline"):
        frame = gui.add_slider("frame", min=first, max=last, step=1, initial_value=first,
                               marks=marks or None, hint="Event marks: N/F hits by the near/far team, "
                               "• floor bounces, g·… glass, net, mesh")
        play = gui.add_checkbox("play", initial_value=False, hint="play / pause (hotkey P)")
        speed = gui.add_dropdown("speed", tuple(f"{s:g}×" for s in SPEEDS), initial_value="1×")
        group = gui.add_button_group("step", ("◀ −1", "+1 ▶"))
    return PlaybackPanel(frame, play, speed, group, group)


def speed_of(label: str) -> float:
    """``"0.25×"`` → 0.25."""
    return float(label.rstrip("×"))


def populate_cameras(gui, names: list[str]) -> object:
    """One button per camera preset; returns the button group (its value is the preset's name)."""
    with gui.add_folder("Camera presets"):
        return gui.add_button_group("view", tuple(names))


def _fmt(v: float, unit: str, nd: int = 0) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.{nd}f} {unit}"


SHOT_COLUMNS = ("#", "shot", "speed", "net", "bounce (m)", "call", "line")
"""Headers of the per-shot table (GUI Markdown and the exported replay.html)."""


def shot_cells(s: Shot) -> tuple[str, ...]:
    """One shot's cells of the table (:data:`SHOT_COLUMNS`), plain text."""
    b = s.first_bounce
    bounce = "–" if b is None or not np.isfinite(b.xy).all() else f"({b.xy[0]:.2f}, {b.xy[1]:.2f})"
    dist = "–" if b is None or not math.isfinite(b.distance_cm) else f"{b.distance_cm:+.0f} cm {b.line}"
    kind = "serve" if s.serve else "shot"
    return (str(s.index), f"{s.team} {kind} @{s.hit.frame}", _fmt(s.launch_speed_kmh, "km/h"),
            _fmt(s.net_clearance_m, "m", 2), bounce, s.verdict, dist)


def shot_line(s: Shot) -> str:
    """One markdown table row of a shot (the call in bold)."""
    cells = list(shot_cells(s))
    cells[5] = f"**{cells[5]}**"
    return "| " + " | ".join(cells) + " |"


def shots_markdown(analysis: RallyAnalysis) -> str:
    """The per-shot table: speed, net clearance, first bounce, call and distance to the nearest line."""
    head = "| " + " | ".join(SHOT_COLUMNS) + " |\n" + "|---" * len(SHOT_COLUMNS) + "|\n"
    return head + "\n".join(shot_line(s) for s in analysis.shots) if analysis.shots else "No racket hits in events.csv."


def current_shot_markdown(analysis: RallyAnalysis, frame: int) -> str:
    """What is happening at ``frame``: the shot in flight, its contacts so far and its call."""
    s = analysis.shot_at(frame)
    if s is None:
        return f"**frame {frame}** — before the first hit"
    lines = [f"**frame {frame}** — shot {s.index}: {s.team} {'serve' if s.serve else 'shot'}, "
             f"{_fmt(s.launch_speed_kmh, 'km/h')}, max {_fmt(s.max_speed_kmh, 'km/h')}, "
             f"net clearance {_fmt(s.net_clearance_m, 'm', 2)}"]
    for b in s.bounces:
        if b.frame <= frame:
            d = "" if not math.isfinite(b.distance_cm) else f" {b.distance_cm:+.0f} cm ({b.line})"
            lines.append(f"- bounce @{b.frame}: **{b.call}**{d}")
    if frame >= max([s.hit.frame, *(c.frame for c in s.contacts)]):
        lines.append(f"- verdict: **{s.verdict}** — {s.reason}")
    return "\n".join(lines)


VIDEO_PANEL_WIDTH = 640
"""Width (px) of the video panel docked at the left edge of the page, beside the 3D view."""


@dataclass
class InfoPanel:
    video: object
    frame: object
    current: object
    table: object


def populate_info(gui, first_image: np.ndarray, analysis: RallyAnalysis, summary: dict) -> InfoPanel:
    """The video (with the reprojection, in a panel docked left of the 3D view) and the shot panel."""
    video_panel = gui.add_panel()
    with video_panel.add_tab("Video (reprojection drawn)"):
        frame = gui.add_markdown("")
        video = gui.add_image(first_image, format="jpeg", jpeg_quality=80)
    video_panel.dock_left()
    video_panel.set_width(VIDEO_PANEL_WIDTH)
    with gui.add_folder("Shots"):
        current = gui.add_markdown("")
        table = gui.add_markdown(shots_markdown(analysis))
        rms = summary.get("reprojection_rms_px")
        gui.add_markdown(f"{summary['shots']} shots, {summary['reconstructed']} reconstructed frames"
                         + (f", reprojection RMS {rms} px" if rms is not None else "")
                         + (f", method {summary['method']}" if summary.get("method") else ""))
    return InfoPanel(video, frame, current, table)


def populate_export(gui) -> tuple[object, object]:
    """Download buttons: the replay (.viser) and the per-shot CSV."""
    with gui.add_folder("Export", expand_by_default=False):
        replay = gui.add_button("download replay (.viser)")
        table = gui.add_button("download shots (.csv)")
    return replay, table
