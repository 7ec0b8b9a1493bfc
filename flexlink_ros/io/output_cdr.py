"""
The node's outputs as CDR: one message (the node, per sample) or many rows at once (replay).

Every output has a fixed layout for a frame, so each is serialised once as a template (zeroed
padding, :func:`.cdr.serialize_message`) and then only its stamp and values are written into a
copy: the deflections (``geometry_msgs/Vector3Stamped``, :func:`vector3_stamped_cdr`), the
joint criteria and the quality (``sensor_msgs/JointState``, :func:`criteria_cdr`,
:func:`quality_cdr`) and the deformed linkage (``visualization_msgs/MarkerArray`` of
:func:`linkage_markers`, :class:`MarkerEncoder`). The row encoders (:func:`vector3_stamped_rows`,
:func:`criteria_rows`, :func:`quality_rows`, :meth:`MarkerEncoder.encode_rows`) write many
messages at once as numpy rows. All are byte-identical to rclpy's ``serialize_message`` of the
same message (tested).
"""

import functools
import struct

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point
import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from .cdr import align, CDR_LE, ENCAPSULATION_SIZE, serialize_message
from ..names import JOINT_NAMES as JOINTS, QUALITY_NAMES

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)
LEVEL_COLOURS = {OK: (0.2, 0.7, 0.3), WARN: (1.0, 0.7, 0.0), ERROR: (0.9, 0.1, 0.1),
                 STALE: (0.5, 0.5, 0.5)}
LINK_COLOURS = ((0.25, 0.45, 0.85), (0.85, 0.4, 0.1), (0.2, 0.6, 0.4))


# -- one message -----------------------------------------------------------------------------

def _header_bytes(sec, nanosec, frame):
    return CDR_LE + struct.pack('<iII', sec, nanosec, len(frame) + 1) + frame + b'\x00'


def vector3_stamped_cdr(sec, nanosec, frame, x, y, z=0.0):
    """CDR bytes of a ``geometry_msgs/Vector3Stamped`` (frame as UTF-8 bytes)."""
    # One pack of the whole message: the lever tip's encoding is on the node's critical path.
    return _vector3_struct(frame).pack(CDR_LE, sec, nanosec, len(frame) + 1, frame, x, y, z)


@functools.lru_cache(maxsize=16)
def _vector3_struct(frame):
    """Return the struct of a frame's Vector3Stamped: header, frame, its NUL, padding, x y z."""
    head = len(CDR_LE) + 12 + len(frame) + 1
    return struct.Struct(f'<{len(CDR_LE)}siII{len(frame) + 1}s{align(head, 8) - head}x3d')


def criteria_cdr(sec, nanosec, frame, ratio, gamma_dot, force):
    """CDR bytes of the criteria ``sensor_msgs/JointState`` (fields: ros/messages.py)."""
    if len(ratio) == len(gamma_dot) == len(force) == len(JOINTS):
        # Per-sample path: the layout is fixed by the frame; patch a template (~1 us).
        template, offsets = criteria_template(frame)
        out = bytearray(template)
        _STAMP.pack_into(out, 4, sec, nanosec)
        _FOUR_DOUBLES.pack_into(out, offsets[0], *ratio)
        _FOUR_DOUBLES.pack_into(out, offsets[1], *gamma_dot)
        _FOUR_DOUBLES.pack_into(out, offsets[2], *force)
        return bytes(out)
    return _criteria_cdr_plain(sec, nanosec, frame, ratio, gamma_dot, force)


@functools.lru_cache(maxsize=16)
def criteria_template(frame):
    """Serialise the criteria message of a frame; return it and its three arrays' offsets."""
    joints = len(JOINTS)
    sentinels = [[1.0e300 + k * 1e285 + j * 1e284 for j in range(joints)] for k in range(3)]
    template = _criteria_cdr_plain(0, 0, frame, *sentinels)
    offsets = [template.index(struct.pack(f'<{joints}d', *values)) for values in sentinels]
    return template, offsets


_STAMP = struct.Struct('<iI')
_FOUR_DOUBLES = struct.Struct(f'<{len(JOINTS)}d')


def _criteria_cdr_plain(sec, nanosec, frame, ratio, gamma_dot, force):
    out = bytearray(_header_bytes(sec, nanosec, frame))
    out += bytes(align(len(out), 4) - len(out)) + struct.pack('<I', len(JOINTS))
    for name in JOINTS:
        out += bytes(align(len(out), 4) - len(out))
        out += struct.pack('<I', len(name) + 1) + name.encode() + b'\x00'
    for values in (ratio, gamma_dot, force):
        out += bytes(align(len(out), 4) - len(out)) + struct.pack('<I', len(values))
        out += bytes(align(len(out), 8) - len(out)) + struct.pack(f'<{len(values)}d', *values)
    return bytes(out)


