"""The small reduced nonlinear model the follower, span and replay tests share."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.nonlinear_tables import build_nonlinear_tables


def small_nonlinear_tables(beta_s):
    """
    Return the paper's linkage's nonlinear tables at 2 elements per link, 12 vectors.

    Rigid crank, bearing springs and stiffness-proportional damping ``beta_s`` [s]: small
    enough to build in seconds, with the resonance's physics.
    """
    mechanism = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    linkage = FlexibleLinkage(mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                 bearings='flexible'))
    return build_nonlinear_tables(linkage, beta_s, size=12, modes=10)
