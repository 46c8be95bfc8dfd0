"""Closed-form on-axis field gradient of a thick winding (thesis eq. 2.14's force model).

With current density J and u the distance below the magnet, on the axis

    dBz/dz = mu0 J / 2 [Phi(H + Lc) - Phi(H)],
    Phi(u) = [ln(a + sqrt(a^2 + u^2)) - a / sqrt(a^2 + u^2)]_{a = Ri}^{Ro}.

Complex arguments are accepted, so derivatives in (Ri, Ro, Lc) can be taken by complex step.
Derivation and its check against :func:`designkit.field.winding_field`: docs/optimize.md.
"""

from __future__ import annotations

import numpy as np

from ..constants import MU0


def _phi(a1, a2, u):
    s1 = np.sqrt(a1 * a1 + u * u)
    s2 = np.sqrt(a2 * a2 + u * u)
    return np.log((a2 + s2) / (a1 + s1)) - a2 / s2 + a1 / s1


def axial_gradient_per_current_density(inner_radius, outer_radius, length, height):
    """dBz/dz on the axis at ``height`` above the top face of a thick winding, per unit J.

    Parameters (arrays broadcast; complex accepted for complex-step derivatives)
    ----------
    inner_radius, outer_radius, length, height : m

    Returns
    -------
    dBz/dz / J, T m / A (negative above a winding with positive J).
    """
    return 0.5 * MU0 * (_phi(inner_radius, outer_radius, height + length)
                        - _phi(inner_radius, outer_radius, height))

