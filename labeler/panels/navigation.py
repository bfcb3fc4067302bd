"""Status line, timeline slider with event/keyframe marks, stepping, play/pause, go-to, undo/redo, mode."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

MODES = ("ball", "stationary", "court")


@dataclass
class NavigationPanel:
    status: Any
    notice: Any
    slider: Any
    steps: Any
    goto: Any
    play: Any
    speed: Any
    history: Any
    mode: Any


def populate_navigation(gui, view) -> NavigationPanel:
    n = view.session.n_frames
    status = gui.add_markdown("")
    notice = gui.add_markdown("")
    slider = gui.add_slider("frame", 0, max(n - 1, 1), 1, 0)
    steps = gui.add_button_group("step", ["|<", "-10", "-1", "+1", "+10", ">|", "unlab."])
    goto = gui.add_number("go to", 0, min=0, max=n - 1, step=1)
    play = gui.add_checkbox("play (space)", False)
    speed = gui.add_slider("speed", 0.1, 2.0, 0.1, 1.0)
    history = gui.add_button_group("history", ["undo", "redo", "fit view"])
    mode = gui.add_dropdown("mode (M)", MODES, initial_value="ball")

    # viser also runs these callbacks when the server sets the value (the status follows the page's frame):
    # only the annotator's own changes navigate, or the page would be sent back to a frame it has left
    slider.on_update(lambda ev: ev.client is not None and view.goto(int(slider.value)))
    goto.on_update(lambda ev: ev.client is not None and view.goto(int(goto.value)))

    def on_step(ev) -> None:
        v = steps.value
        moves = {"-10": -10, "-1": -1, "+1": 1, "+10": 10}
        if v in moves:
            view.step(moves[v])
        elif v == "|<":
            view.goto(0)
        elif v == ">|":
            view.goto(n - 1)
        else:
            view.next_unlabelled()

    steps.on_click(on_step)
    play.on_update(lambda ev: ev.client is not None and view.set_playing(bool(play.value)))
    speed.on_update(lambda ev: ev.client is not None and view.set_speed(float(speed.value)))

    def on_history(ev) -> None:
        {"undo": view.undo, "redo": view.redo, "fit view": view.fit}[history.value]()

    history.on_click(on_history)
    mode.on_update(lambda ev: view.set_mode(str(mode.value)))
    return NavigationPanel(status, notice, slider, steps, goto, play, speed, history, mode)
