"""Checks of the charts the report draws: a PNG of the expected size with the expected colours."""

import struct

from matplotlib import colors
from matplotlib import image
import numpy as np

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def png_size(path):
    """Width and height [px] from a PNG file's header chunk; asserts it is a non-empty PNG."""
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and data[12:16] == b'IHDR', path
    return struct.unpack('>II', data[16:24])


def has_colour(path, name, tolerance=0.02, pixels=20):
    """Whether at least ``pixels`` pixels of the image are the matplotlib colour ``name``."""
    rgb = image.imread(path)[..., :3]
    target = np.array(colors.to_rgb(name))
    return int(np.sum(np.all(np.abs(rgb - target) < tolerance, axis=-1))) >= pixels
