"""Labels in from and out to the annotation tools teams already run: CVAT and Label Studio.

``rally3d import`` / ``rally3d export`` (:mod:`.cli`) move a clip's ball track (``ball.csv``, with its
visibility) and events (``events.csv``) to and from "CVAT for video 1.1" XML (:mod:`.cvat`) and Label Studio's
video JSON (:mod:`.labelstudio`). The mapping is documented in docs/interchange.md. Only
:mod:`inference.clipio` is used from the project.
"""

from inference.lazy import lazy_exports

# name → submodule, imported on first use (keeps `rally3d --help` free of torch/scipy)
_EXPORTS = {
    "Imported": ".common",
    "LabelMap": ".common",
    "write_into_clip": ".common",
    "export_cvat": ".cvat",
    "import_cvat": ".cvat",
    "export_labelstudio": ".labelstudio",
    "import_labelstudio": ".labelstudio",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "Imported",
    "LabelMap",
    "export_cvat",
    "export_labelstudio",
    "import_cvat",
    "import_labelstudio",
    "write_into_clip",
]
