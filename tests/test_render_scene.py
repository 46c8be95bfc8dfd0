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


@pytest.mark.parametrize("damage,match", [
    ("tampered", "corrupted"),  # one array changed: the content hash no longer matches
    ("foreign", "array meta"),  # an .npz of something else
    ("truncated", "readable npz"),
    ("text", "not a scene file"),  # not even a zip: never numpy's allow_pickle message
])
def test_corrupted_or_foreign_file_is_refused(tmp_path, damage, match):
    good = tmp_path / "s.npz"
    assert main(["scene", "compile", "hemisphere", "--lambda", "5", "--out", str(good)]) == 0
    bad = tmp_path / "bad.npz"
    if damage == "tampered":
        np.savez(bad, **dict(np.load(good), obj0_x=np.zeros(3)))
    elif damage == "foreign":
        np.savez(bad, x=np.zeros(3))
    elif damage == "truncated":
        bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    else:
        bad.write_text("hello, I am a text file\n")
    with pytest.raises(FwBadInput, match=match) as exc:
        Scene.load(bad)
    assert "pickle" not in str(exc.value)


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


def test_compile_shows_no_empty_progress_bar(tmp_path, capsys):
    """A bar is shown only for work there is: the hemisphere's lambda leaves no point to the
    allocator, so no bar of zero items ("0it", printed twice before) is shown."""
    out = tmp_path / "s.npz"
    assert main(["scene", "compile", "hemisphere", "--n-side", "5", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert not [ln for ln in err.splitlines() if " 0it" in ln or "| 0/0" in ln], err
