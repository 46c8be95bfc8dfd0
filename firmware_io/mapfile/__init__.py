"""The map file the controller runs on (format v2): the one definition, numpy and the stdlib only.

``designkit map`` writes it (:mod:`designkit.fieldmap` computes the arrays); the runner reads it
with this package alone. Everything about the format -- array names, shapes, validation,
interpolation -- is defined here and nowhere else:

* :mod:`.format`: the file's layout, writing, reading, validation, version refusal;
* :mod:`.drive`: :class:`DriveRecord`, the coils' drive (R model, L, supply, driver, bounds);
* :mod:`.harmonics`: the solid-harmonic maths of A's harmonic cells;
* :mod:`.cells`: A(p), the cell of a point and the per-cell products;
* :mod:`.modes`: the per-core (rho, z) tables (magnet pull, sensor-field modes) and kernels;
* :mod:`.grid`: trilinear interpolation on the bias force's residual grid;
* :mod:`.saturation`: :class:`SaturationTable`, the cores' saturation factors as applied;
* :mod:`.reader`: :class:`MapFile`, the loaded map;
* :mod:`.source`: :class:`ActuationSource`, the one interface of a map or a direct model.

What each array means, the layout's choices and the measured errors and costs:
docs/mapfile_format.md and docs/fieldmap.md.
"""

from .cells import (CELL_CHUNK, GATHER_BLOCK, GEMM_CAP, cell_index, cell_local, cells_many,
                    cells_one, prepare_cells)
from .drive import DriveRecord
from .format import (FORMAT, FORMAT_VERSION, N_MODE_Q, NQ_MAGNET, REBUILD, ROWS, UNITS,
                     array_names, data_hash, read, validate, write)
from .grid import grid_lists, trilinear, trilinear_one
from .harmonics import (harmonic_potential, harmonic_rows, harmonic_terms, monomial_exponents,
                        monomials, solid_harmonic_betas, solid_harmonic_coefficients,
                        solid_harmonics)
from .modes import (BATCH_CHUNK, gradient_tensor, kernel_rows_many, magnet_terms,
                    magnet_terms_one, mode_rows, modes_one, prepare_magnet, prepare_magnet_one,
                    prepare_modes, prepare_one)
from .reader import MapFile, check_currents
from .saturation import SaturationTable
from .source import ActuationSource, selection

__all__ = [
    "CELL_CHUNK", "GATHER_BLOCK", "GEMM_CAP", "cell_index", "cell_local", "cells_many",
    "cells_one", "prepare_cells", "FORMAT", "FORMAT_VERSION", "N_MODE_Q", "NQ_MAGNET", "REBUILD",
    "ROWS", "UNITS", "array_names", "data_hash", "read", "validate", "write", "grid_lists",
    "trilinear", "trilinear_one", "harmonic_potential", "harmonic_rows", "harmonic_terms",
    "monomial_exponents", "monomials", "solid_harmonic_betas", "solid_harmonic_coefficients",
    "solid_harmonics", "BATCH_CHUNK", "gradient_tensor", "kernel_rows_many", "magnet_terms",
    "magnet_terms_one", "mode_rows", "modes_one", "prepare_magnet", "prepare_magnet_one",
    "prepare_modes", "prepare_one", "MapFile", "check_currents", "ActuationSource", "selection",
    "DriveRecord", "SaturationTable",
]
