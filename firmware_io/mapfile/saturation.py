"""The cores' saturation as the map stores it: :class:`SaturationTable` (numpy only).

Column k of A(p) (linear cores) is scaled by the factor ``s_k(|I_k|)`` at coil k's own current
(docs/coupling.md, "Saturation correction"): the force of coil k is F_k(p) g_k(I_k) with the
*linear-equivalent current* ``g_k(I) = s_k(|I|) I`` (A). ``s_k`` is the map's ``SAT_FACTOR``
(n_s, n_coils) at the currents ``SAT_I`` (n_s,) A, interpolated linearly in |I| and held at the
table's ends (as :func:`numpy.interp`). The runner allocates on the linearization of g about a
current (:meth:`SaturationTable.linearize`: the columns scaled by g' and the offset moved to the
target), which is exact where it is taken and off by ``g(I) - [g(I0) + g'(I0) (I - I0)]``
elsewhere (within one segment of the table ``|s'| (I - I0)^2``; across a node also the jump of
g' times the distance past it).
"""

from __future__ import annotations

import numpy as np


class SaturationTable:
    """Per-coil saturation factors s_k(|I|) (1 for air coils and linear cores).

    Parameters
    ----------
    current_a : array (n_s,), A -- strictly increasing from 0 (the map's ``SAT_I``)
    factor : array (n_s, n_coils) -- > 0 (the map's ``SAT_FACTOR``)

    Attributes: ``current_a``, ``factor``, ``n_coils``, ``linear`` (every factor 1: nothing to
    apply).
    """

    __slots__ = ("current_a", "factor", "slope", "n_coils", "linear", "_cols")

    def __init__(self, current_a, factor):
        self.current_a = np.asarray(current_a, dtype=float)
        self.factor = np.asarray(factor, dtype=float)
        self.n_coils = int(self.factor.shape[1])
        # ds/d|I| per segment (n_s - 1, n_coils), 1/A
        self.slope = np.diff(self.factor, axis=0) / np.diff(self.current_a)[:, None]
        self.linear = bool(np.all(self.factor == 1.0))
        self._cols = np.arange(self.n_coils)

    def _at(self, currents, coils=None) -> tuple[np.ndarray, np.ndarray]:
        """(s(|I|), ds/d|I|) for ``currents`` (m,) A of the coils ``coils`` (m indices; None:
        all); the slope is the segment's to the right of a node and 0 beyond the table (the
        table starts at 0 A: :func:`firmware_io.mapfile.format.validate`)."""
        a = np.abs(np.asarray(currents, dtype=float))
        cols = self._cols if coils is None else coils
        cur = self.current_a
        ac = np.minimum(a, cur[-1])
        j = np.minimum(np.searchsorted(cur, ac, side="right") - 1, len(cur) - 2)
        ds = self.slope[j, cols]
        s = self.factor[j, cols] + (ac - cur[j]) * ds
        if a.max(initial=0.0) > cur[-1]:
            ds = np.where(a > cur[-1], 0.0, ds)
        return s, ds

    def factor_at(self, currents, coils=None) -> np.ndarray:
        """s_k(|I_k|), shape of ``currents`` (n_coils,), or (len(coils),) with ``coils``."""
        return self._at(currents, coils)[0]

    def equivalent(self, currents, coils=None) -> np.ndarray:
        """The linear-equivalent currents g(I) = s(|I|) I, A (the currents that, on the linear
        columns of A, give the saturating cores' field)."""
        i = np.asarray(currents, dtype=float)
        return self._at(i, coils)[0] * i

    def linearize(self, currents, coils=None) -> tuple[np.ndarray, np.ndarray]:
        """(gain, offset) with g(I) ~ gain * I + offset near ``currents`` (A): gain = g'(I0) =
        s + |I0| s', offset = g(I0) - gain I0 = -s' |I0| I0 (A)."""
        i0 = np.asarray(currents, dtype=float)
        s, ds = self._at(i0, coils)
        a0 = np.abs(i0)
        return s + a0 * ds, -ds * a0 * i0

