"""Numbers of the flexible four-bar section (studies/flex_data.py): the truncation mode counts."""

from flexlink_ros.studies.flex_data import mode_counts
import numpy as np


def test_quick_counts_are_a_handful_ending_at_the_full_size():
    assert mode_counts(30, quick=True).tolist() == [1, 2, 4, 30]


def test_dense_counts_take_every_count_to_eight_then_every_other():
    counts = mode_counts(17, quick=False)
    assert counts.tolist() == [1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 17]
    assert np.all(np.diff(counts) > 0)


def test_sparse_counts_take_every_fourth_and_the_last_three():
    assert mode_counts(20, quick=False, dense=False).tolist() == [
        1, 2, 3, 4, 5, 6, 8, 12, 16, 18, 19, 20]
