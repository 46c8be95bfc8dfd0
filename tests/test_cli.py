"""The ``designkit`` command as a user meets it: run in a temporary folder (through the
function the console script calls; the entry point itself as a separate process), bad input
gives one clear line and a non-zero exit, never a traceback, and a failing run leaves nothing
behind."""

from __future__ import annotations

import contextlib
import functools
import importlib
import io
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from designkit import __version__ as designkit_version
from designkit.support.progress import LineWriter, tqdm
from designkit.cli import COMMANDS, main
from designkit.commands.common import join_negative_values
from designkit.errors import BadInputError

ROOT = Path(__file__).resolve().parents[1]


def designkit(*args: str, cwd: Path, timeout: float = 300,
              process: bool = False) -> subprocess.CompletedProcess:
    """Run ``designkit ARGS`` in ``cwd``: in this process by default (``designkit.cli.main``,
    the function the console script calls, with its stdout, stderr and warnings captured as a
    process would print them), or with ``process=True`` as a separate process (the installed
    console script when it belongs to this checkout, else the module): the tests of the
    process itself (the entry point, a traceback Python would print) keep that."""
    if process:
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYVISTA_OFF_SCREEN="true",
                   MPLBACKEND="Agg")
        exe = shutil.which("designkit")
        cmd = [exe] if exe and Path(exe).parent == Path(sys.executable).parent else \
            [sys.executable, "-m", "designkit.cli"]
        return subprocess.run(cmd + list(args), cwd=cwd, env=env, capture_output=True,
                              text=True, timeout=timeout)
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with warnings.catch_warnings(record=True) as caught, \
                contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            # what a fresh interpreter shows: each warning once, not the deprecation kinds
            warnings.simplefilter("default")
            for kind in (DeprecationWarning, PendingDeprecationWarning, ImportWarning,
                         ResourceWarning):
                warnings.filterwarnings("ignore", category=kind)
            code = main(list(args))
    finally:
        os.chdir(here)
    shown = "".join(f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n"
                    for w in caught)
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue() + shown)


def _one_clear_line(res, *words):
    assert res.returncode != 0
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


# ----------------------------------------------------------------------------- --out checks
OUT_FOLDER_COMMANDS = {
    "report": ["report", "--quick"],
    "optimize": ["optimize"],
    "sweep": ["sweep", "--param", "inner_radius_m=0.006:0.01:3"],
    "cad": ["cad"],
    "fem": ["fem"],
    "run": ["run", "--simulate"],
    "sensors": ["sensors", "plan"],
}
OUT_FILE_COMMANDS = {
    "map": ["map"],
    "scene": ["scene", "compile", "plane", "--lambda", "5"],
    "viz": ["viz", "scene"],
}


@pytest.mark.parametrize("command", sorted(OUT_FOLDER_COMMANDS))
def test_out_naming_an_existing_file_is_one_line(tmp_path, command):
    (tmp_path / "taken").write_text("precious")
    res = designkit(*OUT_FOLDER_COMMANDS[command], "--out", "taken", cwd=tmp_path)
    _one_clear_line(res, "--out", "existing file", "taken")
    assert (tmp_path / "taken").read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


