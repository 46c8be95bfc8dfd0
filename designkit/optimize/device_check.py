"""A given design judged as a device: its coil and core under the device problem's panel model
and every constraint, with what it misses (the side-by-side report of the thesis device and
the optimized one). Numbers SI; the rule book (:mod:`designkit.rules`: winding fit, the
design's own supply, workspace floor, the printed assembly) is checked too.
"""

from __future__ import annotations

import dataclasses

from .. import rules
from ..design import Design
from ..errors import BadInputError
from ..model import electrical as el
from ..support.blas import one_blas_thread
from .device_problem import DeviceProblem, device_problem_for
from .search_space import SEARCH_VARIABLES, SearchSpace, Variable


def evaluate_device(design: Design, problem: DeviceProblem | None = None) -> dict:
    """A design's coil and core under the device problem's panel model and constraints (SI).

    Used for the side-by-side report: the thesis device with every constraint it misses, the
    optimized device with its margins. Needs a core (``design.core``).
    """
    if design.core is None:
        raise BadInputError("design.core", "a core (the device problem has an iron core)", None)
    p = problem if problem is not None else device_problem_for(design)
    c, k, w = design.coil, design.core, design.wire
    top = c.length_m / 2
    prot = k.offset_m + k.length_m / 2 - top
    x = [c.inner_radius_m, c.outer_radius_m, c.length_m, k.radius_m, k.length_m,
         max(prot, 0.0), w.diameter_m]
    p = dataclasses.replace(p, insulation_ratio=w.insulated_diameter_m / w.diameter_m)
    with one_blas_thread():
        ev = p.evaluate(x, turns=c.turns, model="panel")
    fit = el.turns_from_geometry(c.inner_radius_m, c.outer_radius_m, c.length_m,
                                 w.insulated_diameter_m, w.packing)
    table = p.constraint_table(x, ev)
    # the rule book: winding fit, the design's supply vs the driver, workspace floor, and
    # every rule the printed assembly must meet (what cad refuses)
    table.update({r.name: r.as_dict() for r in rules.rules(design)})
    out = {k2: v2 for k2, v2 in ev.items() if k2 != "g"}
    out.update({"name": design.name, "turns": int(c.turns), "turns_that_fit": fit,
                "inner_radius_m": c.inner_radius_m, "outer_radius_m": c.outer_radius_m,
                "length_m": c.length_m, "wire_diameter_m": w.diameter_m,
                "core_radius_m": k.radius_m, "core_length_m": k.length_m,
                "core_protrusion_m": prot, "current_a": p.current_a,
                "temperature_c": p.hot_temperature_c,
                "core_model": "steel1010 surface-current panel model",
                "constraints": table,
                "violated": sorted(n for n, t in table.items() if not t["met"]),
                "feasible": all(t["met"] for t in table.values())})
    return out




AIR_CORE_CONSTRAINTS = ("resistance_ohm", "supply_voltage_v", "settling_time_s",
                        "time_to_max_temperature_s")
"""The device constraints an air-core coil has (the others are the core's)."""


def air_core_constraints(design: Design) -> dict:
    """The electrical device constraints of an air-core design (no core): R at the hot limit,
    I R there vs the supply, 5 L / R(cold), adiabatic heating time -- the device problem's own
    formulas (:meth:`DeviceProblem.table_with_inductance`) with the winding's closed-form
    air-core inductance (:func:`designkit.model.electrical.air_inductance_from_geometry`)."""
    c, w = design.coil, design.wire
    space = SearchSpace(tuple(Variable(name, 0.0, 1.0) for name in SEARCH_VARIABLES))
    problem = DeviceProblem(design=design, space=space,
                            insulation_ratio=w.insulated_diameter_m / w.diameter_m)
    x = [c.inner_radius_m, c.outer_radius_m, c.length_m, 0.0, 0.0, 0.0, w.diameter_m]
    inductance = el.air_inductance_from_geometry(c.inner_radius_m, c.outer_radius_m,
                                                 c.length_m, c.turns)
    table = problem.table_with_inductance(x, c.turns, inductance)
    return {name: table[name] for name in AIR_CORE_CONSTRAINTS}


def rule_table(design: Design) -> dict:
    """Every rule and constraint of a design, by name -> :meth:`designkit.rules.Rule.as_dict`
    rows: the device constraints (a cored design's under the panel model,
    :func:`evaluate_device`; an air-core design's electrical ones, :func:`air_core_constraints`;
    each coil type of its ``[[groups]]`` too, :func:`group_constraints`) and the rule book
    (:func:`designkit.rules.rules`, any design)."""
    if design.core is None:
        table = air_core_constraints(design)
        table.update({r.name: r.as_dict() for r in rules.rules(design)})
    else:
        table = evaluate_device(design)["constraints"]
    for row in table.values():
        row.setdefault("group", "device")
        row.setdefault("keys", [])
    return {**table, **group_constraints(design)}


def group_constraints(design: Design) -> dict:
    """The device constraints of each coil type of the design's ``[[groups]]`` (a cored
    type's winding and core under the panel model, as :func:`evaluate_device` judges the
    design's own; an air-core type's electrical ones, :func:`air_core_constraints`), named
    ``NAME@groups[g]``, their keys the group's."""
    out = {}
    for t in rules.coil_types(design)[0]:
        if not t.where:
            continue
        alone = dataclasses.replace(design, coil=t.coil, core=t.core, groups=())
        where = t.where.rstrip(".")
        table = (air_core_constraints(alone) if t.core is None
                 else evaluate_device(alone)["constraints"])
        for name, row in table.items():
            if "group" in row:  # a rule of the rule book: the whole design's table has it
                continue
            keys = [t.where + k if k.startswith(("coil.", "core.")) else k
                    for k in row.get("keys", [])]
            out[f"{name}@{where}"] = {**row, "group": "device", "keys": keys}
    return out
