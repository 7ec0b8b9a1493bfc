"""The constant pieces of a link's gather (core/fe/second_order_reduced.py)."""

from flexlink_ros.core import options as core_options
from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.fe.second_order_reduced import gather_harmonics
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
import numpy as np
import pytest


@pytest.mark.parametrize('link', [0, 1, 2])
def test_three_pieces_give_the_gather_at_every_link_angle(link):
    options = core_options.ModelOptions.linear(bearings='flexible', rigid_crank=False,
                                               elements_per_link=3)
    mech = load_mechanism('cho1992')
    linkage = assembly.FlexibleLinkage(mechanism_model.fe_mechanism(mech, options), options)
    t0, t_cos, t_sin = gather_harmonics(linkage, link)
    angles = np.array([0.3, 1.9, -2.4, 4.0])
    expected = linkage.gather(link, angles)
    pieces = (t0[None] + np.cos(angles)[:, None, None] * t_cos[None]
              + np.sin(angles)[:, None, None] * t_sin[None])
    np.testing.assert_allclose(pieces, expected, rtol=0, atol=1e-15)
    # the end-node translations rotate; the rest of the gather is constant
    assert np.any(t_cos != 0.0) and np.any(t_sin != 0.0)
    assert set(np.unique(np.concatenate([t0.ravel(), t_cos.ravel(), t_sin.ravel()]))) <= \
        {-1.0, 0.0, 1.0}