@pytest.mark.parametrize("command", sorted(OUT_FILE_COMMANDS))
def test_out_naming_an_existing_folder_is_one_line(tmp_path, command):
    (tmp_path / "taken.npz").mkdir()
    (tmp_path / "taken.npz" / "keep").write_text("precious")
    res = designkit(*OUT_FILE_COMMANDS[command], "--out", "taken.npz", cwd=tmp_path)
    _one_clear_line(res, "--out", "existing folder", "taken.npz")
    assert [p.name for p in (tmp_path / "taken.npz").iterdir()] == ["keep"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken.npz"]


def test_out_under_a_file_is_one_line(tmp_path):
    (tmp_path / "f").write_text("")
    res = designkit("optimize", "--out", "f/sub", cwd=tmp_path, process=True)
    _one_clear_line(res, "--out", "is a file")


def _must_not_run(*a, **k):
    raise AssertionError("the computation ran before --out was checked")


@pytest.mark.parametrize("command,target", [
    ("optimize", "designkit.commands.optimize.solve"),
    ("sweep", "designkit.commands.sweep.run_sweep"),
    ("report", "designkit.commands.report._run"),
    ("cad", "cad.export.export_all"),
    ("run", "designkit.commands.run.run_simulation"),
    ("map", "designkit.fieldmap.build"),
    ("scene", "designkit.render.make_object"),
])
def test_out_is_checked_before_computing(tmp_path, monkeypatch, capsys, command, target):
    mod, _, name = target.rpartition(".")
    monkeypatch.setattr(importlib.import_module(mod), name, _must_not_run)
    if command in OUT_FOLDER_COMMANDS:
        args, taken, says = OUT_FOLDER_COMMANDS[command], tmp_path / "taken", "existing file"
        taken.write_text("")
    else:
        args, taken, says = OUT_FILE_COMMANDS[command], tmp_path / "taken.npz", "existing folder"
        taken.mkdir()
    assert main([*args, "--out", str(taken)]) == 1
    assert says in capsys.readouterr().err


# ----------------------------------------------------------------------------- report: nothing half written
def test_report_with_wrong_currents_leaves_nothing(tmp_path):
    res = designkit("report", "--quick", "--currents", "6,0", "--out", "rep", cwd=tmp_path)
    _one_clear_line(res, "currents", "9 numbers")
    assert list(tmp_path.iterdir()) == []


def test_report_failing_late_leaves_nothing(tmp_path, monkeypatch, capsys):
    import designkit.commands.report as report

    def fail(*a, **k):
        raise BadInputError("map", "something", "a late failure")

    monkeypatch.setattr(report, "_field_map", fail)
    monkeypatch.setattr(report, "designs_side_by_side", lambda d: (_ for _ in ()).throw(
        ImportError("skip the optimizer in this test")))
    monkeypatch.setattr(report, "_figures_and_vtk", lambda *a, **k: (_ for _ in ()).throw(
        ImportError("skip the figures in this test")))
    assert main(["report", "--quick", "--no-progress", "--out", str(tmp_path / "rep")]) == 1
    assert "a late failure" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # neither rep/ nor a staging folder


def test_report_failing_keeps_a_previous_report_untouched(tmp_path, monkeypatch, capsys):
    import designkit.commands.report as report

    old = tmp_path / "rep"
    old.mkdir()
    (old / "design.json").write_text("old")
    monkeypatch.setattr(report, "_field_map", lambda *a: (_ for _ in ()).throw(
        BadInputError("map", "x", "late")))
    monkeypatch.setattr(report, "designs_side_by_side", lambda d: (_ for _ in ()).throw(
        ImportError("skip")))
    monkeypatch.setattr(report, "_figures_and_vtk", lambda *a, **k: (_ for _ in ()).throw(
        ImportError("skip")))
    assert main(["report", "--quick", "--no-progress", "--out", str(old)]) == 1
    assert [p.name for p in old.iterdir()] == ["design.json"]
    assert (old / "design.json").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]


# ----------------------------------------------------------------------------- currents
def test_join_negative_values():
    assert join_negative_values(["--currents", "-6,0", "--x", "-1"]) == ["--currents=-6,0",
                                                                        "--x", "-1"]
    assert join_negative_values(["--current", "-.5"]) == ["--current=-.5"]
    assert join_negative_values(["--currents", "--out"]) == ["--currents", "--out"]


def test_negative_currents_are_accepted(tmp_path):
    res = designkit("viz", "scene", "--currents", "-6,0,0,0,6,0,0,0,-3", "--size", "320x240",
                    "--out", "s.png", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "s.png").stat().st_size > 1000


@pytest.mark.parametrize("args", [
    ["viz", "scene", "--currents", "60,0,0,0,0,0,0,0,0"],
    ["report", "--quick", "--currents", "-6.5,0,0,0,0,0,0,0,0"],  # a leading minus too
    ["report", "--quick", "--current", "60"],
])
def test_currents_over_the_limit_are_an_error(tmp_path, args):
    res = designkit(*args, "--out", "o.png" if args[0] == "viz" else "rep", cwd=tmp_path)
    line = _one_clear_line(res, "6 A per coil", "--allow-over-limit")
    assert "drive.max_current_a" in line
    assert list(tmp_path.iterdir()) == []


