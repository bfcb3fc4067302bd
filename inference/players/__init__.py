"""Players: pose backends and importers, identity tracking, player selection and teams, court positions."""
from .types import Persons, PoseSequence

__all__ = ["Persons", "PoseSequence"]
