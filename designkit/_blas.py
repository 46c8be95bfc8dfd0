"""BLAS on one thread for the hot paths built of many small dense products.

OpenBLAS wakes its threads for every matrix product; for the small products of the coupled
core solve and the optimizer's panel model they wait for a core far longer than they compute
when the machine is busy. Measured on a shared 2-core machine under load (load average 5-7,
one process per run, the same code with and without the limit): the 3 x 3 coupled array's
build (assembly of 2160 unknowns) 3.0 and 5.5 s with one thread vs 33.6 and 9.6 s with
OpenBLAS' two; ``solve_device(starts=2)`` 4.1 and 3.1 s vs 16.0 and 8.3 s. One large LU
factorization shows no consistent difference either way, so it is left outside the limit.
``studies/bench_blas.py`` repeats the measurement (load average 8.6-11.6: medians of 2,
array build 5.6 vs 34.5 s, device optimizer 4.7 vs 15.4 s).
"""

from __future__ import annotations

import functools

from threadpoolctl import ThreadpoolController

__all__ = ["one_blas_thread"]


@functools.lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    # the controller sees the BLAS libraries loaded when it is made: scipy ships its own
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401

    return ThreadpoolController()


def one_blas_thread():
    """Context manager: numpy's and scipy's BLAS on one thread inside the ``with`` block.

    Entering costs ~10 us (one cached controller), where ``threadpoolctl.threadpool_limits``
    scans the loaded libraries again each time (~0.8 ms): it is cheap enough for per-call use
    in loops such as localization's candidate positions.
    """
    return _controller().limit(limits=1, user_api="blas")