def test_total_current_budget(tmp_path):
    toml = tmp_path / "d.toml"
    toml.write_text("[drive]\ntotal_current_a = 10.0\n")
    res = designkit("viz", "scene", "--design", str(toml), "--currents", "6,6,0,0,0,0,0,0,0",
                    "--out", "o.png", cwd=tmp_path)
    _one_clear_line(res, "10 A", "drive.total_current_a")


def test_over_limit_allowed_explicitly(tmp_path):
    res = designkit("viz", "scene", "--currents", "60,0,0,0,0,0,0,0,0", "--allow-over-limit",
                    "--size", "320x240", "--out", "o.png", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "o.png").is_file()


# ----------------------------------------------------------------------------- progress
NO_PROGRESS_BAR = {"viz", "fem"}
"""Commands without a progress bar (the README says which); every other one takes the flag."""


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_one_progress_flag_everywhere(command, capsys):
    args = [command, "compile"] if command == "scene" else [command]
    assert main([*args, "--help"]) == 0
    text = capsys.readouterr().out
    has = "--no-progress" in text and "--quiet" in text
    assert has != (command in NO_PROGRESS_BAR), command


def test_progress_is_line_wise_without_a_terminal():
    sink = io.StringIO()
    for _ in tqdm(range(50), file=sink, desc="job", mininterval=0, miniters=1):
        pass
    text = sink.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) >= 2 and all(ln.startswith("job") for ln in lines)
    assert "50/50" in lines[-1]
    assert isinstance(LineWriter(sink).encoding, str)


def test_sweep_progress_in_a_pipe_has_no_carriage_returns(tmp_path):
    res = designkit("sweep", "--param", "inner_radius_m=0.006:0.01:5", "--workers", "1",
                    "--out", "sw", cwd=tmp_path, process=True)
    assert res.returncode == 0, res.stderr
    assert "\r" not in res.stderr and "sweep" in res.stderr


# ----------------------------------------------------------------------------- map files
def test_a_text_file_renamed_npz_is_not_a_map_file(tmp_path):
    (tmp_path / "map.npz").write_text("hello, I am a text file\n")
    res = designkit("scene", "compile", "plane", "--map", "map.npz", "--out", "s.npz",
                    cwd=tmp_path)
    line = _one_clear_line(res, "not a map file", "map.npz")
    assert "pickle" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.npz"]


# ----------------------------------------------------------------------------- design files
@pytest.mark.parametrize("text,param", [
    ("name = 5\n", "name"),
    ('[coil]\nturns = "1429"\n', "coil.turns"),
    ('[coil]\ninner_radius_m = "0.012"\n', "coil.inner_radius_m"),
    ("[core]\nbh = 1\n", "core.bh"),
    ("[coil]\nturns = 14.5\n", "coil.turns"),
    ("[drive]\nmax_current_a = true\n", "drive.max_current_a"),
])
def test_design_file_type_errors(tmp_path, text, param):
    (tmp_path / "d.toml").write_text(text)
    res = designkit("optimize", "--design", "d.toml", "--out", "o", cwd=tmp_path)
    _one_clear_line(res, param)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.toml"]


def test_staged_folder_moves_everything_into_place(tmp_path, monkeypatch):
    from designkit.commands.common import staged_folder

    (tmp_path / "a").mkdir()  # --out's folder must exist (the command makes out/ only)
    with staged_folder(tmp_path / "a" / "out") as stage:
        (stage / "sub").mkdir()
        (stage / "sub" / "x.txt").write_text("x")
        assert not (tmp_path / "a" / "out").exists()  # nothing visible before success
    assert (tmp_path / "a" / "out" / "sub" / "x.txt").read_text() == "x"
    # into an existing folder: new files replace, others stay; also with --out .
    monkeypatch.chdir(tmp_path / "a" / "out")
    (tmp_path / "a" / "out" / "keep.txt").write_text("k")
    with staged_folder(".") as stage:
        (stage / "sub").mkdir()
        (stage / "sub" / "x.txt").write_text("y")
    out = tmp_path / "a" / "out"
    assert (out / "sub" / "x.txt").read_text() == "y" and (out / "keep.txt").read_text() == "k"
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt", "sub"]


