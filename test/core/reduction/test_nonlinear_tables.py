"""
The reduced nonlinear model's tables (core/reduction/nonlinear_tables.py).

The interpolated tables equal the projected FE matrices between the grid nodes; the link's
lumped chord shortening 1/2 eta^T g_L eta is the sum of its elements' von Karman shortening
computed through the element strain of the full order; the basis is mass-orthonormal and
spans the chord responses it was built from. Its size is what the singular values say, and
at that size (not below it) the reduced model follows the nonlinear full order through the
resonance, with a rigid and with a flexible crank.
"""

import dataclasses
import math

from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
from flexlink_ros.core.fe.nonlinear_strain import (element_coordinates, element_strain,
                                                   model_elements)
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import nonlinear_tables as nt
from flexlink_ros.core.reduction.basis import mass_weighted_pod
import numpy as np
import pytest


@pytest.fixture(scope='module')
def model():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=3)
    return FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings='flexible'))


@pytest.fixture(scope='module')
def tables(model):
    return nt.build_nonlinear_tables(model, 1e-4, size=16, modes=12)


def test_interpolated_tables_equal_the_projected_matrices_between_nodes(model, tables):
    theta = np.array([0.3 * 2 * np.pi / tables.grid_size, 2.0, 5.1])
    exact = nt.node_fields(model, tables.basis, model_elements(model), theta)
    read = tables.at(theta)
    for name, value in exact.items():
        scale = np.abs(value).max()
        assert np.abs(read[name] - value).max() <= 1e-4 * scale, name


def test_reading_the_tables_keeps_no_copy_of_them(tables):
    # a process streaming the model holds its tables once: reading every field (the numpy
    # step's call) adds one row per stage angle, not a per-cell copy of the tables
    theta = np.array([0.1, 0.1 + 2 * np.pi / tables.grid_size, 6.2])
    read = tables.at(theta)
    tables.at(theta[:1], ('output',))
    kept = sum(value.nbytes for value in vars(tables).values() if isinstance(value, np.ndarray))
    stored = sum(tables.to_arrays()[0][name].nbytes for name in tables.to_arrays()[0])
    row = tables.values.shape[1] * 8
    assert kept <= stored + len(theta) * row
    # the read is the Hermite cubic through the two nodes' values and slopes
    spacing = 2 * np.pi / tables.grid_size
    t = 0.1 / spacing
    first = (tables.values[0] * (2 * t ** 3 - 3 * t ** 2 + 1)
             + spacing * tables.slopes[0] * (t ** 3 - 2 * t ** 2 + t)
             + tables.values[1] * (3 * t ** 2 - 2 * t ** 3)
             + spacing * tables.slopes[1] * (t ** 3 - t ** 2))
    start, shape = tables.layout()['mass']
    np.testing.assert_allclose(read['mass'][0].ravel(), first[start:start + shape[0] * shape[1]],
                               rtol=1e-12, atol=1e-12 * np.abs(first).max())


def test_lumped_shortening_is_the_sum_of_the_elements_von_karman_shortening(model, tables):
    theta = np.array([1.3])
    elements = model_elements(model)
    gather, _ = nt.element_gathers(model, elements, theta)
    eta = np.random.default_rng(5).standard_normal(tables.size) * 1e-3
    q = element_coordinates(gather[0] @ tables.basis, eta)
    shortening = (element_strain(elements, q) - element_strain(elements, q, nonlinear=False))
    shortening = shortening * elements.length
    fields = tables.at(theta)
    for index, link in enumerate(model.links):
        lumped = 0.5 * eta @ fields['shortening'][0, index] @ eta
        expected = shortening[elements.link == link].sum()
        assert lumped == pytest.approx(expected, rel=1e-4)
        elongation = q[elements.link == link] @ np.array([-1.0, 0, 0, 1.0, 0, 0])
        assert fields['chord'][0, index] @ eta == pytest.approx(elongation.sum(), rel=1e-4)


