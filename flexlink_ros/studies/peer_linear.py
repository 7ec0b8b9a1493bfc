"""
The package's linear model with the conventions of the Exudyn peer (for comparisons and tests).

Rigid crank, the peer's bearings ('rigid' pins or bearing 'springs') and gravity switch,
geometric stiffness on: :func:`linear_model`, its static sag (:func:`linear_static`) and its
periodic response (:func:`linear_response`), with the peer's output keys.
"""

import dataclasses
import math

import numpy as np

from .peer_model import DEFAULT_ELEMENTS, OUTPUT_KEYS, resolve_mechanism
from ..core.fe.linkage import FlexibleLinkage
from ..core.fe.simulate import periodic_response
from ..core.options import ModelOptions


def linear_model(mechanism, *, elements_per_link=DEFAULT_ELEMENTS, bearings='rigid',
                 gravity=True):
    """Build the package's FE model (rigid crank) matching the peer's settings."""
    mech = dataclasses.replace(resolve_mechanism(mechanism), elements_per_link=elements_per_link)
    options = ModelOptions.full_model(
        rigid_crank=True, bearings={'rigid': 'rigid', 'springs': 'flexible'}[bearings],
        geometric_stiffness=True, gravity=gravity)
    return FlexibleLinkage(mech, options)


def linear_static(mechanism, crank_angle=0.0, *, elements_per_link=DEFAULT_ELEMENTS,
                  bearings='rigid'):
    """
    Solve the package's static deflection under gravity: (K + K_G) U = R at zero speed.

    Returns
    -------
    dict
        The four :data:`OUTPUT_KEYS` [m].

    """
    model = linear_model(mechanism, elements_per_link=elements_per_link, bearings=bearings,
                         gravity=True)
    theta = np.array([float(crank_angle)])
    system = model.assemble(theta)
    stiffness = system.frozen_stiffness(0.0)[0]
    displacement = np.linalg.solve(stiffness, system.load_at(0.0)[0])
    values = model.output_operator(theta)[0] @ displacement
    return dict(zip(OUTPUT_KEYS, (float(v) for v in values)))


def linear_response(mechanism, rpm, *, elements_per_link=DEFAULT_ELEMENTS, bearings='rigid',
                    gravity=True, zeta=None, steps=720, points=120):
    """
    Run the package's linear KED periodic response (``flexlink simulate --rigid-crank``).

    Returns
    -------
    dict
        'crank_angle' [rad] and the four :data:`OUTPUT_KEYS` [m] over one steady revolution,
        'info' of :func:`core.fe.simulate.periodic_response`.

    """
    model = linear_model(mechanism, elements_per_link=elements_per_link, bearings=bearings,
                         gravity=gravity)
    response = periodic_response(model, rpm * 2.0 * math.pi / 60.0, method='full',
                                 steps=steps, points=points, zeta=zeta)
    out = {'crank_angle': response.crank_angle}
    out.update(zip(OUTPUT_KEYS, response.outputs.T))
    out['info'] = response.info
    return out


__all__ = ['linear_model', 'linear_static', 'linear_response']
