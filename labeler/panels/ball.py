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


def populate_ball(gui, view) -> BallPanel:
    info = gui.add_markdown("")
    visibility = gui.add_button_group("ball", ["hard (H)", "occl. (O)", "out (X)", "clear (⌫)"])
    method = gui.add_dropdown("interpolation", ("physics", "linear"), initial_value="physics")
    proposals = gui.add_button_group("proposals", ["interp. (I)", "accept (Y)", "accept all", "reject"])
    trail = gui.add_slider("trail frames", 0, 60, 1, 15)

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
        elif v == "accept all":
            view.accept_range(None, None)
        else:
            view.reject_proposals()

    visibility.on_click(on_visibility)
    proposals.on_click(on_proposals)
    trail.on_update(lambda ev: view.request(overlay=True))
    return BallPanel(info, visibility, method, proposals, trail)
