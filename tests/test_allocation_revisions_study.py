"""Smoke test of studies/bench_allocation_revisions.py: the allocation package of HEAD (git
archive) against the working tree, 30 problems a set, one pass; the answers agree."""

import shutil

import pytest

from conftest import ROOT, load_study


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="not a git checkout")
def test_bench_allocation_revisions_quick(tmp_path):
    res = load_study("bench_allocation_revisions").run(tmp_path, base="HEAD", n=30, passes=1)
    assert (tmp_path / "bench_allocation_revisions.json").is_file()
    assert res["largest_difference_a"] <= 1e-9
    assert len(res["timing"]) == 6 and all(r["ratio_median"] > 0 for r in res["timing"].values())
