"""recorder_files: an existing path is refused untouched; a link raced in is not followed."""

import os

from flexlink_ros.cli.mcap import mcap_info
from flexlink_ros.errors import RecorderError
from flexlink_ros.io.recorder import McapRecorder
import pytest
from recorder_helpers import record_samples, sample_messages, T0_NS
from sensor_msgs.msg import JointState


def _existing_paths(tmp_path):
    """Each kind of existing path, and the file whose bytes must survive (if any)."""
    victim = tmp_path / 'victim.txt'
    victim.write_bytes(b'precious bytes\n' * 100)
    old_bag = tmp_path / 'old.mcap'
    with McapRecorder(old_bag) as recorder:
        record_samples(recorder, 20)
    link = tmp_path / 'link.mcap'
    link.symlink_to(victim)
    dangling = tmp_path / 'dangling.mcap'
    dangling.symlink_to(tmp_path / 'nowhere' / 'target.mcap')
    dir_link = tmp_path / 'dir_link'
    (tmp_path / 'real_dir').mkdir()
    dir_link.symlink_to(tmp_path / 'real_dir')
    empty_dir = tmp_path / 'empty_bag'
    empty_dir.mkdir()
    return {'bare_mcap': (old_bag, 'a file of'), 'file': (victim, 'a file of'),
            'symlink_to_file': (link, 'symbolic link to'),
            'dangling_symlink': (dangling, 'dangling'),
            'symlink_to_directory': (dir_link, 'symbolic link to'),
            'empty_directory': (empty_dir, 'a directory')}


@pytest.mark.parametrize('kind', ['bare_mcap', 'file', 'symlink_to_file', 'dangling_symlink',
                                  'symlink_to_directory', 'empty_directory'])
def test_existing_path_of_any_kind_is_refused_and_left_untouched(tmp_path, kind):
    cases = _existing_paths(tmp_path)
    path, reason = cases[kind]
    before = {p: (p.read_bytes() if p.is_file() and not p.is_symlink() else None)
              for p in tmp_path.iterdir()}
    listing = sorted(os.listdir(tmp_path)) + sorted(os.listdir(tmp_path / 'real_dir'))
    recorder = McapRecorder(path)
    with pytest.raises(RecorderError, match='never overwrites') as info:
        recorder.open()
    assert reason in str(info.value)
    assert recorder.write('/joint_states', JointState(), T0_NS) is False
    recorder.close()
    after = {p: (p.read_bytes() if p.is_file() and not p.is_symlink() else None)
             for p in tmp_path.iterdir()}
    assert after == before     # bytes of the old bag and the link's target are the same
    assert sorted(os.listdir(tmp_path)) + sorted(os.listdir(tmp_path / 'real_dir')) == listing
    assert not (tmp_path / 'nowhere').exists()   # the dangling link was not created through
    assert mcap_info(tmp_path / 'old.mcap')['message_count'] == 20 * len(sample_messages(0))


def test_a_link_placed_between_check_and_create_is_not_followed(tmp_path, monkeypatch):
    from flexlink_ros.io import recorder as recorder_module
    victim = tmp_path / 'victim.txt'
    victim.write_bytes(b'keep')
    path = tmp_path / 'race.mcap'
    real_check = recorder_module.refuse_existing
    raced = []

    def check_then_race(candidate):
        real_check(candidate)
        if not raced:   # the check saw nothing; a real link appears before the file is made
            raced.append(candidate)
            path.symlink_to(victim)

    monkeypatch.setattr(recorder_module, 'refuse_existing', check_then_race)
    with pytest.raises(RecorderError, match='symbolic link'):
        McapRecorder(path).open()
    assert raced == [path]
    assert victim.read_bytes() == b'keep' and path.is_symlink()


def test_the_files_name_the_mcap_library_as_its_writer_does():
    """The header's library: mcap's own identifier, taken without importing its writer."""
    from flexlink_ros.io.recorder_files import LIBRARY
    from mcap.writer import LIBRARY_IDENTIFIER
    assert LIBRARY == f'flexlink_ros recorder; {LIBRARY_IDENTIFIER}'
