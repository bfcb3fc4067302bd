"""3D reconstruction of the ball from one calibrated camera (see :func:`reconstruct`)."""
from inference.lazy import lazy_exports

# name → submodule, imported on first use (keeps `rally3d --help` free of torch/scipy)
_EXPORTS = {
    "DEFAULT_METHOD": ".api",
    "METHOD_NAMES": ".api",
    "reconstruct": ".api",
    "ContactPrior": ".observations",
    "Observations": ".observations",
    "Segment": ".observations",
    "contact_priors": ".observations",
    "RallyFit": ".results",
    "SegmentFit": ".results",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = ["DEFAULT_METHOD", "METHOD_NAMES", "ContactPrior", "Observations", "RallyFit", "Segment", "SegmentFit",
           "contact_priors", "reconstruct"]