def test_basis_is_mass_orthonormal_and_holds_the_chord_responses(model):
    basis = nt.reduced_basis(model, angles=8, modes=10, size=model.size)
    mass = model.assemble(2 * np.pi * np.arange(8) / 8).mass.mean(axis=0)
    np.testing.assert_allclose(basis.T @ mass @ basis, np.eye(basis.shape[1]), atol=1e-8)
    small = nt.reduced_basis(model, angles=8, modes=10, size=14)
    system = model.assemble(np.array([0.0]))
    elements = model_elements(model)
    gather, _ = nt.element_gathers(model, elements, np.array([0.0]))
    chord = nt.link_chord_gradients(model, elements, gather)[0]
    response = np.linalg.solve(system.stiffness[0], chord.T)
    fit = small @ np.linalg.lstsq(small, response, rcond=None)[0]
    # 14 directions of 8 x 15 snapshots keep the chord responses to a few per cent
    assert np.abs(fit - response).max() < 0.05 * np.abs(response).max()


def test_basis_size_counts_the_singular_values_down_to_the_tolerance():
    values = np.array([4.0, 1.0, 4e-3, 3.9e-3, 1e-7])
    assert nt.basis_size(values, tolerance=1e-3) == 3
    assert nt.basis_size(values, tolerance=1e-4) == 4
    assert nt.basis_size(np.zeros(3)) == 0


@pytest.mark.parametrize('bearings, expected', [('flexible', 20), ('rigid', 14)])
def test_default_basis_has_the_size_its_singular_values_give(bearings, expected):
    # the bench's model: rigid crank, 8 elements per link (54 DOFs with bearing springs)
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=8)
    bench = FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings=bearings))
    snapshots, mass = nt.basis_snapshots(bench)
    _, singular = mass_weighted_pod(snapshots, mass, 1)
    basis = nt.reduced_basis(bench)
    assert basis.shape[1] == nt.basis_size(singular) == expected
    # the kept directions are the snapshots' rank: the next one is far below the last kept
    assert singular[expected] < 0.5 * singular[expected - 1]
    assert nt.reduced_basis(bench, size=12).shape[1] == 12
    with pytest.raises(ValueError):
        nt.reduced_basis(bench, size=bench.size + 1)


def _streamed_last_revolution(tables, speed, steps, points, revolutions=20):
    """Step the reduced model from rest at ``steps`` per revolution; its last turn's points."""
    count = revolutions * steps + 1
    stamps = np.round(np.arange(count) * 2.0 * math.pi / speed / steps * 1e9).astype(np.int64)
    out = estimate_nonlinear(tables, stamps, speed * stamps * 1e-9, np.full(count, speed))
    assert out['refused'] == 0
    return out['outputs'][-steps - 1:-1:steps // points]


def _basis_errors(model, rpm, sizes, steps=360, points=36):
    """Relative RMS (lever tip, coupler mid) against the full order, per basis option dict."""
    speed = rpm * math.pi / 30.0
    reference = nonlinear_response(model, speed, steps=steps, points=points, zeta=0.0,
                                   beta=1e-4).outputs
    out = []
    for options in sizes:
        tables = nt.build_nonlinear_tables(model, 1e-4, **options)
        mine = _streamed_last_revolution(tables, speed, steps, points)
        error = mine - reference
        out.append((tables.size, [math.sqrt((error[:, p] ** 2).sum(axis=1).mean()
                                            / (reference[:, p] ** 2).sum(axis=1).mean())
                                  for p in (slice(0, 2), slice(2, 4))]))
    return out


def test_default_basis_follows_the_full_order_through_the_resonance_and_a_smaller_one_not():
    # rigid crank, bearing springs, 4 elements per link (30 DOFs), beta 1e-4 s, 405 rpm (the
    # resonance's upper peak): the rule keeps 20 directions, measured 1.5 / 1.8 % (lever tip /
    # coupler mid) against the nonlinear full order; 16 directions were 15 / 44 % off
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=4)
    small = FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings='flexible'))
    (chosen, good), (_, cut) = _basis_errors(small, 405.0, [{}, {'size': 16}])
    assert chosen == 20
    assert max(good) < 0.05
    assert max(cut) > 0.10


def test_the_nodes_flexible_crank_model_follows_the_full_order_at_the_papers_speed():
    # the node's default model: flexible crank, bearing springs, 4 elements per link (44 DOFs),
    # 391 rpm; the rule keeps 27 directions of the 8-mode snapshots (1.7 / 2.9 % measured at
    # 720 steps per revolution); the 30 directions of 20-mode snapshots (rank 35) were 10 / 17 %
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=4)
    node = FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=False, bearings='flexible'))
    (chosen, good), (_, cut) = _basis_errors(node, 391.0, [{}, {'size': 30, 'modes': 20}])
    assert chosen == 27
    assert max(good) < 0.05
    assert max(cut) > 0.08
