"""Labels in from and out to the annotation tools teams already run: CVAT and Label Studio.

``rally3d import`` / ``rally3d export`` (:mod:`.cli`) move a clip's ball track (``ball.csv``, with its
visibility) and events (``events.csv``) to and from "CVAT for video 1.1" XML (:mod:`.cvat`) and Label Studio's
video JSON (:mod:`.labelstudio`). The mapping is documented in docs/interchange.md. Only
:mod:`inference.clipio` is used from the project.
"""

from .common import Imported, LabelMap, write_into_clip
from .cvat import export_cvat, import_cvat
from .labelstudio import export_labelstudio, import_labelstudio

__all__ = [
    "Imported",
    "LabelMap",
    "export_cvat",
    "export_labelstudio",
    "import_cvat",
    "import_labelstudio",
    "write_into_clip",
]
