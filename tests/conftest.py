import os
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
os.environ.setdefault("MPLBACKEND", "Agg")

DATA = Path(__file__).resolve().parent / "data"
"""Cached references (tests/data/make_*.py regenerate them)."""


def _hypothesis_profiles() -> None:
    """Reproducible property tests: a fixed seed locally ('dev'), derandomized in CI ('ci',
    chosen by DESIGNKIT_CI or CI); HYPOTHESIS_PROFILE=explore draws fresh examples."""
    from hypothesis import HealthCheck, settings

    settings.register_profile("dev", derandomize=True, deadline=None,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.register_profile("explore", derandomize=False, deadline=None)
    ci = os.environ.get("DESIGNKIT_CI") or os.environ.get("CI")
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if ci else "dev"))


_hypothesis_profiles()


@pytest.fixture(autouse=True)
def collector_given_back():
    """A runner a test starts and never stops (the runner takes the garbage collector while
    it runs: firmware_io.runner.collector) must not leave it off for the tests after it."""
    import gc

    enabled = gc.isenabled()
    yield
    if enabled and not gc.isenabled():
        gc.enable()


@pytest.fixture(scope="session")
def thesis_array():
    """The default design's coupled 3 x 3 array (its one LU solve shared by every test)."""
    from designkit.model.array import CoilArray
    from designkit.design import default_design

    arr = CoilArray.from_design(default_design())
    arr.coupled()
    return arr


@pytest.fixture(scope="session")
def fem_solve_memo():
    """designkit.fem.solve memoized over the run: the FEM studies' smoke tests and
    tests/test_fem.py solve the same models (same coil, current, level, probes); a repeat
    returns the first result. Calls writing files (out_dir, export) always solve. Tests patch
    it in with :func:`shared_fem_solves`."""
    from designkit.fem import runner

    memo = {}

    def memo_solve(coil, current, **kw):
        if kw.get("out_dir") is not None or kw.get("export"):
            return runner.solve(coil, current, **kw)
        probes = kw.pop("probes", None)
        key = (coil, float(current), tuple(sorted((k, repr(v)) for k, v in kw.items())),
               None if probes is None else np.asarray(probes, float).tobytes())
        if key not in memo:
            memo[key] = runner.solve(coil, current, probes=probes, **kw)
        return memo[key]

    return memo_solve


def shared_fem_solves(monkeypatch, memo_solve) -> None:
    """designkit.fem.solve -> the run's memo for one test (undone after it)."""
    import designkit.fem as fem

    monkeypatch.setattr(fem, "solve", memo_solve)


def small_box_design():
    """The default design with a small map box: 60 x 60 mm, 20-45 mm above the coils (the
    lower half of the thesis' 50 mm cube and the closed-loop path)."""
    from designkit.design import default_design

    return default_design().replace(**{"workspace.shape": "box", "workspace.half_width_m": 0.03,
                                       "workspace.z_min_m": 0.020,
                                       "workspace.z_max_m": 0.045})


def small_steel_design():
    """:func:`small_box_design` with 1010-steel cores: they saturate, so its map stores their
    factor and the simulated plant's cores saturate (tests/test_saturation.py)."""
    return small_box_design().replace(**{"name": "thesis-steel1010-small",
                                         "core.bh": "steel1010"})


@pytest.fixture(scope="session")
def steel_small_map(tmp_path_factory):
    """(map path, CoilArray) of :func:`small_steel_design`, its map built once per run."""
    from designkit import fieldmap
    from designkit.model.array import CoilArray

    arr = CoilArray.from_design(small_steel_design())
    path = run_shared(tmp_path_factory, "steel_small_map.npz", lambda out: fieldmap.write(
        out, fieldmap.build(small_steel_design(), array=arr, n_check=10, progress=False)))
    return path, arr


@pytest.fixture(scope="session")
def small_map(tmp_path_factory, thesis_array):
    """The coupled iron-core map (v2 file) of :func:`small_box_design`, built once per run."""
    from designkit import fieldmap

    return run_shared(tmp_path_factory, "small_map.npz", lambda out: fieldmap.write(
        out, fieldmap.build(small_box_design(), array=thesis_array, n_check=10,
                            progress=False)))


def load_study(name: str):
    """Import ``studies/<name>.py`` (the studies are scripts, not a package) for a smoke test."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "studies" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def top_level_imports(path) -> set:
    """Top-level modules a source file imports (absolute imports only): the numpy-only checks
    of the firmware_io modules."""
    import ast

    mods = set()
    for node in ast.walk(ast.parse(Path(path).read_text())):
        if isinstance(node, ast.Import):
            mods |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            mods.add(node.module.split(".")[0])
    return mods


def _ci() -> bool:
    return bool(os.environ.get("DESIGNKIT_CI"))


def pytest_configure(config):
    # a worker of a parallel run: BLAS on one thread in it and in the programs it starts (the
    # workers are the parallelism; two workers each waking two BLAS threads on two cores wait
    # for one another far longer than they compute)
    if os.environ.get("PYTEST_XDIST_WORKER"):
        from threadpoolctl import threadpool_limits

        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[name] = "1"
        threadpool_limits(limits=1, user_api="blas")


def run_shared(tmp_path_factory, name: str, build) -> Path:
    """The file ``name`` that ``build(path)`` writes, made once per test run: the workers of a
    parallel run share the run's base folder, the first to ask builds the file under a lock
    and the others read it (one process alone builds it in its own folder)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path = root / name
    try:
        import fcntl
    except ImportError:            # no POSIX locks: each worker builds its own
        path = tmp_path_factory.mktemp(Path(name).stem) / Path(name).name
        build(path)
        return path
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not path.exists():
            build(path)
    return path


def pytest_sessionstart(session):
    import shutil

    # CI runs every check the README claims: a missing GetDP is an error there, not a skip
    if _ci() and shutil.which("getdp") is None:
        raise pytest.UsageError("DESIGNKIT_CI is set but the getdp program is not on PATH "
                                "(apt-get install getdp): the FEM checks cannot run")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    # in CI a skipped check is a check that did not run: fail it, naming why it skipped
    if _ci() and report.skipped and not hasattr(report, "wasxfail"):
        report.outcome = "failed"
        report.longrepr = f"skipped under DESIGNKIT_CI (every check must run): {report.longrepr}"


PINCH_DESIGN = ROOT / "tests" / "data" / "pinch_small.toml"
"""The thesis device with two magnets (thumb, index) and the small map box."""


@pytest.fixture(scope="session")
def pinch_map(tmp_path_factory, thesis_array):
    """(design, map path) of tests/data/pinch_small.toml, built once per run (the thesis
    array's coupled solve shared: the design's coils are the thesis')."""
    from designkit import fieldmap
    from designkit.design import load_design

    design = load_design(PINCH_DESIGN)
    return design, run_shared(tmp_path_factory, "pinch_map.npz", lambda out: fieldmap.write(
        out, fieldmap.build(design, array=thesis_array, n_check=10, progress=False)))
