"""The README's test command on a machine without GetDP: the FEM checks skip and the skips are
listed; under DESIGNKIT_CI (.ci/run) a missing GetDP stops the run instead."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_without_getdp_fem_checks_skip_locally_and_stop_ci(tmp_path):
    (tmp_path / "test_fem_like.py").write_text(
        "import shutil, pytest\n\n"
        "@pytest.mark.skipif(shutil.which('getdp') is None, reason='needs getdp')\n"
        "def test_fem():\n    pass\n\ndef test_other():\n    pass\n")
    empty = tmp_path / "bin"  # a PATH on which no getdp can be found
    empty.mkdir()
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{ROOT / 'tests'}", PATH=str(empty))
    env.pop("DESIGNKIT_CI", None)
    base = [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "conftest", "-p",
            "no:cacheprovider", str(tmp_path / "test_fem_like.py"), "--rootdir", str(tmp_path)]
    local = subprocess.run(base, env=env, capture_output=True, text=True, timeout=120)
    assert local.returncode == 0, local.stdout + local.stderr
    assert "1 passed, 1 skipped" in local.stdout and "needs getdp" in local.stdout
    env["DESIGNKIT_CI"] = "1"
    ci = subprocess.run(base, env=env, capture_output=True, text=True, timeout=120)
    assert ci.returncode == 4, ci.stdout + ci.stderr  # pytest's usage error: nothing ran
    assert "getdp" in ci.stderr and "passed" not in ci.stdout
