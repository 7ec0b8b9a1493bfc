"""
The nonlinear full order's periodic response (core/fe/nonlinear_response.py).

With the linear strain (and K_G) it reproduces the linear periodic_response, flexible or rigid
crank, springs or pins; undamped and unloaded, free vibration keeps the nonlinear strain plus
kinetic energy to the integrator's accuracy; the time step converges at the method's order;
the nonlinear orbit at the paper's speed differs from the linear one and is stable.
"""

import dataclasses
import math

from flexlink_ros.core.fe import nonlinear_response as nr
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.nonlinear_step import STRAINS
from flexlink_ros.core.fe.nonlinear_strain import element_gather, strain_energy
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

SPEED = 391.0 * math.pi / 30.0


def _model(elements=2, gravity=True, **options):
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=elements)
    return FlexibleLinkage(mech, ModelOptions.full_model(gravity=gravity, **options))


@pytest.mark.parametrize('options', [{'rigid_crank': True, 'bearings': 'flexible'},
                                     {'rigid_crank': False, 'bearings': 'rigid'}],
                         ids=['rigid-crank-springs', 'flexible-crank-pins'])
def test_linear_strain_reproduces_the_linear_periodic_response(options):
    model = _model(**options)
    kwargs = {'steps': 240, 'points': 60, 'zeta': 0.01, 'beta': 1e-4}
    linear = periodic_response(model, SPEED, **kwargs)
    mine = nr.nonlinear_response(model, SPEED, nonlinear=False, start=np.zeros(2 * model.size),
                                 **kwargs)
    scale = np.abs(linear.outputs).max()
    assert np.abs(mine.outputs - linear.outputs).max() < 1e-11 * scale
    assert (np.abs(mine.displacement - linear.displacement).max()
            < 1e-11 * np.abs(linear.displacement).max())
    np.testing.assert_allclose(np.abs(mine.floquet_multipliers),
                               np.abs(linear.floquet_multipliers), rtol=0, atol=1e-9)
    info = mine.info
    assert info['newton_max'] <= 2 and info['shooting_updates'] == 1    # affine: one update
    assert info['periodicity'] < 1e-8 and not info['nonlinear']


def _energy_function(model, law):
    """Kinetic + strain + bearing energy [J] of (U, U') at crank angle 0 (the crank at rest)."""
    angle = np.array([0.0])
    mass = model.assemble(angle).mass[0]
    link_angle = model.kinematic_coefficients(angle)[0]
    gather = element_gather(law.elements,
                            {link: model.gather(link, link_angle[link])[0]
                             for link in model.links})
    bearing = np.asarray(model.bearing_stiffness)

    def energy(q, v, nonlinear=True):
        q_e = np.einsum('eai,i->ea', gather, q)
        strain = (law.strain_energy(q_e) if nonlinear
                  else strain_energy(law.elements, q_e, nonlinear=False))
        return float(0.5 * v @ mass @ v + strain + 0.5 * q @ bearing @ q)

    return energy


@pytest.mark.parametrize('strain', STRAINS)
def test_free_vibration_keeps_the_nonlinear_energy(strain):
    """
    Crank at rest, no gravity, no damping: the lowest mode launched to ~5 mm at the coupler.

    Measured drift over 40 ms (von Karman strain): 2.1e-5, 2.6e-6, 3.6e-7 at h = 200, 100,
    50 us (order 3); the quadratic (linear-strain) energy of the same motion is not kept.
    """
    model = _model(elements=3, gravity=False, rigid_crank=True, bearings='flexible')
    system = model.assemble(np.array([0.0]))
    values, shapes = np.linalg.eig(np.linalg.solve(system.mass[0], system.stiffness[0]))
    lowest = np.argmin(values.real)
    shape = shapes[:, lowest].real
    mid = model.output_operator(np.array([0.0]))[0, 2:]
    shape *= 5e-3 / np.abs(mid @ shape).max()
    velocity = math.sqrt(values.real[lowest]) * shape
    law = nr.make_run(model, 1.0, 1, 1, 2, 0.0, 0.0, True, 0.0, strain).law
    energy = _energy_function(model, law)
    drift = {}
    for h in (2e-4, 1e-4):
        run = nr.Run(law=law, integrator=nr.RadauIIA(2), speed=0.0, h=h, steps=int(0.04 / h),
                     stride=1, start_angle=0.0, zeta=0.0)
        out = nr.march(model, run, np.zeros(model.size), velocity, run.steps)
        energies = np.array([energy(q, v) for q, v in out['saved']])
        drift[h] = np.abs(energies - energies[0]).max() / energies[0]
        assert out['iterations'].max() >= 3           # the strain is nonlinear here
    quadratic = np.array([energy(q, v, nonlinear=False) for q, v in out['saved']])
    assert drift[1e-4] < 1e-5
    assert drift[1e-4] < 0.25 * drift[2e-4]
    assert np.abs(quadratic - quadratic[0]).max() / quadratic[0] > 100.0 * drift[1e-4]


def test_time_step_converges_at_third_order():
    """
    Two-stage Radau IIA (order 3) over a tenth of a revolution at 391 rpm.

    From three times the linear periodic state, first relaxed for 48 fine steps (the
    nonlinear axial strain settles), then 9, 18, 36 and 72 steps against 288: measured
    orders 2.6, 3.0, 3.0.
    """
    model = _model(elements=2, rigid_crank=True, bearings='flexible')
    start = periodic_response(model, SPEED, steps=240, points=60, zeta=0.0, beta=1e-4)
    fine = nr.make_run(model, SPEED, 2880, 1, 2, 0.0, 1e-4, True, 0.0)
    relaxed = nr.march(model, fine, 3.0 * start.displacement[0], 3.0 * start.velocity[0], 48)
    angle = SPEED * fine.h * 48
    ends = {}
    for steps in (9, 18, 36, 72, 288):
        run = nr.make_run(model, SPEED, 10 * steps, 1, 2, 0.0, 1e-4, True, angle)
        out = nr.march(model, run, relaxed['q'], relaxed['v'], steps)
        end_angle = np.array([angle + SPEED * run.h * steps])
        ends[steps] = model.output_operator(end_angle)[0] @ out['q']
    errors = [np.abs(ends[k] - ends[288]).max() for k in (9, 18, 36, 72)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 2.4) and orders[-1] > 2.8, orders


