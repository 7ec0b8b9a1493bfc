"""bag_lock: one holder at a time, across processes; a killed holder holds nothing."""

import signal
import subprocess
import sys

from flexlink_ros.errors import BagInUse
from flexlink_ros.io.bag_lock import lock_bag, unlock_bag
import pytest

HOLDER = """
import sys, time
from flexlink_ros.io.bag_lock import lock_bag
lock_bag(sys.argv[1])
print('held', flush=True)
time.sleep(600)
"""


def test_the_lock_has_one_holder_and_goes_with_a_killed_process(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    holder = subprocess.Popen([sys.executable, '-c', HOLDER, str(bag)], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline().strip() == 'held'
        with pytest.raises(BagInUse, match='is being recorded') as refused:
            lock_bag(bag)
        assert refused.value.exit_code == 2
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=10)
    mine = lock_bag(bag)            # the killed holder's lock went with it
    with pytest.raises(BagInUse):   # another descriptor, even in this process, is refused
        lock_bag(bag)
    unlock_bag(mine)
    unlock_bag(lock_bag(bag))
    unlock_bag(None)
