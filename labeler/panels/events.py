"""Hit events: one button per event of the clip's sport (hotkeys 1–9), remove (0), previous/next event (K)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class EventsPanel:
    info: Any
    labels: Any
    nav: Any


def populate_events(gui, view) -> EventsPanel:
    names = view.session.event_labels
    info = gui.add_markdown("")
    labels = gui.add_button_group("event", [f"{i + 1} {e}" for i, e in enumerate(names[:9])] + ["0 none"])
    nav = gui.add_button_group("jump", ["prev event", "next event"])

    def on_label(ev) -> None:
        key = int(labels.value.split()[0])
        view.event_key(key)

    labels.on_click(on_label)
    nav.on_click(lambda ev: view.jump_event(1 if nav.value.startswith("next") else -1))
    return EventsPanel(info, labels, nav)