# Two doubles the quality template holds where each sample's indicators go.
_QUALITY_SENTINELS = (1.0e300 + 3e285, 1.0e300 + 7e285)
_QUALITY_VALUES = struct.Struct('<2d')


@functools.lru_cache(maxsize=16)
def quality_template(frame):
    """Serialise the quality message of a frame (UTF-8); return it and its values' offset."""
    template = serialize_message(JointState(
        header=Header(frame_id=frame.decode()), name=list(QUALITY_NAMES),
        position=list(_QUALITY_SENTINELS)))
    return template, template.index(_QUALITY_VALUES.pack(*_QUALITY_SENTINELS))


def quality_cdr(sec, nanosec, frame, error_indicator, nonlinearity):
    """
    Return the CDR of the quality ``sensor_msgs/JointState`` (fields: ros/messages.py).

    name = QUALITY_NAMES, position = the two indicators (frame as UTF-8 bytes). The per-sample
    path: the layout is fixed by the frame, so a template is patched (~1 us).
    """
    template, offset = quality_template(frame)
    out = bytearray(template)
    _STAMP.pack_into(out, ENCAPSULATION_SIZE, sec, nanosec)
    _QUALITY_VALUES.pack_into(out, offset, error_indicator, nonlinearity)
    return bytes(out)


# -- the linkage as markers -------------------------------------------------------------------

def _colour(rgb, alpha=1.0):
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(alpha))


def linkage_markers(stamp, frame_id, link_points, link_deflections, exaggeration,
                    joint_positions, joint_levels, namespace='flexlink'):
    """
    Build the rigid and the deformed linkage as markers for RViz and Foxglove.

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time
        Stamp of every marker.
    frame_id : str
        Frame of every marker (the ground frame).
    link_points : sequence of ndarray, shape (n_k, 2)
        Rigid-body positions [m] of points along each link (crank, coupler, lever).
    link_deflections : sequence of ndarray, shape (n_k, 2)
        Elastic deflections [m] at those points, ground frame.
    exaggeration : float
        Factor applied to the deflections in the drawing.
    joint_positions : ndarray, shape (4, 2)
        O2, A, B, O4 [m].
    joint_levels : sequence of int, length 4
        Diagnostic level per joint (colours the joint spheres).
    namespace : str
        Prefix of the markers' namespaces (``<namespace>/rigid`` etc.).

    Returns
    -------
    visualization_msgs.msg.MarkerArray

    """
    header = Header(stamp=stamp, frame_id=frame_id)
    markers = []
    for k, (points, deflection) in enumerate(zip(link_points, link_deflections)):
        for kind, offset, rgb, alpha, width in (
                ('rigid', 0.0, (0.6, 0.6, 0.6), 0.5, 0.002),
                ('deformed', exaggeration, LINK_COLOURS[k], 1.0, 0.004)):
            marker = Marker(header=header, ns=f'{namespace}/{kind}', id=k,
                            type=Marker.LINE_STRIP, action=Marker.ADD)
            marker.pose.orientation.w = 1.0
            marker.scale.x = width
            marker.color = _colour(rgb, alpha)
            shown = np.asarray(points) + offset * np.asarray(deflection)
            marker.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in shown]
            markers.append(marker)
    for j, (position, level) in enumerate(zip(joint_positions, joint_levels)):
        marker = Marker(header=header, ns=f'{namespace}/joints', id=j, type=Marker.SPHERE,
                        action=Marker.ADD)
        marker.pose.position = Point(x=float(position[0]), y=float(position[1]), z=0.0)
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = marker.scale.z = 0.012
        marker.color = _colour(LEVEL_COLOURS[level])
        markers.append(marker)
    return MarkerArray(markers=markers)


