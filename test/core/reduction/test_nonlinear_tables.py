"""
The reduced nonlinear model's tables (core/reduction/nonlinear_tables.py).

The interpolated tables equal the projected FE matrices between the grid nodes; the link's
lumped chord shortening 1/2 eta^T g_L eta is the sum of its elements' von Karman shortening
computed through the element strain of the full order; the basis is mass-orthonormal and
spans the chord responses it was built from.
"""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.nonlinear_strain import (element_coordinates, element_strain,
                                                   model_elements)
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import nonlinear_tables as nt
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
