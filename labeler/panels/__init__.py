"""Thin GUI builders of the labeler: each ``populate_*(gui, view)`` adds its controls and wires them to the view."""
