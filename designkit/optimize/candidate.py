"""A device's physical variables written into a :class:`designkit.design.Design`.

The optimizer and the array sweep search physical variables (:data:`DEVICE_VARIABLES`: winding
radii and length, core radius, length and protrusion, bare wire); a candidate becomes a design
by replacing the typed nested specs (coil, wire, core, array) of a base design, so the design's
own checks (no overlap, core in the bore) judge it.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

from ..design import CoreSpec, Design
from .device_problem import DeviceProblem


def device_candidate(base: Design, x: Sequence[float], turns: int, insulated_m: float, *,
                     pitch_m: float | None = None, **sections) -> Design:
    """``base`` with the coil, wire and 1010-steel core of the physical variables ``x``.

    Parameters
    ----------
    base : Design
        Everything not in ``x`` (a missing core starts from the default :class:`CoreSpec`).
    x : sequence of float, (>= 7,)
        :data:`designkit.optimize.DEVICE_VARIABLES`, SI (m).
    turns : int
    insulated_m : float
        Insulated wire diameter, m.
    pitch_m : float, optional
        Array pitch, m (default: the layout's).
    **sections
        Further top-level replacements (``name``, typed ``drive`` or ``workspace`` specs, the
        ``array`` layout).

    Raises BadInputError or DesignRuleError from the design's checks.
    """
    ri, ro, ln, a, lc, prot, d = x[:7]
    core = base.core if base.core is not None else CoreSpec()
    layout = sections.pop("array", base.array)
    if pitch_m is not None:
        layout = dataclasses.replace(layout, pitch_m=pitch_m)
    return dataclasses.replace(
        base,
        array=layout,
        coil=dataclasses.replace(base.coil, inner_radius_m=ri, outer_radius_m=ro, length_m=ln,
                                 turns=turns),
        wire=dataclasses.replace(base.wire, diameter_m=d, insulated_diameter_m=insulated_m),
        core=dataclasses.replace(core, radius_m=a, length_m=lc,
                                 offset_m=DeviceProblem.core_offset(x), bh="steel1010"),
        **sections)
