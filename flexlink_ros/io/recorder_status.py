"""
What a recording reports of itself: state, error, files and the counts of :meth:`status`.

:class:`RecordingStatus` is the part of :class:`~flexlink_ros.io.recorder.McapRecorder` that
diagnostics and the CLI read, from any thread and without the recorder's lock (the writing
thread may hold it through a slow disk write): each field is read once, so a status may be one
write apart from another. Its cost does not grow with the number of files unless their paths
are asked for.
"""

import os


class RecordingStatus:
    """State, error, files and status of the recorder (a mixin)."""

    @property
    def state(self):
        """Return the :class:`RecorderState`."""
        return self._state

    @property
    def error(self):
        """Return the OS error that stopped recording (None if none)."""
        return self._error

    @property
    def files(self):
        """Paths of every file written or being written."""
        paths = [entry['path'] for entry in self._closed_files]
        current = self._file    # read once: another thread may close it meanwhile
        if current is not None:
            paths.append(current.path)
        return paths

    def status(self, list_files=True):
        """
        Summary of the recording, for diagnostics and the CLI.

        Parameters
        ----------
        list_files : bool
            Include the path of every file (``files``); without it the cost does not grow
            with the number of files (diagnostics, every period).

        Returns
        -------
        dict
            ``state``, ``error``, ``path``, ``files`` (if listed), ``file_count``,
            ``message_count``, ``dropped_count`` (overflow included), ``overflow_count``
            (dropped because the write queue was full), ``queued_bytes``, ``topics``
            (name -> count), ``bytes_written``.

        """
        # Without the lock: the writing thread may hold it through a slow disk write, and
        # diagnostics must not wait for that (each field is read atomically; the set may be
        # one write apart).
        current = self._file    # read once: another thread may close it meanwhile
        size = self._closed_bytes
        if current is not None:
            try:
                size += os.fstat(current.stream.fileno()).st_size
            except (OSError, ValueError):
                pass
        status = {
            'state': self._state.value,
            'error': None if self._error is None else str(self._error),
            'path': str(self.path),
            'file_count': len(self._closed_files) + (current is not None),
            'message_count': self._message_count,
            'dropped_count': self._dropped + self._overflow,
            'overflow_count': self._overflow,
            'queued_bytes': self._queued_bytes,
            'topics': {t.name: t.message_count for t in self._topics.values()},
            'bytes_written': size,
        }
        if list_files:
            status['files'] = [str(p) for p in self.files]
        return status
