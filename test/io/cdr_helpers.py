"""Serialise with rclpy for comparison with the package's CDR encoders."""

from flexlink_ros.io.cdr import _basic_type, align, ENCAPSULATION_SIZE, walk_message
from rclpy.serialization import serialize_message


class CdrSizer:
    """Walk target that only counts: the exact length and the padding's byte ranges."""

    def __init__(self):
        self.position = ENCAPSULATION_SIZE
        self.padding = []

    def pad(self, size):
        """Skip to the next multiple of ``size``, noting the skipped range."""
        start = self.position
        self.position = align(start, size)
        if self.position != start:
            self.padding.append((start, self.position))

    def count(self, value):
        """Skip a uint32 length."""
        self.pad(4)
        self.position += 4

    def string(self, text):
        """Skip a string: length, UTF-8 bytes, NUL."""
        self.count(0)
        self.position += (len(text) if text.isascii() else len(text.encode('utf-8'))) + 1

    def basics(self, typename, values):
        """Skip values of one basic type, aligned to its size."""
        size, _ = _basic_type(typename)
        self.pad(min(size, 8))
        self.position += size * len(values)


def cdr_layout(message):
    """
    Return the exact CDR length of a message and where its alignment padding lies.

    Parameters
    ----------
    message : ROS 2 message instance
        Walked by :func:`io.cdr.walk_message`.

    Returns
    -------
    length : int
        Bytes including the 4-byte encapsulation header.
    padding : list of (int, int)
        Half-open byte ranges of alignment padding, offsets into the whole buffer.

    """
    sizer = CdrSizer()
    walk_message(sizer, message)
    return sizer.position, sizer.padding


def rclpy_exact(message):
    """Serialise with rclpy, zero the padding and cut the buffer at the exact CDR length."""
    data = bytearray(serialize_message(message))
    length, padding = cdr_layout(message)
    assert length <= len(data)
    for start, stop in padding:
        data[start:stop] = bytes(stop - start)
    return bytes(data[:length])
