"""``rally3d import`` and ``rally3d export``: labels in from and out to CVAT and Label Studio."""

from __future__ import annotations

import argparse
import shutil
import textwrap
import time
from pathlib import Path

FORMATS = ("cvat", "labelstudio")
SUFFIXES = {".xml": "cvat", ".json": "labelstudio"}

_MAPPING = (
    "The ball is the label 'ball'; events use the labels of events.csv (ground, wall_near, wall_far, "
    "wall_left, wall_right, mesh, net, player_near, player_far). Map other names with --label-map. "
    "The full mapping is in docs/interchange.md."
)


def _wrap(text: str) -> str:
    return textwrap.fill(text, width=100)


def _say(text: str) -> None:
    """Print a line that may quote the file (a lone surrogate from a JSON escape is spelt out)."""
    print(text.encode("utf-8", "backslashreplace").decode("utf-8"))


def _clip_facts(clip: Path) -> tuple[tuple[int, int] | None, int | None]:
    """An existing clip folder's image size and length (None where there is none to read)."""
    from inference.clipio import Clip, FormatError

    from .common import known_frames

    folder = Clip(clip)
    if not folder.clip_yaml_path.is_file():
        return None, None
    try:
        info = folder.info
    except (FormatError, ValueError, OSError):
        return None, None
    return (info.width, info.height), known_frames(folder)


def _format(explicit: str | None, path: Path) -> str:
    if explicit:
        return explicit
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(
            f"cannot tell the format of {path} from its suffix; pass --format cvat or labelstudio"
        )
    return fmt


