"""3D reconstruction of the ball from one calibrated camera (see :func:`reconstruct`)."""
from .api import DEFAULT_METHOD, METHOD_NAMES, reconstruct
from .observations import ContactPrior, Observations, Segment, contact_priors
from .results import RallyFit, SegmentFit

__all__ = ["DEFAULT_METHOD", "METHOD_NAMES", "ContactPrior", "Observations", "RallyFit", "Segment", "SegmentFit",
           "contact_priors", "reconstruct"]