class MarkerEncoder:
    """
    CDR of :func:`linkage_markers`, by patching a serialised template.

    The marker array has a fixed layout for a given frame id and number of points per link,
    so it is serialised once (exactly, zeroed padding) and each call writes only the stamps,
    the points of the rigid and deformed links, the joint positions and the joint colours.
    Offsets are found by serialising sentinel values; the result equals
    ``serialize_exact(linkage_markers(...))`` (tested).

    Parameters
    ----------
    frame_id : str
    points_per_link : int
    links : int
        Number of links (3).

    """

    _SENTINEL_STAMP = (0x5A5A5A5A, 0x1A2B3C4D)
    _COLOUR_AFTER_POSITION = 80   # bytes: position, orientation (7 doubles), scale (3 doubles)

    def __init__(self, frame_id, points_per_link, links=3):
        self.frame_id, self.count, self.links = frame_id, int(points_per_link), links
        index = np.arange(self.count, dtype=float)
        rigid = [np.stack([1e6 + 1e4 * k + index + 0.25, 2e6 + 1e4 * k + index + 0.25], axis=1)
                 for k in range(links)]
        offset = np.array([5e5, 5e5])
        joints = np.array([[7e6 + j + 0.5, 8e6 + j + 0.5] for j in range(4)])
        stamp = Time(sec=self._SENTINEL_STAMP[0], nanosec=self._SENTINEL_STAMP[1])
        template = serialize_message(linkage_markers(
            stamp, frame_id, rigid, [np.broadcast_to(offset, p.shape) for p in rigid], 1.0,
            joints, [OK] * 4))
        self.template = template
        self.stamp_offsets = self._find_all(template, struct.pack('<iI', *self._SENTINEL_STAMP))
        self.rigid_offsets = [template.index(struct.pack('<d', p[0, 0])) for p in rigid]
        self.deformed_offsets = [template.index(struct.pack('<d', p[0, 0] + offset[0]))
                                 for p in rigid]
        self.joint_offsets = [template.index(struct.pack('<dd', *q)) for q in joints]
        self.colours = {level: struct.pack('<4f', *rgb, 1.0)
                        for level, rgb in LEVEL_COLOURS.items()}

    @staticmethod
    def _find_all(data, pattern):
        found, start = [], 0
        while (position := data.find(pattern, start)) >= 0:
            found.append(position)
            start = position + 1
        return found

    def encode(self, stamp_ns, link_points, link_deflections, exaggeration, joint_positions,
               joint_levels):
        """
        Return the CDR bytes of the marker array (arguments as :func:`linkage_markers`).

        Parameters
        ----------
        stamp_ns : int
            Stamp [ns].
        link_points : sequence of ndarray, shape (points_per_link, 2)
            Rigid-body positions [m] of the points of each link.
        link_deflections : sequence of ndarray, shape (points_per_link, 2)
            Elastic deflections [m] at those points.
        exaggeration : float
            Factor applied to the deflections in the drawing.
        joint_positions : ndarray, shape (4, 2)
            O2, A, B, O4 [m].
        joint_levels : sequence of diagnostic levels, length 4
            Colours of the joint spheres.

        """
        out = bytearray(self.template)
        stamp = struct.pack('<iI', *divmod(int(stamp_ns), 1_000_000_000))
        for position in self.stamp_offsets:
            out[position:position + 8] = stamp
        block = np.zeros((self.count, 3))
        size = 24 * self.count
        for k in range(self.links):
            block[:, :2] = link_points[k]
            position = self.rigid_offsets[k]
            out[position:position + size] = block.tobytes()
            block[:, :2] = link_points[k] + exaggeration * np.asarray(link_deflections[k])
            position = self.deformed_offsets[k]
            out[position:position + size] = block.tobytes()
        for position, joint, level in zip(self.joint_offsets, joint_positions, joint_levels):
            out[position:position + 16] = struct.pack('<dd', joint[0], joint[1])
            colour = position + self._COLOUR_AFTER_POSITION
            out[colour:colour + 16] = self.colours[level]
        return bytes(out)

    def encode_rows(self, stamps_ns, link_points, link_deflections, exaggeration,
                    joint_positions, joint_levels):
        """
        Return the CDR of many marker arrays at once (as :meth:`encode`, a row per message).

        Parameters
        ----------
        stamps_ns : ndarray of int, shape (m,)
            Stamps [ns].
        link_points : ndarray, shape (m, links, points_per_link, 2)
            Rigid-body positions [m] of the points of each link.
        link_deflections : ndarray, shape (m, links, points_per_link, 2)
            Elastic deflections [m] at those points.
        exaggeration : float
            Factor applied to the deflections in the drawing.
        joint_positions : ndarray, shape (m, 4, 2)
            O2, A, B, O4 [m].
        joint_levels : sequence of diagnostic levels, length 4
            Colours of the joint spheres (the same for every message).

        Returns
        -------
        ndarray of uint8, shape (m, length)

        """
        count = len(stamps_ns)
        rows = _stamped_rows(self.template, stamps_ns, self.stamp_offsets)
        link_points = np.asarray(link_points, dtype=float)
        shown = link_points + exaggeration * np.asarray(link_deflections, dtype=float)
        block = np.zeros((count, self.count, 3))
        for k in range(self.links):
            block[:, :, :2] = link_points[:, k]
            _put_doubles(rows, self.rigid_offsets[k], block)
            block[:, :, :2] = shown[:, k]
            _put_doubles(rows, self.deformed_offsets[k], block)
        joint_positions = np.asarray(joint_positions, dtype=float)
        for j, (position, level) in enumerate(zip(self.joint_offsets, joint_levels)):
            _put_doubles(rows, position, joint_positions[:, j])
            colour = position + self._COLOUR_AFTER_POSITION
            rows[:, colour:colour + 16] = np.frombuffer(self.colours[level], dtype=np.uint8)
        return rows


