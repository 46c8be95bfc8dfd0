"""The report's section on a design's sensor layout: its Cramer-Rao bound maps over the
workspace for one magnet (and for two, when the coils serve two), beside a planned layout when
one is given (a ``[sensors]`` table from ``designkit sensors plan``), as a figure, numbers for
report.json and Markdown lines. Bounds as :class:`designkit.sensing.crb.BoundSettings`' defaults
(the pose, the background, TLV493D noise with rounding, the cores). docs/sensors.md.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from ..design.files import design_from_dict
from ..errors import BadInputError
from .crb import BoundSettings
from .design_plan import board_names, scenario_sets
from .figure import bound_figure
from .maps import Layout, direction_text, layout_bounds, summary
from .region import RegionSettings
from .sites import design_boards

LATTICE_M = {"quick": 0.030, "full": 0.015}
"""Step of the magnet positions the report judges, x-y and z, m."""
PAIR_SEPARATION_M = (0.030, 0.060)
"""Two magnets' centre distances the report judges, m."""


def planned_layout(design, path, param: str = "--sensors") -> Layout:
    """The layout of a ``[sensors]`` table in a TOML file (``sensors.toml`` of ``designkit
    sensors plan``, or a design file), checked as the design would check it."""
    p = Path(path)
    try:
        table = tomllib.loads(p.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise BadInputError(param, "a readable TOML file with a [sensors] table",
                            f"{p} ({exc})") from None
    if not isinstance(table.get("sensors"), dict):
        raise BadInputError(param, "a TOML file with a [sensors] table", str(p))
    other = design_from_dict({"sensors": table["sensors"]}, source=str(p))
    spec = design.replace(sensors=other.sensors)
    pos, frames = spec.sensor_poses()
    return Layout(f"planned ({p.name})", pos, frames)


def layout_report(design, figure_path, quality: str = "full", planned: Layout | None = None,
                  settings: BoundSettings = BoundSettings()) -> dict:
    """Bounds of the design's layout (and ``planned``) over the workspace; writes the figure.

    Returns {'figure', 'lattice_m', 'settings', 'summaries': {kind: {layout: summary}}}.
    """
    ws = design.workspace
    region = RegionSettings((ws.z_min_m, ws.z_max_m), LATTICE_M[quality], LATTICE_M[quality],
                            PAIR_SEPARATION_M)
    magnets = 2 if design.n_coils // 3 >= 2 else 1
    scenarios = scenario_sets(design, region, magnets)
    pos, frames = design.sensor_poses()
    layouts = [Layout("design", pos, frames)] + ([planned] if planned is not None else [])
    boards = design_boards(design)
    blocks, summaries = [], {}
    for kind, scen in scenarios.items():
        bounds = layout_bounds(design, layouts, scen, settings)
        summaries[kind] = {lay.name: summary(bounds[lay.name], scen) for lay in layouts}
        blocks.append((scen, [(lay, bounds[lay.name], board_names(lay.positions_m, boards))
                              for lay in layouts]))
    bound_figure(blocks, design, figure_path)
    return {"figure": Path(figure_path).name, "lattice_m": region.spacing_m,
            "separation_m": list(PAIR_SEPARATION_M),
            "settings": {"noise_t": settings.noise_t, "lsb_t": settings.lsb_t,
                         "dof": settings.dof, "background": settings.background,
                         "cores": settings.cores},
            "summaries": summaries}


def layout_report_markdown(entry: dict, figure: str) -> list[str]:
    """The report's section: per layout and kind, the worst and median bound by height."""
    lines = ["## Sensor layout: Cramer-Rao bound of the magnet position", "",
             "Position (5 unknowns a magnet plus a uniform background field, TLV493D noise 0.1 "
             "mT rms per axis with the readout's rounding, the cores the magnet magnetizes; "
             f"magnet positions every {entry['lattice_m'] * 1e3:g} mm in the workspace; two "
             f"magnets {entry['separation_m'][0] * 1e3:g}-{entry['separation_m'][1] * 1e3:g} mm "
             "apart). rms bound worst / median, and the share of magnets whose mean absolute "
             "error bound is within 1.5 mm. A planned layout: `designkit sensors plan` "
             "(docs/sensors.md).", ""]
    for kind, per_layout in entry["summaries"].items():
        names = list(per_layout)
        lines += [f"**{kind}**", "", "| heights | " + " | ".join(names) + " |",
                  "| --- |" + " --- |" * len(names)]
        rows = per_layout[names[0]]["rows"]
        keep = [k for k, r in enumerate(rows) if kind == "one magnet" or r["group"] == "all"]
        for k in keep:
            cells = [_cell(per_layout[n]["rows"][k]) for n in names]
            lines.append(f"| {rows[k]['group']} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [f"![sensor bounds]({figure})", ""]
    return lines


def _cell(row: dict) -> str:
    return (f"{row['worst_rms_m'] * 1e3:.3g} / {row['median_rms_m'] * 1e3:.3g} mm, "
            f"{row['within_target']:.0%} within 1.5 mm, direction <= "
            f"{direction_text(row['worst_orientation_rad'])} deg")