# ----------------------------------------------------------------------------- fem --out
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("getdp") is None, reason="needs getdp")
def test_fem_writes_its_default_relative_out(tmp_path):
    res = designkit("fem", "--level", "0", cwd=tmp_path, timeout=900, process=True)
    assert res.returncode == 0, res.stderr[-2000:]
    out = tmp_path / "fem_out"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fem_out"]  # no staging folder left
    assert out.stat().st_mode & 0o777 == 0o777 & ~_umask()
    import json

    data = json.loads((out / "fem_results.json").read_text())
    assert all((out / name).is_file() for name in data["files"].values())
    # the written comparison is the FEM's own: designkit's core model within 1 % of GetDP
    err = data["comparison"]["axis"]["surface-current_bz_rel_err"]
    assert max(abs(e) for e in err) < 0.01


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ----------------------------------------------------------------------------- map --out
def _unwritable(tmp_path: Path) -> Path:
    """A folder this process cannot create files in (for root: /proc)."""
    if os.geteuid() == 0:
        return Path("/proc")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    return ro


@pytest.mark.parametrize("command", ["map", "scene", "viz"])
def test_an_unwritable_out_is_refused_before_any_work(tmp_path, monkeypatch, capsys, command):
    monkeypatch.setattr(importlib.import_module("designkit.fieldmap"), "build", _must_not_run)
    monkeypatch.setattr(importlib.import_module("designkit.render"), "make_object",
                        _must_not_run)
    monkeypatch.setattr(importlib.import_module("designkit.viz"), "render", _must_not_run)
    target = _unwritable(tmp_path) / ("x.png" if command == "viz" else "x.npz")
    args = {"map": ["map"], "scene": ["scene", "compile", "plane"], "viz": ["viz", "scene"]}
    assert main([*args[command], "--out", str(target)]) == 1
    err = capsys.readouterr().err
    assert "--out" in err and "writable" in err and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------------------- scene compile
@pytest.mark.slow
def test_scene_compile_unipolar_leaves_out_the_points_it_cannot_render(tmp_path):
    """Under a unipolar drive the cores' pull (F0) cannot be cancelled at the wedge's lowest
    points; lambda is the smallest over the points that can be rendered (> 0 N/m), the left-out
    points are counted on stdout and in the file."""
    import json

    import numpy as np

    res = designkit("scene", "compile", "wedge", "--unipolar", "--n-side", "11", "--quiet",
                    "--out", "w.npz", cwd=tmp_path, timeout=900)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    with np.load(tmp_path / "w.npz") as z:
        meta = json.loads(str(z["meta"]))
    left_out = meta["lambda_unrenderable_points"]
    assert 0 < left_out < meta["lambda_points"]
    assert meta["lambda_n_per_m"] > 0.0
    assert f"{left_out} points where the cores' pull cannot be cancelled left out" in res.stdout


def test_scene_compile_refuses_an_object_nothing_can_render(tmp_path, monkeypatch):
    """lambda = 0 at every point (no point renderable): one line naming the object, the
    limiting point and the ways out; nothing written."""
    from types import SimpleNamespace

    import numpy as np

    def force_constant(*args, **kwargs):
        return SimpleNamespace(lam_where_renderable=lambda: 0.0,
                               limiting_point_where_renderable=lambda: np.array([0, 0, 0.03]),
                               limiting_point_m=np.array([0, 0, 0.03]),
                               unrenderable_points=4, points_m=np.zeros((4, 3)))

    monkeypatch.setattr(importlib.import_module("designkit.render"), "force_constant",
                        force_constant)
    res = designkit("scene", "compile", "wedge", "--unipolar", "--n-side", "5", "--quiet",
                    "--out", "w.npz", cwd=tmp_path)
    line = _one_clear_line(res, "wedge", "lambda = 0 N/m", "[0.0, 0.0, 30.0] mm", "--unipolar",
                           "--lambda")
    assert "lam_n_per_m" not in line
    assert list(tmp_path.iterdir()) == []


