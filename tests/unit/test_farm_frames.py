"""The farm's frame and file-name rules (csm_engine/farm/frames.py), without Blender."""
import os

import pytest

from csm_engine.farm import frames
from csm_engine.farm.command import is_farm_command


@pytest.mark.parametrize("text, expected", [
    ("1-8", list(range(1, 9))), ("7", [7]), ("0", [0]), (" 3 - 5 ", [3, 4, 5]),
    ("1-3,10,2-4", [1, 2, 3, 4, 10]), ("240-240", [240]),
])
def test_frame_ranges(text, expected):
    assert frames.parse_frames(text) == expected


@pytest.mark.parametrize("text, message", [
    ("", "empty"), ("8-1", "did you mean 1-8"), ("1-x", "'1-x' is not a frame"),
    ("-3", "is not a frame"), ("1,,2", "'' is not a frame"), ("1-2000000", "beyond"),
])
def test_bad_frame_ranges_say_what_is_wrong(text, message):
    with pytest.raises(frames.FrameSpecError, match=message):
        frames.parse_frames(text)


def test_frame_path_pads_the_last_run_of_hashes_as_blender_does():
    assert frames.frame_path("/r/f_####.png", 7) == "/r/f_0007.png"
    assert frames.frame_path("/r/f_##.png", 1234) == "/r/f_1234.png"
    assert frames.frame_path("/r/take#2_###.png", 5) == "/r/take#2_005.png"


def test_patterns(tmp_path):
    assert frames.check_pattern(str(tmp_path / "new" / "f_####.png")) == \
        str(tmp_path / "new" / "f_####.png")
    for bad, message in (("f.png", "has no #"), ("f_##.exr", "end the name with .png"),
                         ("", "empty"), ("##/f.png", "has no # in its file name")):
        with pytest.raises(frames.FrameSpecError, match=message):
            frames.check_pattern(str(tmp_path / bad) if bad else bad)
    (tmp_path / "file").write_text("x")
    with pytest.raises(frames.FrameSpecError, match="is a file"):
        frames.check_pattern(str(tmp_path / "file" / "f_#.png"))


def test_existing_frames_are_kept_unless_overwrite(tmp_path):
    pattern = str(tmp_path / "f_##.png")
    (tmp_path / "f_02.png").write_bytes(b"png")
    (tmp_path / "f_03.png").write_bytes(b"")          # a placeholder: rendered again
    assert frames.frames_to_render(pattern, [1, 2, 3]) == ([1, 3], [2])
    assert frames.frames_to_render(pattern, [1, 2, 3], overwrite=True) == ([1, 2, 3], [])
    assert os.listdir(tmp_path) and frames.frame_done(str(tmp_path / "f_02.png"))


@pytest.mark.parametrize("argv, farm", [
    (["shot.blend", "--frames", "1-2"], True), (["--workers", "2", "a.BLEND"], True),
    (["scene.json", "shot.png"], False), ([], False), (["--list-settings"], False),
    (["scene.json", "--set", "x=y.blend"], False),
])
def test_a_blend_file_first_asks_for_the_farm(argv, farm):
    assert is_farm_command(argv) is farm
