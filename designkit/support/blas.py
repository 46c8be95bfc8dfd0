"""BLAS on one thread for the hot paths built of many small dense products.

A multi-threaded BLAS wakes its threads for every matrix product; for the small products of the
coupled core solve and the optimizer's panel model they wait for a core far longer than they
compute when the machine is busy, so these paths run with one thread. One large LU
factorization shows no consistent difference either way, so it is left outside the limit.
``python studies/bench_blas.py OUT`` measures both settings.
"""

from __future__ import annotations

import functools

import numpy  # noqa: F401  (loaded before the controller is made: it sees numpy's BLAS)
import scipy.linalg  # noqa: F401  (scipy ships its own BLAS, which must be limited too)
from threadpoolctl import ThreadpoolController

__all__ = ["one_blas_thread"]


@functools.lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    # the controller sees the BLAS libraries loaded when it is made
    return ThreadpoolController()


def one_blas_thread():
    """Context manager: numpy's and scipy's BLAS on one thread inside the ``with`` block.

    Entering reuses one cached controller, where ``threadpoolctl.threadpool_limits`` scans the
    loaded libraries again each time: it is cheap enough for per-call use in loops such as
    localization's candidate positions.
    """
    return _controller().limit(limits=1, user_api="blas")
