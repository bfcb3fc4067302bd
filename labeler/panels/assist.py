"""Model-assisted labelling: run a detector checkpoint over the clip in the background, then accept or reject."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class AssistPanel:
    weights: Any
    run: Any
    progress: Any
    info: Any
    start: Any
    stop: Any
    accept: Any
    events: Any


def populate_assist(gui, view) -> AssistPanel:
    n = view.session.n_frames
    weights = gui.add_text("checkpoint", "", hint="empty: the shipped WASB padel weights")
    run = gui.add_button("run ball detector")
    progress = gui.add_progress_bar(0.0, visible=False)
    info = gui.add_markdown("")
    start = gui.add_number("from frame", 0, min=0, max=n - 1, step=1)
    stop = gui.add_number("to frame", n - 1, min=0, max=n - 1, step=1)
    accept = gui.add_button_group("proposals in range", ["accept", "accept (overwrite)", "reject"])
    events = gui.add_button_group("hit events", ["propose events", "accept events"])

    run.on_click(lambda ev: view.run_detector(weights.value.strip() or None))

    def on_accept(ev) -> None:
        a, b = int(start.value), int(stop.value)
        if accept.value == "reject":
            view.reject_proposals(range(a, b + 1))
        else:
            view.accept_range(a, b, overwrite=accept.value.endswith("(overwrite)"))

    accept.on_click(on_accept)
    events.on_click(lambda ev: view.propose_events() if events.value.startswith("propose") else view.accept_events())
    return AssistPanel(weights, run, progress, info, start, stop, accept, events)
