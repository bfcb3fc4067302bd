"""Court points: which named point the next click places, removal, the live calibration's residuals."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class CourtPanel:
    point: Any
    remove: Any
    show: Any
    info: Any


def populate_court(gui, view) -> CourtPanel:
    names = view.session.offered_points() or view.session.court.point_names   # the ones inside the picture
    point = gui.add_dropdown("point", names, initial_value=view.next_court_point() or names[0])
    remove = gui.add_button("remove this point")
    show = gui.add_checkbox("court model in every mode", False)
    info = gui.add_markdown("")
    point.on_update(lambda ev: view.request(overlay=True))
    remove.on_click(lambda ev: view.remove_point(str(point.value)))
    show.on_update(lambda ev: view.request(overlay=True))
    return CourtPanel(point, remove, show, info)
