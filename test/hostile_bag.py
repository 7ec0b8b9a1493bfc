"""Entries a careless or hostile user puts into a bag directory, for the readers' tests."""

import os


ENTRIES = ('fifo_2.mcap', 'out_3.mcap', 'zero_4.mcap', 'dir_5.mcap')


def plant_hostile_entries(bag, outside, names=ENTRIES):
    """
    Put a FIFO, links out of the bag (to a file, to /dev/zero) and a directory, all *.mcap.

    Parameters
    ----------
    bag : pathlib.Path
        The bag directory.
    outside : pathlib.Path
        A regular MCAP file outside the bag.
    names : sequence of str
        Which of :data:`ENTRIES` to plant.

    Returns
    -------
    list of str
        The names planted.

    """
    plant = {'fifo_2.mcap': os.mkfifo, 'out_3.mcap': lambda path: os.symlink(outside, path),
             'zero_4.mcap': lambda path: os.symlink('/dev/zero', path),
             'dir_5.mcap': os.mkdir}
    for name in names:
        plant[name](bag / name)
    return list(names)
