"""
The constant pieces of a link's gather on a reduced basis (the second-order tables' start).

With a constant basis V (U = V q, :mod:`core.reduction.model`) only the end-node translation
rows of T^T rotate with the link angle theta_L, ``T^T = T0 + cos T_c + sin T_s``
(:func:`gather_harmonics`), so the second-order forms of a link are quadratic forms in q with
constant harmonic pieces: the streamed tables (:mod:`core.reduction.second_order_tables`,
:mod:`core.reduction.second_order_dynamic_tables`) start from them. The other ways of
evaluating the same forms, compared in the second-order study, are in
``docs/studies/second_order_forms.py``.
"""

import numpy as np


def gather_harmonics(linkage, link):
    """
    Constant pieces of a link's gather, T^T(theta_L) = T0 + cos(theta_L) T_c + sin(theta_L) T_s.

    Only the end-node translation rows rotate (u^L = R^T (X, Y) there), so three evaluations of
    :meth:`FlexibleLinkage.gather` (theta_L = 0, pi/2, pi) give the pieces exactly.

    Returns
    -------
    ndarray, shape (3, 3 (e + 1), n)
        T0, T_c, T_s.

    """
    g = linkage.gather(link, np.array([0.0, 0.5 * np.pi, np.pi]))
    t0 = 0.5 * (g[0] + g[2])
    # entries are 0 and +-1: rounding drops the 1e-16 of sin(pi) and cos(pi / 2)
    return np.round(np.stack([t0, 0.5 * (g[0] - g[2]), g[1] - t0]))
