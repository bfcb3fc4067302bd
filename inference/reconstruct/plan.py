"""The plan of a joint fit: which contacts (the clip's events, or inserted ones) a chain of flights is
fitted through. Shared by :mod:`.joint` (fits a plan) and :mod:`.plausibility` (proposes other plans for a
flight that fails its checks)."""
from __future__ import annotations

from dataclasses import dataclass, field

from .observations import ContactPrior


@dataclass
class PlanContact:
    """A contact to fit: an event (``event`` = its index in the clip's events) or an inserted one."""

    prior: ContactPrior
    event: int | None
    note: str = ""


@dataclass
class Plan:
    """The contacts to fit, in time order, and notes on how the plan was made (refits)."""

    contacts: list[PlanContact]
    notes: list[str] = field(default_factory=list)
    #: frames whose detections every fit of this plan leaves out (a run the detector spent off the ball inside a
    #: flight whose other detections agree: :func:`.joint.leave_out_off_runs`)
    left_out: tuple[int, ...] = ()

    def key(self) -> tuple:
        return (tuple((c.prior.frame, c.prior.label) for c in self.contacts), self.left_out)
