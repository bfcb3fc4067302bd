"""Reading and writing a clip folder (docs/formats.md): typed tables, clip.yaml, frames, importers.

Every reader validates its input and raises :class:`FormatError` naming the file, the line and the
fix; every writer is atomic and deterministic.
"""

from .atomic import atomic_write_bytes, atomic_write_text, private_temp_path
from .clip import Clip
from .clip_yaml import ClipInfo, read_clip_yaml, write_clip_yaml
from .csvfiles import (
    read_ball_3d_csv,
    read_ball_csv,
    read_court_points_csv,
    read_events_csv,
    read_inactive_balls_csv,
    write_ball_3d_csv,
    write_ball_csv,
    write_court_points_csv,
    write_events_csv,
    write_inactive_balls_csv,
)
from .errors import FormatError
from .frames import FolderFrames, FrameSource, VideoFrames, write_frames_folder, write_video
from .manifest import SPLITS, Manifest, ManifestEntry, split_of
from .players import PlayerTracks, read_players_csv, write_players_csv
from .importers import (
    PADEL_6CLASS_CODES,
    export_tracknet_label,
    hit_by_image_half,
    import_thesis_ball,
    import_thesis_court_3d,
    import_thesis_court_points,
    import_thesis_hits,
    import_tracknet_badminton,
    import_tracknet_label,
)
from .tables import (
    BALL3D_KINDS,
    EVENT_LABELS,
    Ball3D,
    BallTrack,
    CourtPoints,
    DenseBallTrack,
    HitEvents,
    InactiveBalls,
)

__all__ = [
    "BALL3D_KINDS",
    "EVENT_LABELS",
    "PADEL_6CLASS_CODES",
    "Ball3D",
    "BallTrack",
    "Clip",
    "ClipInfo",
    "CourtPoints",
    "DenseBallTrack",
    "FolderFrames",
    "FormatError",
    "FrameSource",
    "HitEvents",
    "InactiveBalls",
    "Manifest",
    "ManifestEntry",
    "SPLITS",
    "PlayerTracks",
    "VideoFrames",
    "atomic_write_bytes",
    "atomic_write_text",
    "private_temp_path",
    "export_tracknet_label",
    "hit_by_image_half",
    "import_thesis_ball",
    "import_thesis_court_3d",
    "import_thesis_court_points",
    "import_thesis_hits",
    "import_tracknet_badminton",
    "import_tracknet_label",
    "read_ball_3d_csv",
    "split_of",
    "read_ball_csv",
    "read_clip_yaml",
    "read_court_points_csv",
    "read_events_csv",
    "read_inactive_balls_csv",
    "read_players_csv",
    "write_ball_3d_csv",
    "write_ball_csv",
    "write_clip_yaml",
    "write_court_points_csv",
    "write_events_csv",
    "write_frames_folder",
    "write_inactive_balls_csv",
    "write_players_csv",
    "write_video",
]
