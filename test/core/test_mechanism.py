"""Mechanism dataclass: cache key, bounds that hold for every variant, crank-rocker check."""

import dataclasses

from flexlink_ros.core.mechanism import (check_crank_rocker, MAX_ELEMENTS_PER_LINK,
                                         Mechanism)
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.errors import MechanismError
import pytest


def test_key_changes_with_any_field():
    cho = load_mechanism('cho1992')
    assert cho.key() == load_mechanism('cho1992').key()
    assert cho.key() != dataclasses.replace(cho, damping_ratio=0.03).key()


def test_variants_are_bounded_too():
    cho = load_mechanism('cho1992')
    assert dataclasses.replace(cho, elements_per_link=MAX_ELEMENTS_PER_LINK).elements_per_link \
        == MAX_ELEMENTS_PER_LINK
    with pytest.raises(MechanismError, match='elements_per_link'):
        dataclasses.replace(cho, elements_per_link=10 ** 6)


def test_crank_rocker_check_names_the_reason():
    check_crank_rocker(0.238, 0.0785, 0.262, 0.240)
    with pytest.raises(MechanismError, match='Grashof'):
        check_crank_rocker(0.238, 0.0785, 0.45, 0.240)
    with pytest.raises(MechanismError, match='shorter than the crank'):
        check_crank_rocker(0.238, 0.25, 0.262, 0.240)


def test_a_grashof_linkage_that_is_not_a_crank_rocker_is_named_for_what_it_is():
    """A drag link's crank turns fully: "the crank cannot fully rotate" was false there."""
    with pytest.raises(MechanismError, match='double crank') as info:
        check_crank_rocker(0.05, 0.10, 0.12, 0.11)
    assert 'cannot fully rotate' not in str(info.value)
    with pytest.raises(MechanismError, match='double rocker'):
        check_crank_rocker(0.11, 0.10, 0.05, 0.12)
    with pytest.raises(MechanismError, match='rocker-crank'):
        check_crank_rocker(0.11, 0.10, 0.12, 0.05)


def test_default_joint_masses_are_zero():
    mechanism = Mechanism(name='m', ground_length=1.0, links=())
    assert mechanism.joint_masses == {'O2': 0.0, 'A': 0.0, 'B': 0.0, 'O4': 0.0}
