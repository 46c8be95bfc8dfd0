"""Compiled scenes: CLI, atomic write, numpy-only loader, refusal of another map's scene."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from designkit.cli import main
from designkit.design import default_design
from firmware_io.errors import BadInputError as FwBadInput
from firmware_io.scene import Scene

ROOT = Path(__file__).resolve().parents[1]


def test_compile_plane_and_load_numpy_only(tmp_path):
    out = tmp_path / "plane.npz"
    assert main(["scene", "compile", "plane", "--lambda", "6", "--out", str(out)]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["plane.npz"]  # no temp file left
    sha = default_design().spec_hash()
    sc = Scene.load(out, expected_design_sha256=sha)
    # thesis 4.2.1: 6 N/m x 50 mm = 0.3 N up on the flat surface, nothing above it
    f = sc.force([[0.01, 0.02, 0.0499], [0.0, 0.0, 0.06]])
    np.testing.assert_allclose(f, [[0, 0, 0.3], [0, 0, 0]], atol=1e-12)
    # the runner's view: numpy only (designkit and scipy made unimportable)
    code = ("import sys; sys.modules['designkit'] = None; sys.modules['scipy'] = None\n"
            "from firmware_io.scene import Scene\n"
            f"s = Scene.load({str(out)!r}, expected_design_sha256={sha!r})\n"
            "print(s.force([[0.0, 0.0, 0.049]])[0, 2])\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert res.returncode == 0, res.stderr
    assert float(res.stdout) == pytest.approx(0.3)


def test_scene_for_another_map_is_refused(tmp_path):
    out = tmp_path / "s.npz"
    assert main(["scene", "compile", "wedge", "--lambda", "5", "--out", str(out)]) == 0
    other = default_design().replace(**{"coil.turns": 1000}).spec_hash()
    with pytest.raises(FwBadInput, match="Recompile") as exc:
        Scene.load(out, expected_design_sha256=other)
    assert other[:12] in str(exc.value)


def test_corrupted_or_foreign_file_is_refused(tmp_path):
    out = tmp_path / "s.npz"
    main(["scene", "compile", "hemisphere", "--lambda", "5", "--out", str(out)])
    data = dict(np.load(out))
    data["obj0_x"] = np.zeros(3)  # tamper: hash no longer matches
    bad = tmp_path / "bad.npz"
    np.savez(bad, **data)
    with pytest.raises(FwBadInput, match="corrupted"):
        Scene.load(bad)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"nope")
    with pytest.raises(FwBadInput, match="scene"):
        Scene.load(junk)


def test_compile_mesh_and_computed_lambda(tmp_path, capsys):
    import pyvista as pv

    stl = tmp_path / "ball.stl"
    pv.Sphere(radius=30.0, theta_resolution=40, phi_resolution=40).save(str(stl))
    out = tmp_path / "ball.npz"
    assert main(["scene", "compile", str(stl), "--n-side", "5", "--quiet", "--unipolar",
                 "--out", str(out), "--law", "penetration", "--stiffness", "1000"]) == 0
    text = capsys.readouterr().out
    assert "computed" in text and "limited by position noise" in text
    sc = Scene.load(out)
    assert sc.meta["law"]["stiffness_n_per_m"] == pytest.approx(0.8e-3 / 0.3e-3)
    assert sc.lam_n_per_m > 0
    # the loaded grid object answers like the built one
    from designkit.render import MeshSurface

    m = MeshSurface.from_file(stl, spacing_m=0.002)
    p = np.random.default_rng(0).uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.07], (200, 3))
    np.testing.assert_allclose(sc.objects[0].signed_distance(p), m.signed_distance(p),
                               atol=1e-7)


def test_cli_bad_input_no_traceback(tmp_path, capsys):
    assert main(["scene", "compile", "cube", "--out", str(tmp_path / "x.npz")]) == 1
    err = capsys.readouterr().err
    assert "OBJECT" in err and "Traceback" not in err
    assert main(["scene", "compile", "plane", "--lambda", "-1",
                 "--out", str(tmp_path / "x.npz")]) == 1
    assert not (tmp_path / "x.npz").exists()


def test_firmware_scene_numpy_only():
    from conftest import top_level_imports

    mods = top_level_imports(ROOT / "firmware_io" / "scene.py")
    assert mods <= {"numpy", "hashlib", "json", "zipfile", "pathlib", "__future__"}, mods
