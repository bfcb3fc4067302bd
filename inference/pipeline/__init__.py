"""The end-to-end pipeline ``rally3d infer``: video → ball, events, players, 3D in a clip folder.

Stages (:mod:`.stages`) run in order, resumably (:mod:`.state`), with a per-stage timing summary
(:mod:`.run`); many clips go through Lightning's predict loop (:mod:`.engine`).
"""
from inference.lazy import lazy_exports

# light, and named like their submodule (an import of the submodule would rebind a lazy name to it)
from .prepare import Prepared, prepare
from .score import Scores, score

# name → submodule, imported on first use (keeps `rally3d --help` free of torch/scipy)
_EXPORTS = {
    "PipelineReport": ".run",
    "StageReport": ".run",
    "run_pipeline": ".run",
    "PipelineConfig": ".stages",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = ["PipelineConfig", "PipelineReport", "Prepared", "Scores", "StageReport", "prepare", "run_pipeline",
           "score"]
