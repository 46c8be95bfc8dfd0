"""``python -m firmware_io.mapfile MAP.npz``: check a map on the target host (numpy only).

Loads and validates the map, evaluates A(p), F0(p) and the sensor field at the box centre and
prints a labelled summary (exit 0); a file that is not a valid map gives one ``error:`` line
naming the problem and how to rebuild it (exit 1), never a traceback.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..errors import FirmwareIOError
from .drive import DriveRecord
from .reader import MapFile

EXIT_BAD_MAP = 1


def summary(m: MapFile) -> str:
    """The map's labelled summary: what it is for, its box, its drive, its values at the box
    centre and the errors measured when it was built."""
    lo, hi = m.bounds
    centre = (lo + hi) / 2
    a = m.actuation(centre)
    f0 = m.bias_force(centre)
    b = m.sensor_induced_field(centre)
    drive = DriveRecord.from_dict(m.meta["drive"], m.n_coils)
    errors = m.meta.get("errors", {})
    worst = max(errors.get("actuation_max_rel_per_row", {}).values(), default=float("nan"))
    rows = [
        ("design", f"{m.meta['design_name']} (SHA-256 {m.design_sha256[:12]}...)"),
        ("format version", f"{m.meta['version']}"),
        ("coils / sensors", f"{m.n_coils} / {m.n_sensors}"),
        ("box (mm)", f"{np.round(lo * 1e3, 2).tolist()} .. {np.round(hi * 1e3, 2).tolist()}"),
        ("magnet moment (A m^2)", f"{np.round(m.moment_a_m2, 4).tolist()}"),
        ("supply / driver", f"{drive.supply_voltage_v:g} V / {drive.driver.name} "
                            f"({drive.driver.min_voltage_v:g}-{drive.driver.max_voltage_v:g} V, "
                            f"{drive.driver.continuous_current_a:g} A)"),
        ("current limit / budget (A)", f"{drive.current_limit_a:.4g} / "
                                       f"{drive.total_current_a:.4g}"),
        ("drive rating", "; ".join(drive.violations()) or "within the driver's ratings"),
        ("at the box centre: max |A| B rows (T/A)", f"{np.abs(a[:3]).max():.4g}"),
        ("at the box centre: max |A| gradient rows (T/(m A))", f"{np.abs(a[3:]).max():.4g}"),
        ("at the box centre: F0 (mN)", f"{np.round(f0 * 1e3, 3).tolist()}"),
        ("at the box centre: max |induced field at the sensors| (mT)",
         f"{np.abs(b).max() * 1e3:.4g}"),
        ("build check: worst row error of A (of the row's largest)", f"{worst:.3g}"),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {v}" for k, v in rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m firmware_io.mapfile",
                                     description="Check a map file on the target host.")
    parser.add_argument("map", help="the map file (designkit map --out FILE.npz)")
    args = parser.parse_args(argv)
    try:
        m = MapFile.load(args.map)
        text = summary(m)
    except (FirmwareIOError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_MAP
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    print(text)
    return 0


if __name__ == "__main__":  # pragma: no cover - the command line
    sys.exit(main())