# -- many messages at once ---------------------------------------------------------------------
#
# The fixed-layout messages above, for many stamps and values: one template row per message
# (numpy uint8 array of shape (m, length)) with the stamps and values written into their
# columns. Byte-identical to the one-message functions (tested).

def _stamp_columns(stamps_ns):
    sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
    stamp = np.empty(sec.size, dtype=[('sec', '<i4'), ('nanosec', '<u4')])
    stamp['sec'] = sec
    stamp['nanosec'] = nanosec
    return stamp.view(np.uint8).reshape(sec.size, 8)


def _stamped_rows(template, stamps_ns, stamp_offsets=(ENCAPSULATION_SIZE,)):
    """One copy of ``template`` per stamp, the stamp (sec, nanosec) at each offset."""
    rows = np.tile(np.frombuffer(template, dtype=np.uint8), (len(stamps_ns), 1))
    stamp = _stamp_columns(stamps_ns)
    for position in stamp_offsets:
        rows[:, position:position + 8] = stamp
    return rows


def _put_doubles(rows, offset, values):
    if not rows.shape[0]:       # no messages (a block without markers): reshape(0, -1) fails
        return
    values = np.ascontiguousarray(values, dtype='<f8').reshape(rows.shape[0], -1)
    rows[:, offset:offset + 8 * values.shape[1]] = values.view(np.uint8)


def rows_to_bytes(rows):
    """Split the rows of a (m, length) uint8 array into a list of m bytes objects."""
    blob = rows.tobytes()
    width = rows.shape[1]
    return [blob[k:k + width] for k in range(0, len(blob), width)]


def vector3_stamped_rows(stamps_ns, frame, values):
    """
    Return the CDR of many ``geometry_msgs/Vector3Stamped`` (as :func:`vector3_stamped_cdr`).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Stamps [ns].
    frame : bytes
        Frame id, UTF-8.
    values : ndarray, shape (m, 2) or (m, 3)
        x, y[, z] (z = 0 if absent).

    Returns
    -------
    ndarray of uint8, shape (m, length)

    """
    template = vector3_stamped_cdr(0, 0, frame, 0.0, 0.0, 0.0)
    rows = _stamped_rows(template, stamps_ns)
    _put_doubles(rows, len(template) - 24, values)
    return rows


def criteria_rows(stamps_ns, frame, ratio, gamma_dot, force):
    """
    Return the CDR of many criteria ``sensor_msgs/JointState`` (as :func:`criteria_cdr`).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Stamps [ns].
    frame : bytes
        Frame id, UTF-8.
    ratio : ndarray, shape (m, joints)
        Criterion |dgamma/dt| / R per joint (positions).
    gamma_dot : ndarray, shape (m, joints)
        dgamma/dt per joint (velocities).
    force : ndarray, shape (m, joints)
        Reaction force magnitude R per joint (efforts).

    Returns
    -------
    ndarray of uint8, shape (m, length)

    """
    template, offsets = criteria_template(frame)
    rows = _stamped_rows(template, stamps_ns)
    for offset, values in zip(offsets, (ratio, gamma_dot, force)):
        _put_doubles(rows, offset, values)
    return rows


def quality_rows(stamps_ns, frame, error_indicator, nonlinearity):
    """
    Return the CDR of many quality ``sensor_msgs/JointState`` (as :func:`quality_cdr`).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Stamps [ns].
    frame : bytes
        Frame id, UTF-8.
    error_indicator, nonlinearity : ndarray, shape (m,)
        The indicators [-] (NaN: not available).

    Returns
    -------
    ndarray of uint8, shape (m, length)

    """
    template, offset = quality_template(frame)
    rows = _stamped_rows(template, stamps_ns)
    _put_doubles(rows, offset, np.column_stack([error_indicator, nonlinearity]))
    return rows
