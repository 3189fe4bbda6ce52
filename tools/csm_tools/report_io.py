"""Files the measuring tools write: generated sections of a markdown page, and PNGs.

Owns the one way a tool rewrites its part of a hand-written page (the text between a
``BEGIN`` and an ``END`` marker; the prose around them stays) and the one plain-numpy PNG
writer and reader (8-bit, non-interlaced, no imaging library), so the tools and their tests
agree on the format, and what every generated table says of the run that made it
(``run_facts``). bpy and gpu are imported only there, for Blender's version and renderer.
"""

import datetime
import os
import platform
import struct
import zlib

import numpy as np

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_COLOR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}        # channels -> PNG colour type
_PNG_CHANNELS = {v: k for k, v in _PNG_COLOR_TYPES.items()}


class ReportError(Exception):
    """A page or image cannot be written or read; ``str()`` is one line naming the file."""


# -- the run behind a table ----------------------------------------------------------------
def machine():
    """Cores, system and, once Blender has made a GPU context, the OpenGL renderer."""
    text = f"{os.cpu_count()} cores, {platform.system()} {platform.machine()}"
    try:
        import gpu
        text += f", {gpu.platform.renderer_get()}"
    except Exception:      # no GPU context: the renderer is unknown, the rest still holds
        pass
    return text


def run_facts(prog, argv, **more):
    """The command, date, machine and Blender version a generated table states, plus
    ``more``."""
    import bpy
    return dict(command=" ".join([prog] + list(argv)),
                date=datetime.date.today().isoformat(), machine=machine(),
                blender=bpy.app.version_string, **more)


# -- generated markdown sections ----------------------------------------------------------
def read_page(path, begin, end, title=None):
    """The text of ``path``, checked to hold a ``begin`` ... ``end`` section.

    With ``title``, a missing page starts as ``# title`` with an empty section and a page
    without the markers gets an empty section appended; without it both raise ReportError,
    so a tool can refuse before a long run rather than after it."""
    try:
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
    except FileNotFoundError:
        if title is None:
            raise ReportError(f"cannot read '{path}' (no such file)")
        text = f"# {title}\n"
    except OSError as error:
        raise ReportError(f"cannot read '{path}' ({error.strerror})")
    if begin not in text or end not in text:
        if title is None:
            raise ReportError(f"'{path}' has no '{begin}' ... '{end}' section to rewrite")
        text = text.rstrip() + f"\n\n{begin}\n{end}\n"
    return text


def write_section(path, begin, end, body, title=None):
    """Replace what lies between ``begin`` and ``end`` in ``path`` with ``body`` (a string
    ending in a newline); see ``read_page`` for ``title``."""
    text = read_page(path, begin, end, title)
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w", encoding="utf-8") as stream:
        stream.write(head + begin + "\n" + body + end + tail)


# -- PNG ----------------------------------------------------------------------------------
def _chunk(kind, data):
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def png_bytes(image):
    """An (H, W, C) uint8 image (C = 1 grey, 2 grey+alpha, 3 RGB, 4 RGBA), top row first,
    as the bytes of an 8-bit PNG. Deterministic: the same pixels give the same bytes."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    if image.ndim == 2:
        image = image[..., None]
    height, width, channels = image.shape
    if channels not in _PNG_COLOR_TYPES:
        raise ValueError(f"png_bytes: {channels} channels; expected 1 to 4")
    rows = np.concatenate([np.zeros((height, 1), np.uint8), image.reshape(height, -1)],
                          axis=1)       # filter type 0 (none) before each row
    header = struct.pack(">IIBBBBB", width, height, 8, _PNG_COLOR_TYPES[channels], 0, 0, 0)
    return (PNG_SIGNATURE + _chunk(b"IHDR", header)
            + _chunk(b"IDAT", zlib.compress(rows.tobytes(), 9)) + _chunk(b"IEND", b""))


def write_png(path, image):
    """Write an (H, W, C) uint8 image, top row first, as an 8-bit PNG (see png_bytes)."""
    with open(path, "wb") as stream:
        stream.write(png_bytes(image))


def _unfilter(raw, height, stride, bytes_per_pixel):
    """Undo PNG's per-row filters (types 0-4); rows of ``stride`` bytes."""
    rows = np.zeros((height, stride), np.int32)
    previous = np.zeros(stride, np.int32)
    for y in range(height):
        kind, line = raw[y, 0], raw[y, 1:].astype(np.int32)
        if kind == 0:
            row = line
        elif kind == 2:
            row = (line + previous) & 0xFF
        else:
            # Sub, Average and Paeth depend on the pixel to the left: one byte at a time.
            row = np.zeros(stride, np.int32)
            for x in range(stride):
                left = row[x - bytes_per_pixel] if x >= bytes_per_pixel else 0
                up = previous[x]
                up_left = previous[x - bytes_per_pixel] if x >= bytes_per_pixel else 0
                if kind == 1:
                    predictor = left
                elif kind == 3:
                    predictor = (left + up) // 2
                else:
                    p = left + up - up_left
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - up_left)
                    predictor = left if pa <= pb and pa <= pc else (up if pb <= pc else up_left)
                row[x] = (line[x] + predictor) & 0xFF
        rows[y] = row
        previous = row
    return rows.astype(np.uint8)


def read_png(path):
    """A non-interlaced 8- or 16-bit PNG (as this module and Blender write them) as an
    (H, W, C) array, top row first: uint8 for 8-bit files, uint16 for 16-bit ones."""
    with open(path, "rb") as stream:
        data = stream.read()
    if data[:8] != PNG_SIGNATURE:
        raise ReportError(f"'{path}' is not a PNG")
    offset, chunks, header = 8, [], None
    while offset < len(data):
        length, kind = struct.unpack(">I4s", data[offset:offset + 8])
        body = data[offset + 8:offset + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            chunks.append(body)
        offset += 12 + length
    width, height, depth, color_type, _, _, interlace = header
    if interlace != 0 or depth not in (8, 16) or color_type not in _PNG_CHANNELS:
        raise ReportError(f"'{path}': unsupported PNG (depth {depth}, colour type "
                          f"{color_type}, interlace {interlace})")
    channels = _PNG_CHANNELS[color_type]
    bytes_per_pixel = channels * depth // 8
    stride = width * bytes_per_pixel
    raw = np.frombuffer(zlib.decompress(b"".join(chunks)), np.uint8).reshape(height,
                                                                             stride + 1)
    samples = _unfilter(raw, height, stride, bytes_per_pixel)
    if depth == 16:
        samples = samples.reshape(height, -1, 2).astype(np.uint16)
        samples = samples[..., 0] * 256 + samples[..., 1]
    return samples.reshape(height, width, channels)


def saved_render(scene, path):
    """Blender's last render result ("Render Result") as linear float RGBA (H, W, 4), rows
    bottom first as Blender keeps them, through a 32-bit OpenEXR file written to ``path``
    (OpenEXR keeps scene-linear values; Python cannot read the Render Result's pixels
    directly). Shared by the reports and the tests that compare with EEVEE or Cycles."""
    import bpy
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):      # 5.0: image, multilayer image or video
        settings.media_type = 'IMAGE'
    settings.file_format = 'OPEN_EXR'
    settings.color_depth = '32'
    settings.color_mode = 'RGBA'
    bpy.data.images["Render Result"].save_render(filepath=path, scene=scene)
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(height, width, 4)
