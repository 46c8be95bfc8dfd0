"""The device optimizer on any layout: layout variables (a ring's radius and tilt), the
no-overlap constraint of coils in their poses, the rendering objective of tilted coils.

Independent references: designkit.CoilArray (poses, frames, F = G^T m) for the force of tilted
air coils; the rule book's cylinders built by hand for the overlap; the default ranges worked
out from the design's numbers.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from designkit import optimize as opt
from designkit.cli import main
from designkit.commands.optimize import layout_variables
from designkit.design import default_design, load_design
from designkit.errors import BadInputError
from designkit.model.array import CoilArray, force_matrix
from designkit.rules.convex import Cylinder, signed_distance

LAYOUTS = Path(__file__).parent / "data" / "layouts"


@pytest.fixture(scope="module")
def ring():
    return load_design(LAYOUTS / "ring6_tilt30.toml")


def test_a_rings_radius_and_tilt_are_search_variables_with_stated_ranges(ring):
    p = opt.device_problem_for(ring, objective="rendering",
                               vary={"radius_m": None, "tilt_deg": None})
    assert p.space.names[7:] == ("radius_m", "tilt_deg")
    # radius: from 0.6 x 75 mm (neighbours 2 r sin(pi/6) = r apart) to the design's 75 mm;
    # tilt: upright to the printable 45 degrees
    assert p.space.bounds("radius_m") == pytest.approx((0.045, 0.075))
    assert p.space.bounds("tilt_deg") == (0.0, 45.0)
    # Ro's bound: 2 Ro + 4.4 mm (wall + lips + clearances) within the widest spacing
    assert p.upper[1] == pytest.approx(min((0.075 - 4.4e-3) / 2, 0.025))
    lay = p.layout_of(list(p.lower[:7]) + [0.06, 12.0])
    assert (lay.radius_m, lay.tilt_deg, lay.count) == (0.06, 12.0, 6)
    assert "coil_overlap_m" in p.constraint_names


def test_layout_variables_are_refused_where_they_do_not_belong(ring):
    with pytest.raises(BadInputError, match="layout 'ring'.*pitch_m"):
        opt.device_problem_for(ring, objective="rendering", vary={"pitch_m": None})
    with pytest.raises(BadInputError, match="rendering"):
        opt.device_problem_for(ring, vary={"tilt_deg": None})
    with pytest.raises(BadInputError, match="tilt_deg range"):
        opt.device_problem_for(ring, objective="rendering", vary={"tilt_deg": (0.0, 95.0)})
    assert layout_variables(["radius_m,tilt_deg=0:40"]) == {"radius_m": None,
                                                            "tilt_deg": (0.0, 40.0)}
    assert layout_variables([], True, "40:6cm") == {"pitch_m": (0.04, 0.06)}  # an option: mm
    assert layout_variables(["pitch_m=0.04:60mm"]) == {"pitch_m": (0.04, 0.06)}  # a key: m
    for bad in (["tilt_deg=0-40"], ["tilt_deg", "tilt_deg"], ["radius_m,"]):
        with pytest.raises(BadInputError, match="--vary"):
            layout_variables(bad)


def test_the_overlap_constraint_is_the_pockets_distance_in_their_poses(ring):
    p = opt.device_problem_for(ring, objective="rendering",
                               vary={"radius_m": None, "tilt_deg": None})
    x = opt.DeviceProblem.physical(np.array(p.lower) + 0.5 * (np.array(p.upper)
                                                             - np.array(p.lower)))
    x[7], x[8] = 0.05, 20.0
    ro, ln = x[1], x[2]
    lay = p.layout_of(x)
    tops, axes = lay.top_centres_m(), lay.axes()
    rp = ro + 1.5e-3 + 0.3e-3
    cyl = [Cylinder(tuple(t - a * ln / 2), tuple(a), ln / 2 + 2e-3, rp)
           for t, a in zip(tops[:2], axes[:2])]
    assert p.overlap_m(x) == pytest.approx(0.8e-3 - signed_distance(*cyl), abs=1e-12)
    # a grid: 2 Ro + clearance - pitch, by hand
    g = opt.device_problem_for(default_design(), objective="rendering",
                               vary={"pitch_m": None})
    xg = list(x[:7]) + [0.045]
    assert g.overlap_m(xg) == pytest.approx(2 * ro + 4.4e-3 - 0.045, abs=1e-15)


def test_the_rendering_force_of_tilted_coils_matches_the_coil_array():
    """array_force_per_amp without cores (ratio 0) on a tilted ring against designkit.CoilArray
    of air coils in the same poses: a model that treated the tilted coils as upright (or did not
    rotate their gradient) is off by tens of percent here."""
    d = load_design(LAYOUTS / "ring6_tilt30.toml").replace(core=None)
    arr = CoilArray.from_design(d)
    rng = np.random.default_rng(4)
    pts = np.c_[rng.uniform(-0.05, 0.05, (6, 2)), rng.uniform(0.02, 0.06, 6)]
    m = np.array([0.0, 0.0, d.magnet.moment_a_m2])
    ref = np.einsum("jk,nkc->njc", force_matrix(m), arr.actuation_matrix(pts)[:, 3:, :])
    x = (0.012, 0.019, 0.1, 0.006, 0.05, 0.0, 0.7e-3)
    got = opt.array_force_per_amp(opt.RodCoil(x, 1429, 6.0, core_force_ratio=0.0), d.array,
                                  pts, d.magnet.moment_a_m2)
    np.testing.assert_allclose(got, ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())
    upright = dataclasses.replace(d.array, tilt_deg=0.0)
    wrong = opt.array_force_per_amp(opt.RodCoil(x, 1429, 6.0, core_force_ratio=0.0), upright,
                                    pts, d.magnet.moment_a_m2)
    assert np.abs(wrong - ref).max() > 0.1 * np.abs(ref).max()


def test_ring_render_points_follow_the_workspace_and_fold_by_its_mirrors(ring):
    """The rendering region of a ring is its workspace (the hexagon of the top centres), not a
    square: 5 of the 9 grid points lie in it at each height; the ring's two mirror planes fold
    them to 3, and the forces at the folded points are those at all of them."""
    pts = opt.workspace_region(ring)
    assert len(pts) == 10 and ring.workspace_region().contains(pts).all()
    p = opt.device_problem_for(ring, objective="rendering")
    assert len(p.render_points_m) == 6
    x = opt.DeviceProblem.physical(np.array(p.lower) + 0.5 * (np.array(p.upper)
                                                             - np.array(p.lower)))
    full = opt.array_render_forces(opt.RodCoil(tuple(x), p.turns(x), 6.0), ring.array, pts,
                                   ring.magnet.moment_a_m2, ring.drive.total_current_a)
    folded = p.render_forces(x)
    np.testing.assert_allclose(sorted(set(np.round(full, 9))), sorted(set(np.round(folded, 9))),
                               rtol=1e-9)


def test_the_coil_problem_takes_no_layout_variable(tmp_path, capsys):
    assert main(["optimize", "--problem", "coil", "--vary", "pitch_m", "--out",
                 str(tmp_path / "o"), "--no-progress"]) == 1
    assert "--vary" in capsys.readouterr().err and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_ring_tilt_optimum_is_feasible_and_no_other_tilt_renders_more(ring, tmp_path):
    """``optimize --vary tilt_deg`` on the tilted ring: the reported device meets every
    constraint under the panel model, and with its coil fixed a scan of the tilt finds no
    stronger rendering; the written design carries the tilt."""
    p = opt.device_problem_for(ring, objective="rendering", vary={"tilt_deg": None})
    res = opt.solve_device(p, starts=2)
    assert res.feasible and res.fast_model_check["within_bound"]
    best = res.rendering["min_upward_force_n"]
    pc = dataclasses.replace(p, corrections=res.corrections)
    x = list(res.x)
    for tilt in np.linspace(0.0, 45.0, 7):
        if pc.overlap_m(x[:7] + [tilt]) <= 0:
            assert pc.render_forces(x[:7] + [tilt], res.turns).min() <= best * (1 + 1e-4)
    written = opt.device_design(ring, res, p)
    assert written.array.tilt_deg == pytest.approx(x[7]) and written.array.kind == "ring"
    assert not [r.name for r in __import__("designkit").rules.violations(written, "cad")]
    assert math.isfinite(best) and best > 0
