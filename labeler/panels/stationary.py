"""Stationary (inactive) balls: what a click does in this mode, and removal of a selected ball."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

ACTIONS = ("add", "move selected", "remove nearest")


@dataclass
class StationaryPanel:
    info: Any
    action: Any
    selected: Any
    remove: Any


def populate_stationary(gui, view) -> StationaryPanel:
    info = gui.add_markdown("")
    action = gui.add_dropdown("click does", ACTIONS, initial_value="add")
    selected = gui.add_number("ball no", 0, min=0, step=1)
    remove = gui.add_button("remove ball no from this frame on")
    remove.on_click(lambda ev: view.remove_inactive(int(selected.value)))
    return StationaryPanel(info, action, selected, remove)
