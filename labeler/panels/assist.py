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
    uncertain = gui.add_button("next uncertain frame (U)")
    events = gui.add_button_group("hit events", ["propose events", "next (P)", "accept here (V)", "accept all"])

    run.on_click(lambda ev: view.run_detector(weights.value.strip() or None))

    def on_accept(ev) -> None:
        a, b = int(start.value), int(stop.value)
        if accept.value == "reject":
            view.reject_proposals(range(a, b + 1))
        else:
            view.accept_range(a, b, overwrite=accept.value.endswith("(overwrite)"))

    accept.on_click(on_accept)
    uncertain.on_click(lambda ev: view.next_uncertain())

    def on_events(ev) -> None:
        v = events.value
        if v.startswith("propose"):
            view.propose_events()
        elif v.startswith("next"):
            view.jump_proposed_event()
        elif v.startswith("accept here"):
            view.accept_event_here()
        else:
            view.accept_events()

    events.on_click(on_events)
    return AssistPanel(weights, run, progress, info, start, stop, accept, events)
