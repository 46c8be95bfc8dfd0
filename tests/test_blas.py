"""The hot paths' BLAS limit: one thread inside, the caller's setting restored after."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (loads scipy's own BLAS, which must be limited too)
from threadpoolctl import threadpool_info, threadpool_limits

from designkit.support.blas import one_blas_thread


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_blas_thread_inside_and_the_callers_setting_after():
    assert _blas_threads(), "numpy and scipy link a BLAS"
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        with one_blas_thread():
            assert _blas_threads() == [1] * len(before)
            a = np.random.default_rng(0).standard_normal((50, 50))
            np.testing.assert_allclose(a @ np.linalg.inv(a), np.eye(50), atol=1e-10)
        assert _blas_threads() == before


@pytest.mark.slow  # a benchmark's smoke test (CI runs it; fresh processes, timings only)
def test_bench_blas_smoke(tmp_path):
    from conftest import load_study

    r = load_study("bench_blas").run(tmp_path, quick=True)
    case = r["cases"]["array build"]
    assert case["median_s"]["one_thread"] > 0 and case["median_s"]["default"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench_blas.json"]
