"""The farm's pure rules: which frames a ``--frames`` text names, which file each frame
goes to (Blender's ``#`` convention), and which of them still need rendering.

Standard library only, no bpy and no Dask, so the coordinator checks a user's mistakes
before any worker starts and the rules are tested without Blender. Mistakes raise
``FrameSpecError`` with one line that names the bad text.
"""

import os
import re

# Blender's own limit on a frame number (MAXFRAME in DNA_scene_types.h).
MAX_FRAME = 1048574
# A run of '#' in the file name: the frame number's place, padded with zeros to its length.
_HASHES = re.compile(r"#+")


class FrameSpecError(ValueError):
    """A ``--frames`` or ``--output`` text that cannot be used; the message is one line."""


def parse_frames(text):
    """The frames ``text`` names, ascending and each once: ``1-240``, ``7``, or a comma
    list of both (``1-10,20,30-40``); both ends of a range are included, as with Blender's
    Frame Start and End."""
    frames = set()
    parts = [part.strip() for part in (text or "").split(",")]
    if not any(parts):
        raise FrameSpecError("--frames is empty: give a range like 1-240")
    for part in parts:
        match = re.fullmatch(r"(\d+)(?:\s*-\s*(\d+))?", part)
        if match is None:
            raise FrameSpecError(f"--frames: '{part}' is not a frame or a range like 1-240 "
                                 "(frames are whole numbers from 0)")
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) is not None else first
        if last < first:
            raise FrameSpecError(f"--frames: '{part}' ends before it starts; "
                                 f"did you mean {last}-{first}?")
        if last > MAX_FRAME:
            raise FrameSpecError(f"--frames: {last} is beyond Blender's last frame, "
                                 f"{MAX_FRAME}")
        frames.update(range(first, last + 1))
    return sorted(frames)


def check_pattern(pattern):
    """``pattern`` as an absolute path, or FrameSpecError: a PNG file name with a run of
    ``#`` in it (``renders/f_####.png``) in a folder that is not a file."""
    if not pattern or not pattern.strip():
        raise FrameSpecError("--output is empty: name the frames, e.g. renders/f_####.png")
    path = os.path.abspath(os.path.expanduser(pattern))
    folder, name = os.path.split(path)
    if not _HASHES.search(name):
        raise FrameSpecError(f"--output '{pattern}' has no # in its file name: mark where "
                             "the frame number goes, e.g. renders/f_####.png")
    if os.path.splitext(name)[1].lower() != ".png":
        raise FrameSpecError(f"--output '{pattern}': frames are written as PNG, end the "
                             "name with .png (e.g. f_####.png)")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise FrameSpecError(f"--output '{pattern}': '{folder}' is a file, not a folder")
    return path


def frame_path(pattern, frame):
    """The file ``frame`` goes to: the last run of ``#`` in the file name replaced by the
    frame number, zero-padded to the run's length (longer numbers are not cut), as Blender
    names animation frames."""
    folder, name = os.path.split(pattern)
    runs = list(_HASHES.finditer(name))
    if not runs:
        raise FrameSpecError(f"'{pattern}' has no # in its file name")
    run = runs[-1]
    number = f"{frame:0{run.end() - run.start()}d}"
    return os.path.join(folder, name[:run.start()] + number + name[run.end():])


def frame_done(path):
    """Whether a frame's file is there: a regular file with something in it (an empty
    file is a placeholder or a broken write, and is rendered again)."""
    return os.path.isfile(path) and os.path.getsize(path) > 0


def frames_to_render(pattern, frames, overwrite=False):
    """(to render, present): the frames whose file is missing (all of them with
    ``overwrite``), and those whose file is there already and is kept."""
    if overwrite:
        return list(frames), []
    present = [frame for frame in frames if frame_done(frame_path(pattern, frame))]
    kept = set(present)
    return [frame for frame in frames if frame not in kept], present
