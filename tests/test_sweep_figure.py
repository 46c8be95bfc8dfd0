"""sweep.csv says why a design is infeasible; sweep.png says which slice it shows, keeps its
legend off the points and its labels on the canvas, and explains an all-infeasible sweep."""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest

from designkit import Coil, default_design
from designkit.model import electrical as el
from designkit.optimize.sweep import ParamRange, parse_param, run_sweep, sweep_figure

from test_cli import designkit


def _extent_inside_canvas(fig):
    """Everything drawn (tick labels, axis labels, titles, colour bar) lies on the canvas."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    for ax in fig.axes:
        bb = ax.get_tightbbox(renderer)
        assert bb.x0 >= canvas.x0 - 0.5 and bb.x1 <= canvas.x1 + 0.5, ax
        assert bb.y0 >= canvas.y0 - 0.5 and bb.y1 <= canvas.y1 + 0.5, ax


@pytest.mark.parametrize("args,param,value", [
    (["--param", "inner_radius_m=6:10:3"], "--param inner_radius_m START", "6.0"),
    (["--param", "length_m=10:100:3"], "--param length_m START", "10.0"),
    (["--array", "--param", "pitch_m=40:60:2"], "--param pitch_m START", "40.0"),
])
def test_mm_by_mistake_is_refused_at_once_with_the_hint(tmp_path, args, param, value):
    # every row would be invalid: one line (parameter, value, valid range, the mm hint) before
    # any work, nothing written
    res = designkit("sweep", *args, "--workers", "1", "--no-progress", "--out", "sw",
                    cwd=tmp_path)
    assert res.returncode == 1 and "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    for word in (param, value, "[0.0001, " if "pitch" not in param else "[0.001, ",
                 "Millimetres where metres are expected", "mm"):
        assert word in lines[0], lines[0]
    assert not (tmp_path / "sw").exists() and "planned" not in res.stdout


def test_lengths_with_units_are_the_same_sweep(tmp_path):
    from designkit.commands.sweep import si_param

    assert parse_param(si_param("length_m=20mm:10cm:3")) == parse_param("length_m=0.02:0.1:3")
    assert si_param("current_a=1:2:2") == "current_a=1:2:2"  # not a length: untouched


def test_reason_matches_independent_limits():
    d = default_design()
    rng = np.random.default_rng(17)
    result = run_sweep(d, [parse_param("inner_radius_m=0.005:0.02:7"),
                           parse_param("length_m=0.02:0.1:6")], workers=1, progress=False)
    seen = set()
    for r in result.rows:
        if not r["valid"]:
            assert r["reason"].startswith("outer radius < inner radius")
            continue
        coil = Coil(r["inner_radius_m"], r["outer_radius_m"], r["length_m"], r["turns"])
        res_ohm = el.resistance(coil, d.wire)
        over_r = res_ohm > d.optimize.max_resistance_ohm
        over_t = 5 * r["time_constant_s"] > d.optimize.max_settling_time_s
        assert ("R(20 C) > 6 ohm" in r["reason"]) == over_r
        assert ("5 L/R > 100 ms" in r["reason"]) == over_t
        assert (r["reason"] == "") == r["feasible"]
        seen.add((over_r, over_t))
    assert len(seen) >= 2  # the grid crosses a limit
    del rng


def _fig_all_infeasible():
    d = default_design()
    # the library's own ranges (the command line refuses these values before any work)
    result = run_sweep(d, [ParamRange("inner_radius_m", 6.0, 10.0, 3),
                           parse_param("length_m=0.03:0.1:3")], workers=1, progress=False)
    return result, sweep_figure(result)


def test_all_infeasible_plot_says_so_instead_of_empty_axes():
    result, fig = _fig_all_infeasible()
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert any("no feasible design" in t and "millimetres" in t for t in texts)
    _extent_inside_canvas(fig)


def _within_rating():
    """The thesis design with its supply at the driver's rating: the rule book's one violation
    no coil sweep can fix removed (feasible rows exist)."""
    d = default_design()
    return dataclasses.replace(d, drive=dataclasses.replace(
        d.drive, supply_voltage_v=d.drive.driver_max_voltage_v))


def test_three_parameter_sweep_names_its_slice_and_legend_is_off_the_points():
    d = _within_rating()
    # a small grid: what is checked (the slice, the legend) does not grow with it
    result = run_sweep(d, [parse_param("inner_radius_m=0.006:0.014:3"),
                           parse_param("length_m=0.03:0.1:4"),
                           parse_param("outer_radius_m=0.015:0.025:2")], workers=1,
                       progress=False)
    fig = sweep_figure(result)
    ax = fig.axes[0]
    best = result.rows[result.best_index]
    title = ax.get_title()
    assert "slice at outer_radius = " in title
    assert f"{best['outer_radius_m'] * 1e3:.4g} mm" in title
    n_slice = sum(1 for r in result.rows if r["outer_radius_m"] == best["outer_radius_m"])
    assert f"{n_slice} of {len(result.rows)} designs" in title
    # every plotted point belongs to the slice: 3 x 4 points
    n_points = sum(len(c.get_offsets()) for c in ax.collections)
    assert n_points == n_slice == 12
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend = ax.get_legend().get_window_extent(renderer)
    axes_box = ax.get_window_extent(renderer)
    assert legend.y0 >= axes_box.y1 - 1.0  # above the axes, not over the points
    _extent_inside_canvas(fig)
    assert math.isfinite(best["force_n"])


@pytest.mark.parametrize("n", [1, 2])
def test_one_and_two_parameter_figures_have_no_slice_note(n):
    d = default_design()
    params = [parse_param("inner_radius_m=0.006:0.014:4"), parse_param("length_m=0.03:0.1:3")]
    result = run_sweep(d, params[:n], workers=1, progress=False)
    fig = sweep_figure(result)
    assert "slice" not in fig.axes[0].get_title()
    _extent_inside_canvas(fig)


def test_figure_names_the_objective_and_limits_it_was_given():
    # the array sweep plots another objective under other limits: the figure must say so
    d = _within_rating()
    result = run_sweep(d, [parse_param("inner_radius_m=0.006:0.014:4"),
                           parse_param("length_m=0.03:0.1:3")], workers=1, progress=False)
    fig = sweep_figure(result, objective="smallest upward force", limits="device constraints")
    title = fig.axes[0].get_title().splitlines()
    assert title[0].endswith("feasible (device constraints)")
    # the model, current and height it was evaluated with (the design's own core model)
    assert title[1] == "model: surface-current, current 6 A, magnet at 30 mm above the coil top"
    assert fig.axes[1].get_ylabel() == "smallest upward force (mN)"  # the colour bar
    _extent_inside_canvas(fig)


def test_array_sweep_says_why_a_row_is_infeasible():
    from designkit.design import named_design
    from designkit.optimize.sweep import ARRAY_PARAMETERS, reason_summary, run_array_sweep

    d = named_design("optimized")
    result = run_array_sweep(d, [parse_param("pitch_m=0.03:0.05:2", ARRAY_PARAMETERS),
                                 parse_param("core_length_m=0.05:0.08:2", ARRAY_PARAMETERS)],
                             workers=1, progress=False)
    for r in result.rows:
        # a core reaching below the winding is a valid device (the thesis' core does)
        if 2 * d.coil.outer_radius_m > r["pitch_m"]:
            assert r["reason"].startswith("coils overlap")
        else:
            assert r["valid"]
        assert (r["reason"] == "") == r["feasible"]
        assert r["core_model"] == "steel1010 fast slice model"
    assert any(r["feasible"] for r in result.rows)
    assert "coils overlap" in reason_summary(result)
