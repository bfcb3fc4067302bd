"""``rally3d synth --out``: a file or a folder of a person's clips is refused with a clear line, untouched."""
from __future__ import annotations

from inference.cli import main


def test_out_naming_a_file_is_a_clear_error(tmp_path, capsys):
    target = tmp_path / "notes.txt"
    target.write_text("mine")
    assert main(["synth", "--out", str(target), "--clips", "1", "--max-frames", "10"]) == 1
    err = capsys.readouterr().err
    assert "is a file" in err and str(target) in err and "Traceback" not in err
    assert target.read_text() == "mine"


def test_out_holding_labelled_clips_is_refused(tmp_path, capsys):
    clip = tmp_path / "data" / "clip_0000"
    clip.mkdir(parents=True)
    (clip / "clip.yaml").write_text("sport: padel\nfps: 30\nwidth: 1280\nheight: 720\nvideo: video.mp4\n")
    (clip / "ball.csv").write_text("frame,visibility,x,y\n0,1,0.5,0.5\n")
    assert main(["synth", "--out", str(tmp_path / "data"), "--clips", "1", "--max-frames", "10"]) == 1
    err = capsys.readouterr().err
    assert "did not make" in err and "clip_0000" in err
    assert (clip / "ball.csv").read_text() == "frame,visibility,x,y\n0,1,0.5,0.5\n"
