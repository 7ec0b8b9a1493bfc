"""Cho 1992's claims judged (studies/flex_claims.py) on small computed sweeps and responses."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import RPM
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import flex_claims, flex_frequencies
from flexlink_ros.studies.flex_frequencies import BEARINGS, PAPER_RPM
import numpy as np
import pytest


@pytest.fixture(scope='module')
def mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


@pytest.fixture(scope='module')
def sweeps(mechanism):
    cases = flex_frequencies.paper_frequency_cases()
    crank_deg = np.arange(0.0, 360.0, 30.0)
    return {key: flex_frequencies.sweep_case(mechanism, cases[key], crank_deg, 3)
            for key in ('flex', 'rigid_crank_kg_45', 'rigid_crank_bearings_kg_45')}


@pytest.fixture(scope='module')
def responses(mechanism):
    out = {}
    for bearings in BEARINGS:
        model = FlexibleLinkage(mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                   bearings=bearings))
        for rpm in PAPER_RPM:
            out[bearings, rpm] = periodic_response(model, rpm * RPM, 'full', steps=120,
                                                   points=30)
    return out


def test_fig7_claim_follows_the_spread_of_mode_three(sweeps):
    claim = flex_claims.claim_fig7({'sweeps': sweeps})
    assert claim['where'] == 'Fig. 7' and claim['measured'].count(' Hz') == 3
    spans = np.ptp(sweeps['flex'].frequencies_hz, axis=0)
    assert claim['verdict'] == ('agree' if spans[2] > 5.0 * spans[:2].max() else 'disagree')
    # with the modes reversed the widely varying one comes first: the claim fails
    flipped = dataclasses.replace(sweeps['flex'],
                                  frequencies_hz=sweeps['flex'].frequencies_hz[:, ::-1])
    assert flex_claims.claim_fig7({'sweeps': {'flex': flipped}})['verdict'] == 'disagree'


def test_resonance_band_spans_modes_one_and_two_of_the_bearing_model(sweeps):
    for bearings, key in (('rigid', 'rigid_crank_kg_45'),
                          ('flexible', 'rigid_crank_bearings_kg_45')):
        f = sweeps[key].frequencies_hz[:, :2]
        low, high = flex_claims.resonance_band(sweeps, bearings)
        assert (low, high) == pytest.approx((0.9 * f.min(), 1.1 * f.max()))
    # flexible bearings lower the frequencies
    assert flex_claims.resonance_band(sweeps, 'flexible')[0] < flex_claims.resonance_band(
        sweeps, 'rigid')[0]


def test_lever_tip_claim_agrees_and_fails_with_the_bearings_swapped(responses):
    claim = flex_claims.claim_lever_tip({'responses': responses})
    assert claim['verdict'] == 'agree' and claim['where'] == 'Fig. 20'
    swapped = {(('rigid' if b == 'flexible' else 'flexible'), rpm): r
               for (b, rpm), r in responses.items()}
    assert flex_claims.claim_lever_tip({'responses': swapped})['verdict'] == 'disagree'


def test_every_claim_is_listed_once():
    names = [claim.__name__ for claim in flex_claims.CLAIMS]
    assert len(names) == len(set(names)) and all(n.startswith('claim_') for n in names)
    assert {n for n in dir(flex_claims) if n.startswith('claim_')} == set(names)