def test_scene_compile_says_where_a_mesh_outside_the_box_is(tmp_path):
    import pyvista as pv

    pv.Sphere(radius=30.0, theta_resolution=16, phi_resolution=16).save(str(tmp_path / "b.stl"))
    res = designkit("scene", "compile", "b.stl", "--mesh-at", "0,0,500", "--n-side", "7",
                    "--out", "b.npz", cwd=tmp_path)
    line = _one_clear_line(res, "box (x -75..75", "--mesh-at", "--mesh-scale")
    assert "MeshSurface" not in line
    # the sphere's top is at 500 mm + its 60 mm diameter
    assert "z 5" in line and "560 mm" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.stl"]


@pytest.mark.parametrize("args,param,internal", [
    (["viz", "scene", "--size", "8x8", "--out", "x.png"], "--size", "window_size"),
    (["run", "--simulate", "--lambda", "-1", "--out", "r"], "--lambda", "lam_n_per_m"),
    (["run", "--simulate", "--period-ms", "100", "--out", "r"], "--period-ms", "period "),
    (["run", "--simulate", "--duration", "1000", "--out", "r"], "--duration", "duration "),
    (["scene", "compile", "plane", "--lambda", "inf", "--out", "s.npz"], "--lambda",
     "lam_n_per_m"),
    (["scene", "compile", "plane", "--current-limit", "-1", "--out", "s.npz"],
     "--current-limit", "current_limit_a"),
])
def test_messages_name_the_option_not_the_internal_name(tmp_path, args, param, internal):
    res = designkit(*args, cwd=tmp_path)
    line = _one_clear_line(res, param)
    assert internal not in line.replace(param, "")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- help texts
@pytest.mark.parametrize("command,option,says", [
    ("fem", "--level", "default 1"), ("fem", "--out", "default ./fem_out"),
    ("run", "--out", "default ./run-out"), ("run", "--seed", "default 0"),
    ("run", "--period-ms", "default 1"), ("run", "--duration", "cuts it"),
    ("map", "--out", "default ./fieldmap.npz"), ("scene", "--out", "default ./scene.npz"),
    ("fem", "--design", "optimized"), ("map", "--design", "optimized"),
    ("run", "--design", "optimized"), ("scene", "--design", "optimized"),
    ("viz", "--design", "optimized"), ("viz", "--size", "default 1024x768"),
])
def test_help_states_defaults_and_the_shipped_designs(capsys, command, option, says):
    args = [command, "compile"] if command == "scene" else [command]
    assert main([*args, "--help"]) == 0
    text = capsys.readouterr().out
    start = text.index("\n  " + option)  # its row in the options list, not the usage line
    nxt = text.find("\n  -", start + 1)
    row = " ".join(text[start:nxt if nxt > 0 else None].split())
    assert says in row, row


@pytest.mark.parametrize("command", ["report", "optimize", "sweep", "cad", "check"])
def test_design_help_lists_the_shipped_designs_and_the_default(command, tmp_path):
    # the same --design help as check/map/...: every shipped name and what the default is
    from designkit.design import NAMED_DESIGNS
    res = designkit(command, "--help", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    text = " ".join(res.stdout.split())
    for name in NAMED_DESIGNS:
        if name != "thesis-default":
            assert name in text
    assert "(default: thesis, the embedded thesis device)" in text


def test_python_dash_m_designkit_is_the_same_command_line(tmp_path):
    """``python -m designkit`` (documented beside the script): the version, and bad input as
    one clear line with the script's exit code, nothing written."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = functools.partial(subprocess.run, cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=120)
    res = run([sys.executable, "-m", "designkit", "--version"])
    assert res.returncode == 0 and res.stdout.strip() == designkit_version
    res = run([sys.executable, "-m", "designkit", "map", "--scene-margin", "-5", "--out",
               "m.npz"])
    assert res.returncode == 1  # a value the library refuses (argparse's own errors: 2)
    _one_clear_line(res, "--scene-margin", "-5")
    assert not list(tmp_path.iterdir())
