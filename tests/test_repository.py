"""The repository keeps its own promises: CI fails when a required tool is missing and runs the
slow tests, no generated output is committed, imports point one way."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bin_without_getdp(tmp_path: Path) -> Path:
    """A PATH folder with python and the few tools .ci/run uses, but no getdp nor apt-get."""
    b = tmp_path / "bin"
    b.mkdir()
    for tool in ("dirname", "head", "cat", "id"):
        found = shutil.which(tool)
        if found:
            (b / tool).symlink_to(found)
    (b / "python3.11").symlink_to(sys.executable)
    (b / "python3").symlink_to(sys.executable)
    return b


def test_ci_script_fails_without_getdp(tmp_path):
    b = _bin_without_getdp(tmp_path)
    res = subprocess.run(["/bin/bash", str(ROOT / ".ci" / "run")], env={"PATH": str(b)},
                         capture_output=True, text=True, timeout=60)
    assert res.returncode != 0
    assert "getdp is required" in res.stderr
    assert not (ROOT / ".venv-ci-should-not-exist").exists()


def test_ci_script_runs_the_default_suite_and_the_slow_tests():
    # one session selects both (the default suite's 'not slow' and the slow checks)
    lines = [ln.split("#")[0].strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    calls = [ln for ln in lines if ln.startswith("run_pytest") and "()" not in ln]
    assert calls == ['run_pytest -m "slow or not slow"']
    assert "export DESIGNKIT_CI=1" in lines


def test_conftest_refuses_to_start_in_ci_without_getdp(tmp_path):
    b = _bin_without_getdp(tmp_path)
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "tests/test_pose.py"],
                         cwd=ROOT, env={"PATH": str(b), "DESIGNKIT_CI": "1",
                                        "PYTHONPATH": str(ROOT)},
                         capture_output=True, text=True, timeout=120)
    assert res.returncode != 0
    assert "getdp" in res.stdout + res.stderr


def test_conftest_turns_a_skip_into_a_failure_in_ci(tmp_path):
    (tmp_path / "test_skips.py").write_text(
        "import pytest\n\ndef test_a():\n    pytest.skip('tool missing')\n\n"
        "@pytest.mark.xfail(reason='known')\ndef test_b():\n    assert False\n")
    # a stand-in getdp on PATH: this test is about skips, and must not depend on whether the
    # machine running it has GetDP (conftest refuses to start in CI without one)
    stub = tmp_path / "bin"
    stub.mkdir()
    (stub / "getdp").write_text("#!/bin/sh\nexit 0\n")
    (stub / "getdp").chmod(0o755)
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{ROOT / 'tests'}",
               PATH=f"{stub}{os.pathsep}{os.environ.get('PATH', '')}")
    base = [sys.executable, "-m", "pytest", "-q", "-p", "conftest", "-p", "no:cacheprovider",
            str(tmp_path / "test_skips.py"), "--rootdir", str(tmp_path)]
    env.pop("DESIGNKIT_CI", None)
    local = subprocess.run(base, env=env, capture_output=True, text=True, timeout=120)
    assert local.returncode == 0, local.stdout
    env["DESIGNKIT_CI"] = "1"
    ci = subprocess.run(base, env=env, capture_output=True, text=True, timeout=120)
    assert ci.returncode == 1, ci.stdout
    assert "1 failed" in ci.stdout and "1 xfailed" in ci.stdout
    assert "tool missing" in ci.stdout


def test_no_test_skips_on_a_required_dependency():
    for path in (ROOT / "tests").glob("test_*.py"):
        if path.name != "test_repository.py":
            assert "pytest.importorskip(" not in path.read_text(), path.name


def test_readme_default_test_command_excludes_slow_tests():
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "-m 'not slow'" in cfg["addopts"]
    # one worker per core, each test file on one worker (its module fixtures built once)
    assert "-n auto --dist loadfile" in cfg["addopts"]
    assert "python -m pytest -m slow" in (ROOT / "README.md").read_text()


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="not a git checkout")
def test_no_generated_output_is_tracked_and_study_output_is_ignored():
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    assert not [t for t in tracked if t.split("/")[0] in
                ("bench-optimize-out", "studies_out", "study_out", "out")]
    for study in (ROOT / "studies").glob("*.py"):
        text = study.read_text()
        if "def run(" not in text:   # a helper module of the studies, it writes nothing
            continue
        assert '"out" / "' in text, f"{study.name}: default output not under out/"
    ignored = subprocess.run(["git", "check-ignore", "-q", "out/bench_map/bench_map.json"],
                             cwd=ROOT)
    assert ignored.returncode == 0


# ----------------------------------------------------------------------------- import direction
LAYERS = {  # a module may import only from the same or a lower layer
    "designkit.constants": 0, "designkit.errors": 0, "designkit.support": 1,
    "designkit.geometry": 2, "designkit.field": 2, "designkit.field.fourier_bessel": 1,
    "designkit.design": 2, "designkit.geometry.winding": 2,
    "designkit.model.electrical": 3,
    "designkit.cores": 3, "designkit.model.coil": 4, "designkit.model": 5,
}


def _layer(module: str) -> int | None:
    best = None
    for name, layer in LAYERS.items():
        if module == name or module.startswith(name + "."):
            best = layer
    return best


def _imports(path: Path, package: str) -> list[str]:
    """Every designkit module the file imports at run time, function-level imports included
    (imports under ``if TYPE_CHECKING:`` never run and are left out)."""
    tree = ast.parse(path.read_text())
    out: list[str] = []

    def visit(node, type_only=False):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            type_only = True
        if not type_only and isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - (node.level - 1)]
                mod = ".".join(parts + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("designkit"):
                for alias in node.names:  # "from . import electrical" imports a module
                    sub = f"{mod}.{alias.name}"
                    out.append(sub if _layer(sub) is not None and sub in LAYERS else mod)
        elif not type_only and isinstance(node, ast.Import):
            out.extend(a.name for a in node.names if a.name.startswith("designkit"))
        for child in ast.iter_child_nodes(node):
            visit(child, type_only)

    visit(tree)
    return out


def test_every_study_with_a_main_runs_as_a_script():
    # a study's command line (`python studies/X.py ...`) is what the docs and the README give
    missing = []
    for study in sorted((ROOT / "studies").glob("*.py")):
        text = study.read_text()
        if "\ndef main(" in text and 'if __name__ == "__main__":' not in text:
            missing.append(study.name)
    assert missing == []


def test_imports_point_one_way():
    """constants/errors <- field, design <- electrical, core <- coil <- array <- everything
    else, even inside functions."""
    bad = []
    for path in sorted((ROOT / "designkit").rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        module = ".".join(rel.parts).removesuffix(".__init__")
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        mine = _layer(module)
        if mine is None:
            continue
        for imp in _imports(path, package):
            theirs = _layer(imp)
            if theirs is not None and theirs > mine:
                bad.append(f"{module} (layer {mine}) imports {imp} (layer {theirs})")
    assert not bad, "\n".join(bad)


def test_firmware_io_imports_numpy_smbus2_and_the_standard_library_only():
    """firmware_io runs on the controller: every module, at any level (function-level imports
    included), imports numpy, smbus2 (the bus only) and the standard library, nothing else."""
    allowed = set(sys.stdlib_module_names) | {"numpy", "firmware_io"}
    bad = []
    for path in sorted((ROOT / "firmware_io").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            else:
                continue
            ok = allowed | ({"smbus2"} if path.name == "bus.py" else set())
            bad += [f"{path.name}: {n}" for n in names if n.split(".")[0] not in ok]
    assert not bad, "\n".join(bad)


def test_progress_bars_go_through_the_line_wise_wrapper():
    """Every progress bar writes plain lines when its stream is not a terminal: nothing but
    designkit.support.progress imports tqdm itself."""
    raw = set()
    for folder in ("designkit", "cad", "studies"):
        for path in (ROOT / folder).rglob("*.py"):
            tree = ast.parse(path.read_text())
            if any(isinstance(n, ast.ImportFrom) and n.level == 0 and n.module == "tqdm"
                   or isinstance(n, ast.Import) and any(a.name == "tqdm" for a in n.names)
                   for n in ast.walk(tree)):
                raw.add(path.relative_to(ROOT).as_posix())
    assert raw == {"designkit/support/progress.py"}


def test_field_kernels_do_not_import_the_design_spec():
    for path in (ROOT / "designkit" / "field").glob("*.py"):
        assert "design import" not in path.read_text(), path.name


def test_no_reference_to_notes_outside_the_repository():
    """Docstrings and comments cite only files that ship with the repository (or public
    datasheets by name): a reader of a clone cannot open a design note that is not there."""
    import re

    missing = []
    paths = [p for d in ("designkit", "cad", "firmware_io", "studies", "tests")
             for p in (ROOT / d).rglob("*.py")]
    for path in paths:
        for name in set(re.findall(r"\b([A-Z][A-Z_]+\.md)\b", path.read_text())):
            if not list(ROOT.glob(f"**/{name}")):
                missing.append(f"{path.relative_to(ROOT)}: {name}")
        if "shared/seed" in path.read_text() and path.name != "test_repository.py":
            missing.append(f"{path.relative_to(ROOT)}: shared/seed")
    assert not missing, "\n".join(missing)
