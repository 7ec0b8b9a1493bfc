"""
What flexlink_node can tell about its input beyond single messages (no rclpy here).

Two things a message cannot say by itself, judged once per diagnostics period:

- **Input lost before the node took it.** A crank sampled at a fixed rate gives stamps at a
  steady spacing; a gap of k spacings means k - 1 messages that never reached the callback
  (dropped by the middleware or the subscription's history while the node was behind). The
  spacing is the median positive stamp step of the period; gaps beyond the estimator's reset
  gap are pauses, not losses. With the time the callback was busy, a loss while the node was
  busy most of the period means the input rate exceeds what the node can take.
- **Several publishers on the input topic while outliers are frequent** (from the ROS graph):
  interleaved sources with different crank angles look like a stream of outliers.

Both give one sentence each for the log (rate-limited by the caller) and ``/diagnostics``.
"""

import numpy as np

# Stamps kept per period (beyond them the rest of the period is not judged): 20 s at 10 kHz.
MAX_STAMPS = 200_000
# Say so when at least this share of the messages the stamps imply is missing ...
LOSS_FRACTION = 0.05
MIN_LOST = 10           # ... and at least this many.
# A gap counts from 1.5 spacings: timer jitter of up to half a spacing is not a loss.
GAP_SPACINGS = 1.5
# Busy for at least this share of the period: the node, not the link, is the limit.
BUSY_FRACTION = 0.5
# Several publishers are suspect when at least this share of the messages are refused as
# outliers or conflicting ...
REFUSED_FRACTION = 0.1
MIN_REFUSED = 10        # ... and at least this many.


def lost_messages(stamps_ns, reset_gap_ns):
    """
    Estimate the messages missing between ``stamps_ns`` (in arrival order).

    Parameters
    ----------
    stamps_ns : array_like of int
        Stamps of the messages received [ns].
    reset_gap_ns : int
        Longer gaps are pauses of the publisher, not losses [ns].

    Returns
    -------
    lost : int
        Messages the gaps imply, at the median positive spacing.
    spacing_ns : float
        That spacing (NaN with fewer than two forward steps).

    """
    steps = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    forward = steps[steps > 0]
    if forward.size < 2:
        return 0, float('nan')
    spacing = float(np.median(forward))
    gaps = forward[(forward >= GAP_SPACINGS * spacing) & (forward <= reset_gap_ns)]
    return int(np.sum(np.rint(gaps / spacing) - 1)), spacing


class InputWatch:
    """Stamps and busy time of the current diagnostics period, judged at its end."""

    def __init__(self):
        self.stamps = []
        self.busy_ns = 0        # time in the input callback
        self.received = 0       # callbacks

    def note(self, stamp_ns):
        """Keep a received message's stamp (up to MAX_STAMPS a period)."""
        if len(self.stamps) < MAX_STAMPS:
            self.stamps.append(stamp_ns)

    def judge(self, elapsed_s, refused, publishers, reset_gap_s):
        """
        Return the period's facts and the sentences to say, and start a new period.

        Parameters
        ----------
        elapsed_s : float
            Length of the period [s].
        refused : int
            Of them, refused as outliers or conflicting.
        publishers : int
            Publishers of the input topic in the ROS graph.
        reset_gap_s : float
            The estimator's reset gap [s].

        Returns
        -------
        facts : dict
            'lost_in_period', 'busy_fraction', 'publishers' (key values of /diagnostics).
        sentences : list of str

        """
        stamps, busy_ns, received = self.stamps, self.busy_ns, self.received
        self.stamps, self.busy_ns, self.received = [], 0, 0
        busy = busy_ns * 1e-9 / max(elapsed_s, 1e-9)
        lost, spacing = (0, float('nan')) if publishers > 1 else lost_messages(
            stamps, int(reset_gap_s * 1e9))
        facts = {'lost_in_period': lost, 'busy_fraction': round(busy, 3),
                 'publishers': publishers}
        sentences = []
        if lost >= MIN_LOST and lost >= LOSS_FRACTION * (lost + len(stamps)):
            sentence = (f'about {lost} of {lost + len(stamps)} input messages '
                        f'({100 * lost / (lost + len(stamps)):.0f} %) missing in the last '
                        f'{elapsed_s:.3g} s (gaps in the stamps, spaced {spacing * 1e-6:.3g} ms)')
            if busy >= BUSY_FRACTION:
                # The input's rate is the stamps' (a node behind its input takes in a period
                # the messages of a shorter span); what the node took is what it received.
                sentence += (f': the input rate ({1e9 / spacing:.0f} Hz, from the stamps) '
                             f'exceeds what this node took ({received / elapsed_s:.0f} Hz; '
                             f'busy {100 * min(busy, 1.0):.0f} % of the time)')
            sentences.append(sentence)
        if publishers > 1 and refused >= MIN_REFUSED and refused >= REFUSED_FRACTION * received:
            sentences.append(f'{publishers} publishers feed the input topic while '
                             f'{100 * refused / max(received, 1):.0f} % of its messages are '
                             'outliers or conflicting: do several sources publish different '
                             'crank angles? (ros2 topic info -v)')
        return facts, sentences
