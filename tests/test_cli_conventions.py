"""Conventions every ``designkit`` command shares, checked command by command: ``--out`` makes
no folder above the one it names, a length on the command line takes the same units
everywhere (a number with its unit, or the option's millimetres), and the studies parse their
command line (``--help`` prints help, it is not an output folder)."""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from designkit.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _must_not_run(*a, **k):
    raise AssertionError("the computation ran before --out was checked")


OUT_CASES = {
    "report": (["report", "--quick"], "designkit.commands.report._run", "rep"),
    "optimize": (["optimize"], "designkit.commands.optimize.solve_device", "opt"),
    "sweep": (["sweep", "--param", "inner_radius_m=0.006:0.01:3"],
              "designkit.commands.sweep.run_sweep", "sw"),
    "map": (["map"], "designkit.fieldmap.build", "x.npz"),
    "scene": (["scene", "compile", "plane"], "designkit.render.make_object", "x.npz"),
    "viz": (["viz", "scene"], "designkit.viz.render", "x.png"),
    "run": (["run", "--simulate"], "designkit.commands.run.run_simulation", "run"),
    "cad": (["cad"], "cad.export.export_all", "cad"),
    "fem": (["fem"], "designkit.commands.fem.solve", "fem"),
    "calibrate": (["calibrate", "--plan"], "designkit.commands.calibrate.make_plan", "p.csv"),
    "sensors": (["sensors", "plan"], "designkit.commands.sensors.plan_design", "sp"),
}