@pytest.mark.parametrize('options, least_change', [
    ({'rigid_crank': True, 'bearings': 'flexible'}, 0.1),      # measured: up to 0.45
    ({'rigid_crank': False, 'bearings': 'rigid'}, 0.02)],      # measured: up to 0.045
    ids=['rigid-crank-springs', 'flexible-crank-pins'])
def test_nonlinear_orbit_at_the_papers_speed(options, least_change):
    """The nonlinear orbit differs from the linear one (by most near resonance), stable."""
    model = _model(elements=2, **options)
    kwargs = {'steps': 360, 'points': 60, 'zeta': 0.0, 'beta': 1e-4}
    linear = periodic_response(model, SPEED, **kwargs)
    mine = nr.nonlinear_response(model, SPEED, **kwargs)
    change = np.abs(mine.peak_to_peak / linear.peak_to_peak - 1.0)
    assert change.max() > least_change
    assert mine.info['spectral_radius'] < 1.0 and mine.info['periodicity'] < 1e-8
    assert 2.0 <= mine.info['newton_mean'] <= 5.0
    assert mine.floquet_multipliers.shape == (2 * model.size,)


def test_kept_stage_systems_give_the_same_revolution():
    model = _model(elements=2, rigid_crank=True, bearings='flexible')
    run = nr.make_run(model, SPEED, 120, 60, 2, 0.0, 1e-4, True, 0.0)
    q0 = np.full(model.size, 1e-4)
    cache = []
    first = nr.march(model, run, q0, np.zeros(model.size), 120, True, cache=cache)
    assert len(cache) == 120 and nr.stage_bytes(model, run, 120) < nr.STAGE_CACHE_BYTES
    again = nr.march(model, run, q0, np.zeros(model.size), 120, True, cache=cache)
    fresh = nr.march(model, run, q0, np.zeros(model.size), 120, True)
    for key in ('q', 'v', 'monodromy'):
        np.testing.assert_array_equal(again[key], fresh[key])
        np.testing.assert_array_equal(first[key], fresh[key])


def test_mesh_converges():
    """
    A quarter revolution at 391 rpm from rest in the moving frames, 2, 4 and 8 elements.

    The end outputs of 2 and 4 elements against 8: measured 4.8 % and 0.26 % of the largest
    output (docs/nonlinear.md has the periodic orbit's p2p per mesh).
    """
    ends = {}
    for elements in (2, 4, 8):
        model = _model(elements=elements, rigid_crank=True, bearings='flexible')
        run = nr.make_run(model, SPEED, 720, 1, 2, 0.0, 1e-4, True, 0.0)
        zero = np.zeros(model.size)
        out = nr.march(model, run, zero, zero, 180)
        ends[elements] = model.output_operator(np.array([SPEED * run.h * 180]))[0] @ out['q']
    scale = np.abs(ends[8]).max()
    errors = [np.abs(ends[k] - ends[8]).max() / scale for k in (2, 4)]
    assert scale > 1e-4 and errors[1] < errors[0] / 3.0, errors


def test_floquet_multipliers_are_the_finite_difference_monodromys():
    """
    Multipliers: the eigenvalues of the monodromy, itself the revolution's derivative.

    The monodromy P of a revolution marched from the periodic state has the response's
    multipliers as eigenvalues; along random directions d, P d equals the central difference
    of two revolutions marched from the state perturbed by +-d (co-rotational strain, 391 rpm,
    near resonance).
    """
    model = _model(elements=2, rigid_crank=True, bearings='flexible')
    steps = 120
    orbit = nr.nonlinear_response(model, SPEED, steps=steps, points=60, zeta=0.0, beta=1e-4)
    assert orbit.info['strain'] == 'corotational'
    run = nr.make_run(model, SPEED, steps, 60, 2, 0.0, 1e-4, True, 0.0)
    n = model.size
    start = np.concatenate([orbit.displacement[0], orbit.velocity[0]])
    cache = []
    monodromy = nr.march(model, run, start[:n], start[n:], steps, True, cache=cache)['monodromy']
    mine = orbit.floquet_multipliers
    assert 0.3 < abs(mine[0]) < 1.0
    eigenvalues = np.linalg.eigvals(monodromy)
    for mu in mine[:8]:
        assert np.abs(eigenvalues - mu).min() < 1e-6 * abs(mine[0])
    sizes = np.repeat([np.abs(start[:n]).max(), np.abs(start[n:]).max()], n)
    rng = np.random.default_rng(5)
    for _ in range(3):
        direction = 1e-4 * sizes * rng.standard_normal(2 * n)
        ends = [nr.march(model, run, z[:n], z[n:], steps, cache=cache)
                for z in (start + direction, start - direction)]
        numeric = 0.5 * np.concatenate([ends[0]['q'] - ends[1]['q'],
                                        ends[0]['v'] - ends[1]['v']])
        exact = monodromy @ direction
        for block in (slice(0, n), slice(n, 2 * n)):
            np.testing.assert_allclose(numeric[block], exact[block], rtol=0,
                                       atol=1e-5 * np.abs(exact[block]).max())
