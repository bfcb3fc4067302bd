"""Thin GUI builders of the review (viser ``GuiApi``: ``client.gui`` for one viewer). No state lives here:
each builder returns its handles; the session wires them to its :class:`~labeler.review.playback.Playback`.

viser renders Markdown's raw HTML unsanitised: every file-derived string goes through :func:`md_text`."""
from __future__ import annotations

import html
import math
import re
from dataclasses import dataclass

import numpy as np

from .playback import SPEEDS
from .shots import Plausibility, RallyAnalysis, Shot, sigma_note


def md_text(text: str) -> str:
    """Plain text made safe inside viser Markdown (and its tables): HTML-escaped, Markdown marks escaped."""
    return re.sub(r"([\\`*_\[\]{}|#~>!-])", r"\\\1", html.escape(str(text), quote=False))


BANNER_STYLE = {"bad": "background:#ffd7d2;border:2px solid #c62828;color:#5a0000",
                "ok": "background:#e8f5e9;border:1px solid #8bc48f;color:#1b4d20"}


def banner_html(plausibility: Plausibility | None) -> str:
    """The 3D status as a coloured HTML block (:meth:`Plausibility.lines`, escaped): red when the clip is not
    plausible or not judged, green when it passed; "" without a check."""
    if plausibility is None:
        return ""
    kind = "ok" if plausibility.judged and plausibility.plausible else "bad"
    lines = plausibility.lines()
    head = f"<b>{html.escape(lines[0])}</b>"
    rest = "".join(f"<br>{html.escape(t)}" for t in lines[1:])
    return (f'<div class="rally3d-banner {kind}" role="{"alert" if kind == "bad" else "status"}" '
            f'style="{BANNER_STYLE[kind]};padding:6px 8px;border-radius:4px;font-size:0.9em">'
            f"{head}{rest}</div>")


def populate_banner(gui, plausibility: Plausibility | None) -> object | None:
    """The 3D status banner, the first thing in the panel (:func:`banner_html`); None without a check."""
    content = banner_html(plausibility)
    return gui.add_html(content) if content else None


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


SHOT_COLUMNS = ("#", "shot", "speed", "net", "bounce (m)", "call", "line", "note")
"""Headers of the per-shot table (GUI Markdown and the exported replay.html). ``note``: ``no 3D: <why>`` for a
shot without trustworthy 3D, else the first bounce's uncertainty (``within 2σ (±4 cm): too close to call``,
``±3 cm at 2σ``, ``σ unknown``)."""


def shot_cells(s: Shot) -> tuple[str, ...]:
    """One shot's cells of the table (:data:`SHOT_COLUMNS`), plain text (escape it for HTML/Markdown)."""
    b = s.first_bounce if s.has_3d else None
    bounce = "–" if b is None or not np.isfinite(b.xy).all() else f"({b.xy[0]:.2f}, {b.xy[1]:.2f})"
    dist = "–" if b is None or not b.judged else f"{b.distance_cm:+.0f} cm {b.line}"
    note = s.reason if not s.has_3d else ("" if b is None else sigma_note(b))
    kind = "serve" if s.serve else "shot"
    return (str(s.index), f"{s.team} {kind} @{s.hit.frame}", _fmt(s.launch_speed_kmh, "km/h"),
            _fmt(s.net_clearance_m, "m", 2), bounce, s.verdict, dist, note)


def shot_line(s: Shot) -> str:
    """One markdown table row of a shot (the call in bold; text escaped)."""
    cells = [md_text(c) for c in shot_cells(s)]
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
    kind = "serve" if s.serve else "shot"
    if not s.has_3d:
        return f"**frame {frame}** — shot {s.index}: {s.team} {kind}, {md_text(s.reason)}"
    lines = [f"**frame {frame}** — shot {s.index}: {s.team} {kind}, "
             f"{_fmt(s.launch_speed_kmh, 'km/h')}, max {_fmt(s.max_speed_kmh, 'km/h')}, "
             f"net clearance {_fmt(s.net_clearance_m, 'm', 2)}"]
    for b in s.bounces:
        if b.frame <= frame:
            d = "" if not b.judged else f" {b.distance_cm:+.0f} cm ({b.line}), {sigma_note(b)}"
            lines.append(f"- bounce @{b.frame}: **{b.call}**{md_text(d)}")
    if frame >= max([s.hit.frame, *(c.frame for c in s.contacts)]):
        lines.append(f"- verdict: **{s.verdict}** — {md_text(s.reason)}")
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