# ---------------------------------------------------------------------------------------------- import
def register_import(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import",
        help="import a ball track and events from CVAT (video XML) or Label Studio (JSON) into a clip folder",
        description=_wrap(
            "Reads a 'CVAT for video 1.1' annotations.xml or a Label Studio JSON export and writes "
            "the clip folder's ball.csv and events.csv (and clip.yaml when the folder is new). " + _MAPPING
        ),
        epilog="examples:\n"
        "  rally3d import annotations.xml clips/rally_01                  # into an existing clip\n"
        "  rally3d import export.json clips/rally_02 --task 17 --sport padel --width 1920 --height 1080\n"
        "  rally3d import annotations.xml clips/rally_01 --label-map bounce=ground --overwrite",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", type=Path, help="CVAT annotations.xml or Label Studio export .json")
    p.add_argument("clip", type=Path, help="clip folder to write into (created with clip.yaml if new)")
    p.add_argument(
        "--format", choices=FORMATS, help="default: from the suffix (.xml cvat, .json labelstudio)"
    )
    p.add_argument(
        "--label-map",
        action="append",
        default=[],
        metavar="NAME=TARGET",
        help="map a label of the file to 'ball', an event label or 'ignore' (repeatable)",
    )
    p.add_argument(
        "--task", type=int, metavar="ID", help="Label Studio: the task id when the export holds several"
    )
    p.add_argument(
        "--annotation",
        type=int,
        metavar="ID",
        help="Label Studio: the annotation id (default: the first one)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace existing ball.csv/events.csv (a backup goes to .rally3d/backup/)",
    )
    p.add_argument(
        "--dry-run", action="store_true", help="read and check the file, print a summary, write nothing"
    )
    new = p.add_argument_group("a new clip folder (when CLIP has no clip.yaml yet)")
    new.add_argument("--sport", help="court of the clip: padel or tennis")
    new.add_argument("--fps", type=float, help="frame rate (Label Studio files give one; CVAT files do not)")
    new.add_argument("--video", help="the frames, relative to the clip folder (default video.mp4)")
    new.add_argument(
        "--width", type=int, help="image width in pixels (CVAT files of tasks made from a video give it)"
    )
    new.add_argument(
        "--height", type=int, help="image height in pixels (CVAT files of tasks made from a video give it)"
    )
    p.set_defaults(func=run_import)


def run_import(args: argparse.Namespace) -> int:
    from .common import LabelMap, write_into_clip

    fmt = _format(args.format, args.file)
    labels = LabelMap.parse(args.label_map)
    clip_size, clip_frames = _clip_facts(args.clip)  # an existing clip bounds the frames from the start
    if fmt == "cvat":
        from .cvat import import_cvat

        # for a file without <original_size>: --width/--height, else the clip's own image size
        size = (args.width, args.height) if args.width and args.height else clip_size
        imported = import_cvat(args.file, labels, size=size, clip_frames=clip_frames)
    else:
        from .labelstudio import import_labelstudio

        imported = import_labelstudio(
            args.file, labels, task=args.task, annotation=args.annotation, clip_frames=clip_frames
        )
    if args.width and args.height:
        imported.width, imported.height = args.width, args.height
    for line in imported.warnings:
        _say(f"warning: {line}")
    visible = int((imported.ball.visibility > 0).sum())
    _say(
        f"{imported.source}: {len(imported.ball)} ball rows ({visible} visible), "
        f"{len(imported.events)} events"
        + (f", {imported.n_frames} frames" if imported.n_frames else "")
        + (f", {imported.fps:g} fps" if imported.fps else "")
    )
    if args.dry_run:
        print("dry run: nothing written")
        return 0
    _, report = write_into_clip(
        args.clip, imported, overwrite=args.overwrite, sport=args.sport, fps=args.fps, video=args.video
    )
    for line in report:
        print(line)
    return 0


# ---------------------------------------------------------------------------------------------- export
def register_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="export a clip folder's ball track and events to CVAT (video XML) or Label Studio (JSON)",
        description=_wrap(
            "Writes the clip's ball.csv and events.csv as a 'CVAT for video 1.1' annotations.xml "
            "(upload it to a task made from the clip's video) or as a Label Studio JSON task (import "
            "it into a project whose labeling config is in docs/interchange.md). " + _MAPPING
        ),
        epilog="examples:\n"
        "  rally3d export clips/rally_01 --out rally_01.xml                 # CVAT\n"
        "  rally3d export clips/rally_01 --out rally_01.json --video-url /data/local-files/?d=rally_01.mp4",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("clip", type=Path, help="clip folder (clip.yaml; ball.csv and events.csv where present)")
    p.add_argument(
        "--out", type=Path, required=True, help="the file to write (.xml CVAT, .json Label Studio)"
    )
    p.add_argument("--format", choices=FORMATS, help="default: from the suffix of --out")
    p.add_argument("--video-url", help="Label Studio: the task's data.video (default: clip.yaml's video)")
    p.add_argument(
        "--overwrite", action="store_true", help="replace --out if it exists (a backup is kept beside it)"
    )
    p.set_defaults(func=run_export)


def run_export(args: argparse.Namespace) -> int:
    from inference.clipio import Clip, FormatError

    fmt = _format(args.format, args.out)
    clip = Clip(args.clip)
    info = clip.info
    track = clip.read_ball(missing_ok=True)
    events = clip.read_events(missing_ok=True)
    n_frames = clip.n_frames
    if args.out.exists():
        if not args.overwrite:
            raise FormatError(
                args.out,
                "exists already; nothing was written",
                fix="pass --overwrite to replace it (a backup is kept beside it)",
            )
        kept = args.out.with_name(f"{args.out.name}.{time.strftime('%Y%m%d-%H%M%S')}.bak")
        shutil.copy2(args.out, kept)
        print(f"backup {kept}")
    size = {"width": info.width, "height": info.height, "n_frames": n_frames}
    if fmt == "cvat":
        from .cvat import export_cvat

        path = export_cvat(args.out, track, events, **size, name=clip.root.resolve().name)
    else:
        from .labelstudio import export_labelstudio

        video_url = args.video_url or info.video
        path = export_labelstudio(args.out, track, events, **size, fps=info.fps, video_url=video_url)
    print(f"wrote {path}: {len(track)} ball rows, {len(events)} events, {n_frames} frames ({fmt})")
    return 0
