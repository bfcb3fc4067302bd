"""Keyboard behaviour of the labeler page that viser does not give: a small script sent to each tab.

viser only delivers hotkeys while no input field has focus, and its dropdown keeps typed text without
selecting anything on Enter. This script (our own code, never built from file contents) makes the keyboard
work as in CVAT:

- Enter or Escape in any field (go-to, numbers, text, dropdown) leaves it, so the next key is a hotkey again;
- in a dropdown, focusing selects its text (typing replaces it) and Enter picks the option that matches what
  was typed (exactly, the only one left, or the first that starts with it);
- ``?`` outside a field clicks the GUI's "shortcuts (?)" button, which opens the cheat-sheet;
- :func:`show_tab` brings a panel tab to the front (viser's tab groups cannot be switched from Python): a
  mode change by key shows the mode's tab.

Sent with viser's ``RunJavascriptMessage`` (the mechanism viser itself uses to load plotly.js).
"""
from __future__ import annotations

SHORTCUTS_BUTTON = "shortcuts (?)"
"""Label of the GUI button that opens the cheat-sheet (the script clicks it on ``?``)."""

KEYBOARD_JS = """
(function () {
  if (window.__rally3dKeyboard) return;
  window.__rally3dKeyboard = true;
  const isField = (t) => t instanceof HTMLElement &&
    (t.tagName === "INPUT" || t.tagName === "TEXTAREA" || t.isContentEditable);
  const isCombo = (t) => t instanceof HTMLInputElement && t.getAttribute("role") === "combobox";
  document.addEventListener("focusin", (ev) => {
    if (isCombo(ev.target)) setTimeout(() => ev.target.select(), 0);
  }, true);
  document.addEventListener("keydown", (ev) => {
    const t = ev.target;
    if (!isField(t)) {
      if (ev.key === "?" && !ev.ctrlKey && !ev.metaKey && !ev.altKey) {
        const button = Array.from(document.querySelectorAll("button"))
          .find((b) => (b.textContent || "").trim() === "__BUTTON__");
        if (button) { ev.preventDefault(); button.click(); }
      }
      return;
    }
    if (ev.key !== "Enter" && ev.key !== "Escape") return;
    if (ev.key === "Enter" && isCombo(t)) {
      const typed = (t.value || "").trim().toLowerCase();
      const listId = t.getAttribute("aria-controls");
      const list = listId ? document.getElementById(listId) : null;
      const opts = list ? Array.from(list.querySelectorAll('[role="option"]')) : [];
      const text = (o) => (o.textContent || "").trim().toLowerCase();
      const pick = opts.find((o) => text(o) === typed) || (opts.length === 1 ? opts[0] : null) ||
        opts.find((o) => typed && text(o).startsWith(typed));
      if (pick) { ev.preventDefault(); ev.stopPropagation(); pick.click(); }
    }
    setTimeout(() => t.blur(), 0);
  }, true);
})();
""".replace("__BUTTON__", SHORTCUTS_BUTTON)


def install_keyboard(client) -> None:
    """Send :data:`KEYBOARD_JS` to one viser client (idempotent in the page)."""
    from viser import _messages

    client.gui._websock_interface.queue_message(_messages.RunJavascriptMessage(source=KEYBOARD_JS))


def show_tab(client, label: str) -> None:
    """Bring the panel tab called ``label`` (one of the labeler's own tab names) to the front in one client."""
    import json

    from viser import _messages

    # viser's tabs are dock tabs (they can be dragged): they select on a pointer press and release, not a
    # click. A page still building its panel (a reload) has no tab yet: try again every 0.1 s for 10 s. The
    # latest call wins: an earlier call's retries stop (M pressed twice must not flip back to the first tab).
    want = json.dumps(str(label))
    source = ("(function () { const me = {}; window.__rally3dTab = me; let tries = 0; const go = () => {"
              " if (window.__rally3dTab !== me) return;"
              " const tab = Array.from(document.querySelectorAll('[role=\"tab\"]'))"
              f".find((t) => (t.textContent || '').trim() === {want});"
              " if (tab && tab.getAttribute('aria-selected') === 'true') return;"
              " if (tab) { const o = {bubbles: true, button: 0, isPrimary: true, pointerId: 1};"
              " tab.dispatchEvent(new PointerEvent('pointerdown', o));"
              " tab.dispatchEvent(new PointerEvent('pointerup', o)); }"
              " if (++tries < 100) setTimeout(go, 100); }; go(); })();")
    client.gui._websock_interface.queue_message(_messages.RunJavascriptMessage(source=source))