@pytest.mark.parametrize("command", sorted(OUT_CASES))
def test_out_never_makes_the_folders_above_the_one_it_names(tmp_path, monkeypatch, capsys,
                                                            command):
    args, target, leaf = OUT_CASES[command]
    mod, _, name = target.rpartition(".")
    monkeypatch.setattr(importlib.import_module(mod), name, _must_not_run)
    out = tmp_path / "nonexistent" / "dir" / leaf
    assert main([*args, "--out", str(out)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "--out" in err[0] and "does not exist" in err[0], err
    assert str(tmp_path / "nonexistent") in err[0]  # the first missing folder is named
    assert list(tmp_path.iterdir()) == []


def test_a_folder_out_is_made_in_an_existing_folder(tmp_path, capsys):
    # the folder --out names is made (one level), as before
    assert main(["sweep", "--param", "inner_radius_m=0.006:0.01:2", "--design", "optimized",
                 "--workers", "1", "--no-progress", "--out", str(tmp_path / "sw")]) == 0
    assert sorted(p.name for p in (tmp_path / "sw").iterdir()) == ["sweep.csv", "sweep.png"]


# ----------------------------------------------------------------------------- lengths
class _Seen(Exception):
    """Raised by a stand-in once it has the value the option was converted to."""


def _catch(monkeypatch, target: str, pick):
    mod, _, name = target.rpartition(".")
    seen = {}

    def stand_in(*a, **k):
        seen["value"] = pick(a, k)
        raise _Seen

    monkeypatch.setattr(importlib.import_module(mod), name, stand_in)
    return seen


LENGTH_CASES = [
    # command line, the computation given the length, how to read it there, metres
    (["map", "--spacing", "1cm"], "designkit.fieldmap.build", lambda a, k: k["spacing"], 0.01),
    (["map", "--spacing", "8"], "designkit.fieldmap.build", lambda a, k: k["spacing"], 0.008),
    (["optimize", "--vary-pitch", "--pitch-range", "40:6cm"],
     "designkit.commands.optimize.device_problem_for",
     lambda a, k: k["vary"]["pitch_m"], (0.04, 0.06)),
    (["cad", "--min-wall", "0.8"], "cad.cli.from_design",
     lambda a, k: k["min_wall_mm"] * 1e-3, 0.8e-3),
    (["cad", "--min-wall", "1.2mm", "--build-volume", "20cm,19cm,0.2m"], "cad.cli.from_design",
     lambda a, k: (k["min_wall_mm"] * 1e-3, *[q * 1e-3 for q in k["printer"].build_volume_mm]),
     (1.2e-3, 0.2, 0.19, 0.2)),
    (["scene", "compile", "part.stl", "--mesh-at", "0,-1cm,5", "--mesh-spacing", "0.5"],
     "designkit.render.make_object",
     lambda a, k: (*k["position_m"], k["spacing_m"]), (0.0, -0.01, 0.005, 5e-4)),
]


@pytest.mark.parametrize("args,target,pick,metres", LENGTH_CASES,
                         ids=[" ".join(c[0][:3]) for c in LENGTH_CASES])
def test_every_length_option_takes_a_unit_and_a_number_is_mm(tmp_path, monkeypatch, args,
                                                             target, pick, metres):
    seen = _catch(monkeypatch, target, pick)
    with pytest.raises(_Seen):
        main([*args, "--out", str(tmp_path / ("o.npz" if args[0] in ("map", "scene")
                                              else "o"))])
    assert seen["value"] == pytest.approx(metres)


@pytest.mark.parametrize("args,param", [
    (["map", "--spacing", "0.01"], "--spacing"),
    (["optimize", "--vary-pitch", "--pitch-range", "0.04:0.06"], "--pitch-range"),
    (["cad", "--min-wall", "0.0008"], "--min-wall"),
    (["scene", "compile", "part.stl", "--mesh-spacing", "0.002"], "--mesh-spacing"),
])
def test_metres_given_to_a_mm_option_are_refused_with_the_hint(tmp_path, monkeypatch, capsys,
                                                               args, param):
    for target in ("designkit.fieldmap.build", "designkit.commands.optimize.solve_device",
                   "cad.export.export_all", "designkit.render.make_object"):
        mod, _, name = target.rpartition(".")
        monkeypatch.setattr(importlib.import_module(mod), name, _must_not_run)
    out = tmp_path / ("o.npz" if args[0] in ("map", "scene") else "o")
    assert main([*args, "--out", str(out)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and param in err[0] and "Metres where mm are expected" in err[0], err
    assert "mm" in err[0] and "Write " in err[0]


def test_optimize_names_a_rule_it_cannot_fix_before_it_solves(tmp_path, monkeypatch, capsys):
    _catch(monkeypatch, "designkit.commands.optimize.solve_device", lambda a, k: None)
    d = tmp_path / "d.toml"
    # the magnet cannot reach 15 mm above the coils: no coil the optimizer picks changes it
    d.write_text("[optimize]\nheight_m = 0.015\n")
    with pytest.raises(_Seen):
        main(["optimize", "--design", str(d), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert "designkit optimize: note: every design breaks rule magnet_at_design_height" in err
    assert "optimize.height_m, sensors.offset_m are not varied" in err
    # the default design: the optimizer sets the supply to the driver's rating itself
    with pytest.raises(_Seen):
        main(["optimize", "--out", str(tmp_path / "o")])
    assert "note:" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- studies
def _reads_argv_by_hand(path: Path) -> bool:
    """The script's own code reads ``sys.argv`` (code run in a child process, written in a
    string, does not count)."""
    import ast

    tree = ast.parse(path.read_text())
    return any(isinstance(n, ast.Attribute) and n.attr == "argv"
               and getattr(n.value, "id", None) == "sys" for n in ast.walk(tree))


def _studies():
    out = []
    for p in sorted((ROOT / "studies").glob("*.py")):
        if p.name.startswith("_") or 'if __name__ == "__main__"' not in p.read_text():
            continue
        out.append(pytest.param(p, id=p.stem))
    return out


@pytest.mark.parametrize("study", _studies())
def test_every_study_parses_its_command_line_with_argparse(study):
    text = study.read_text()
    assert "argparse" in text or "study_parser" in text
    assert not _reads_argv_by_hand(study)


def test_a_study_s_help_is_help_not_an_output_folder(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = subprocess.run([sys.executable, str(ROOT / "studies" / "bench_blas.py"), "--help"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stdout.startswith("usage: bench_blas.py"), res.stderr
    assert "--quick" in res.stdout and "OUT" in res.stdout
    assert list(tmp_path.iterdir()) == []
    bad = subprocess.run([sys.executable, str(ROOT / "studies" / "bench_blas.py"), "--bogus"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "unrecognized arguments: --bogus" in bad.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="not a git checkout")
def test_no_output_folder_is_committed_at_the_root():
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True)
    assert not [t for t in tracked.stdout.split() if t.startswith("-")]
