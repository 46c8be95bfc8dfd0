"""Trajectory files against the design's workspace: a path written in millimetres, below the
workspace's floor or beside it is refused in one line (the column, its file line and value,
the valid range, the unit hint) before anything is computed or written -- it used to render
nothing and exit 0 ("force error RMS n/a", issue 39)."""

from __future__ import annotations

import pytest

from designkit import cli
from designkit.design import default_design
from designkit.errors import BadInputError
from designkit.sim import Trajectory

WORKSPACE = default_design().workspace_region()   # 150 x 150 mm, 20-80 mm above the coils


def _csv(tmp_path, rows, name="path.csv"):
    p = tmp_path / name
    p.write_text("t_s,x_m,y_m,z_m\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return p


def _error(path, workspace=WORKSPACE) -> str:
    with pytest.raises(BadInputError) as err:
        Trajectory.from_csv(path, workspace)
    return str(err.value)


def test_a_path_in_millimetres_is_refused_with_the_hint(tmp_path):
    msg = _error(_csv(tmp_path, [(0, 0, 0, 30), (1, 10, 0, 35)]))
    assert "z_m" in msg and "30 (line 2)" in msg and "[0.02, 0.08] m" in msg
    assert "Millimetres where metres are expected? Write 0.03." in msg


def test_a_path_below_the_floor_or_beside_the_workspace_is_refused(tmp_path):
    msg = _error(_csv(tmp_path, [(0, 0, 0, 0.03), (1, 0.01, 0, 0.012)]))
    assert "z_m" in msg and "0.012 (line 3)" in msg and "[0.02, 0.08] m" in msg
    assert "Millimetres" not in msg
    msg = _error(_csv(tmp_path, [(0, 0, 0, 0.03), (1, 0, -0.5, 0.03)]))
    assert "y_m" in msg and "-0.5 (line 3)" in msg and "[-0.075, 0.075] m" in msg
    # inside the bounding box of a disc workspace, outside the disc: the outline is named
    disc = default_design().replace(**{"workspace.shape": "disc",
                                       "workspace.radius_m": 0.04}).workspace_region()
    msg = _error(_csv(tmp_path, [(0, 0, 0, 0.03), (1, 0.035, 0.035, 0.03)]), disc)
    assert "outline" in msg and "(line 3)" in msg


def test_a_path_inside_the_workspace_is_read(tmp_path):
    # the floor and the top themselves are inside
    t = Trajectory.from_csv(_csv(tmp_path, [(0, -0.075, 0.075, 0.02), (1, 0.0, 0.0, 0.08)]),
                            WORKSPACE)
    assert t.position_m.shape == (2, 3)


def test_run_simulate_refuses_it_in_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    rc = cli.main(["run", "--simulate", "--trajectory", str(_csv(tmp_path, [(0, 0, 0, 30),
                                                                             (1, 0, 0, 40)])),
                   "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "z_m" in err and "Write 0.03" in err
    assert not out.exists()
