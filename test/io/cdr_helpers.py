"""Serialise with rclpy for comparison with the package's CDR encoders."""

from flexlink_ros.io.msg_schema import cdr_layout
from rclpy.serialization import serialize_message


def rclpy_exact(message):
    """Serialise with rclpy, zero the padding and cut the buffer at the exact CDR length."""
    data = bytearray(serialize_message(message))
    length, padding = cdr_layout(message)
    assert length <= len(data)
    for start, stop in padding:
        data[start:stop] = bytes(stop - start)
    return bytes(data[:length])
