"""Ball mode: visibility keys, clear, keyframe interpolation (linear / physics) and its acceptance, trail."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class BallPanel:
    info: Any
    visibility: Any
    method: Any
    proposals: Any
    trail: Any
    max_gap: Any
    follow: Any
    zoom: Any


def populate_ball(gui, view) -> BallPanel:
    info = gui.add_markdown("")
    visibility = gui.add_button_group("ball", ["hard (H)", "occl. (O)", "out (X)", "clear (⌫)"])
    method = gui.add_dropdown("interpolation", ("physics", "linear"), initial_value="physics")
    max_gap = gui.add_number("max gap (frames)", view.session.max_gap, min=2, max=view.session.n_frames, step=1,
                             hint="interpolation never fills a longer gap between keyframes (nor across an event)")
    proposals = gui.add_button_group("proposals", ["interp. (I)", "accept (Y)", "flight (⇧Y)", "reject"])
    trail = gui.add_slider("trail frames", 0, 60, 1, 15)
    follow = gui.add_checkbox("follow the ball (G)", False, hint="keep the ball centred, zoomed in")
    zoom = gui.add_slider("follow zoom", 1.0, 8.0, 0.5, 3.0)

    def on_visibility(ev) -> None:
        v = visibility.value
        if v.startswith("clear"):
            view.clear_ball()
        else:
            view.set_visibility({"hard": 2, "occl.": 3, "out": 0}[v.split()[0]])

    def on_proposals(ev) -> None:
        v = proposals.value
        if v.startswith("interp"):
            view.interpolate()
        elif v.startswith("accept ("):
            view.accept_here()
        elif v.startswith("flight"):
            view.accept_flight()
        else:
            view.reject_proposals()

    visibility.on_click(on_visibility)
    proposals.on_click(on_proposals)
    trail.on_update(lambda ev: view.request(overlay=True))
    follow.on_update(lambda ev: view.follow != bool(follow.value) and view.toggle_follow())
    zoom.on_update(lambda ev: view.request(overlay=True))
    return BallPanel(info, visibility, method, proposals, trail, max_gap, follow, zoom)
