"""clip.yaml: ClipInfo validation, round trip and rejected files."""

import pytest
import yaml

from inference.clipio import ClipInfo, FormatError, read_clip_yaml, write_clip_yaml

MINIMAL = "sport: padel\nfps: 30\nwidth: 1920\nheight: 1080\nvideo: video.mp4\n"


@pytest.mark.parametrize(
    "info",
    [
        ClipInfo("padel", 30.0, 1920, 1080, "video.mp4"),
        ClipInfo(
            "tennis",
            25.0,
            1280,
            720,
            "frames/",
            n_frames=912,
            camera_id="cam0",
            split="train",
            source="https://example.org/v",
            licence="CC-BY-4.0",
            court="../courts/tennis_clay.yaml",
            extra={"notes": "rain delay", "weather": {"temp_c": 21}},
        ),
    ],
    ids=["minimal", "full"],
)
def test_round_trip(tmp_path, info):
    path = write_clip_yaml(tmp_path / "clip.yaml", info)
    assert read_clip_yaml(path) == info
    first = path.read_text()
    write_clip_yaml(path, read_clip_yaml(path))
    assert path.read_text() == first


def test_key_order_and_unknown_keys_kept(tmp_path):
    path = tmp_path / "clip.yaml"
    path.write_text("zz_custom: 1\n" + MINIMAL + "camera_id: 7\n")
    info = read_clip_yaml(path)
    assert info.fps == 30.0 and isinstance(info.fps, float)
    assert info.camera_id == "7" and info.extra == {"zz_custom": 1}
    write_clip_yaml(path, info)
    keys = list(yaml.safe_load(path.read_text()))
    assert keys == ["sport", "fps", "width", "height", "video", "camera_id", "zz_custom"]


@pytest.mark.parametrize(("video", "is_folder"), [("video.mp4", False), ("frames/", True), ("frames", True)])
def test_is_frames_folder(video, is_folder):
    assert ClipInfo("padel", 30, 64, 48, video).is_frames_folder is is_folder


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("sport: padel\nfps: 30\nwidth: 1920\nvideo: video.mp4\n", None, ["missing key", "height"]),
        (MINIMAL.replace("fps: 30", "fps: -2"), 2, ["fps must be a number > 0"]),
        (MINIMAL.replace("fps: 30", "fps: fast"), 2, ["fps"]),
        (MINIMAL.replace("width: 1920", "width: 19.5"), 3, ["width must be a whole number"]),
        (MINIMAL.replace("height: 1080", "height: true"), 4, ["height"]),
        (MINIMAL.replace("video: video.mp4", "video: ''"), 5, ["video must be a non-empty string"]),
        (MINIMAL + "n_frames: 0\n", 6, ["n_frames"]),
        (MINIMAL + "split: [a, b]\n", 6, ["split"]),
        ("sport: padel\nfps: [30\n", 3, ["not valid YAML"]),
        ("- a\n- b\n", 1, ["mapping"]),
        ("", 1, ["empty file"]),
    ],
)
def test_rejected(tmp_path, text, line, words):
    path = tmp_path / "clip.yaml"
    path.write_text(text)
    with pytest.raises(FormatError) as info:
        read_clip_yaml(path)
    message = str(info.value)
    assert "clip.yaml" in message and "fix:" in message
    assert info.value.line == line
    if line is not None:
        assert f"line {line}:" in message
    for word in words:
        assert word in message


def test_missing_file(tmp_path):
    with pytest.raises(FormatError, match=r"clip.yaml: file not found"):
        read_clip_yaml(tmp_path / "clip.yaml")


@pytest.mark.parametrize("kwargs", [dict(fps=0), dict(width=0), dict(sport=""), dict(video=None)])
def test_clip_info_validates(kwargs):
    args = dict(sport="padel", fps=30.0, width=64, height=48, video="video.mp4") | kwargs
    with pytest.raises(ValueError):
        ClipInfo(**args)


def test_source_may_be_any_yaml_value(tmp_path):
    """Provenance from other tools: a mapping (or list) `source` is read and written back as written."""
    from inference.clipio import read_clip_yaml, write_clip_yaml

    path = tmp_path / "clip.yaml"
    path.write_text("sport: padel\nfps: 25\nwidth: 1920\nheight: 1080\nvideo: match.mp4\n"
                    "source:\n  url: https://example.org/match\n  start_s: 812.4\n  cameras: [main, side]\n")
    info = read_clip_yaml(path)
    assert info.source == {"url": "https://example.org/match", "start_s": 812.4, "cameras": ["main", "side"]}
    write_clip_yaml(tmp_path / "again.yaml", info)
    assert read_clip_yaml(tmp_path / "again.yaml").source == info.source
