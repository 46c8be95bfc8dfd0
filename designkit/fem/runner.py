"""Run one axisymmetric FEM model of a coil with GetDP and extract what designkit predicts.

:func:`solve` meshes (gmsh), writes the .pro (``problem.py``), runs ``getdp`` and reads back
B along an axis line and an off-axis line above the coil, the magnetic energy and the winding's
flux linkage. Derivatives along the lines come from local least-squares polynomials through
densely sampled B (the FEM's b is piecewise linear; the fit averages its inter-element jumps).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..constants import MU0
from ..cores.material import STEEL1010_B, STEEL1010_H
from ..errors import BadInputError, MissingDependencyError
from ..support.atomic import write_json_atomic
from .mesh import MeshSpec, build_mesh, export_meshio
from .problem import AxiProblem, problem_text

APT_HINT = "sudo apt-get install getdp"


class GetDPNotFoundError(MissingDependencyError):
    """The ``getdp`` program is not on PATH."""

    def __init__(self, purpose: str = "designkit.fem"):
        self.module = "getdp"
        self.package = "getdp"
        self.purpose = purpose
        ImportError.__init__(
            self, f"{purpose} needs the GetDP finite-element solver (program 'getdp' on PATH): "
                  f"install it with `{APT_HINT}` (Debian/Ubuntu package 'getdp', version >= 3.2)")

    def __reduce__(self):
        return (type(self), (self.purpose,))


def find_getdp() -> str:
    """Path of the getdp executable, or raise :class:`GetDPNotFoundError`."""
    path = shutil.which("getdp")
    if path is None:
        raise GetDPNotFoundError()
    return path


@contextlib.contextmanager
def work_folder(out_dir: str | Path | None, prefix: str):
    """The folder a GetDP run writes into: ``out_dir`` (created if needed, kept), or a
    temporary folder named ``prefix...`` removed when the block ends."""
    if out_dir is None:
        with tempfile.TemporaryDirectory(prefix=prefix) as name:
            yield Path(name)
    else:
        work = Path(out_dir)
        work.mkdir(parents=True, exist_ok=True)
        yield work


def run_getdp(exe: str, work: Path, pro_text: str, msh: Path, timeout_s: float, *,
              verbosity: int = 2, expect: str | None = None) -> tuple[str, float]:
    """Write ``work/model.pro``, solve MagSta and run the post-operation Post on ``msh``.

    GetDP's output goes to ``work/getdp.log``. Raises RuntimeError (with the log's tail) when
    getdp fails or does not write ``work/expect``. Returns (stdout, seconds of the run).
    """
    pro = work / "model.pro"
    pro.write_text(pro_text)
    t0 = time.perf_counter()
    proc = subprocess.run([exe, str(pro), "-msh", str(msh), "-solve", "MagSta", "-pos", "Post",
                           "-v", str(verbosity)], cwd=work, capture_output=True, text=True,
                          timeout=timeout_s)
    seconds = time.perf_counter() - t0
    (work / "getdp.log").write_text(proc.stdout + "\n" + proc.stderr)
    if proc.returncode != 0 or (expect is not None and not (work / expect).exists()):
        raise RuntimeError(f"getdp failed (exit {proc.returncode}); see {work / 'getdp.log'}:\n"
                           + (proc.stderr or proc.stdout)[-2000:])
    return proc.stdout, seconds


@dataclass(frozen=True)
class LineResult:
    """B sampled along a line r = const above the coil (local frame, winding centre at z=0)."""

    r: float
    z: np.ndarray
    br: np.ndarray
    bz: np.ndarray

    def fit(self, z0, *, half_window: float = 4e-3, degree: int = 4):
        """Bz, dBz/dz, Br, dBr/dz at local heights ``z0`` (m) from local polynomial fits.

        Returns
        -------
        dict of ndarrays (T and T/m), each of the shape of ``z0``.
        """
        z0 = np.atleast_1d(np.asarray(z0, dtype=float))
        out = {k: np.empty(z0.shape) for k in ("bz", "dbz_dz", "br", "dbr_dz")}
        for i, zc in enumerate(z0):
            lo = max(zc - half_window, self.z[0])
            hi = min(zc + half_window, self.z[-1])
            if hi - lo < 2 * half_window * 0.999:  # shift the window inside the sampled range
                if lo == self.z[0]:
                    hi = min(lo + 2 * half_window, self.z[-1])
                else:
                    lo = max(hi - 2 * half_window, self.z[0])
            sel = (self.z >= lo) & (self.z <= hi)
            t = (self.z[sel] - zc) / half_window
            for name, y in (("bz", self.bz), ("br", self.br)):
                c = np.polynomial.polynomial.polyfit(t, y[sel], degree)
                out[name][i] = c[0]
                out["d" + name + "_dz"][i] = c[1] / half_window
        return out


@dataclass(frozen=True)
class FemResult:
    """What one GetDP solve gives (local frame of the winding; SI units)."""

    current: float
    axis: LineResult
    off_axis: LineResult
    energy_j: float
    flux_linkage_wb: float
    solve_seconds: float
    mesh_seconds: float
    mesh_stats: dict
    files: dict = field(default_factory=dict)
    newton_converged: bool = True
    probes: dict | None = None
    """With ``solve(probes=...)``: arrays r, z (local, m), br, bz (T), dbr_dz, dbz_dz (T/m)."""

    @property
    def inductance_energy(self) -> float:
        """L = 2 W / I^2 (linear problems), H."""
        return 2.0 * self.energy_j / self.current**2

    @property
    def inductance_linkage(self) -> float:
        """L = flux linkage / I (secant inductance; valid for nonlinear cores too), H."""
        return self.flux_linkage_wb / self.current

    def to_dict(self) -> dict:
        return {
            "current_a": self.current,
            "energy_j": self.energy_j,
            "flux_linkage_wb": self.flux_linkage_wb,
            "inductance_energy_h": self.inductance_energy,
            "inductance_linkage_h": self.inductance_linkage,
            "solve_seconds": self.solve_seconds,
            "mesh_seconds": self.mesh_seconds,
            "mesh": self.mesh_stats,
            "newton_converged": self.newton_converged,
            "axis": {"r_m": self.axis.r, "z_m": self.axis.z, "br_t": self.axis.br,
                     "bz_t": self.axis.bz},
            "off_axis": {"r_m": self.off_axis.r, "z_m": self.off_axis.z,
                         "br_t": self.off_axis.br, "bz_t": self.off_axis.bz},
            "files": {k: str(v) for k, v in self.files.items()},
        }


def read_line(path: Path, r: float) -> LineResult:
    data = np.loadtxt(path, ndmin=2)
    # SimpleTable: x y z bx by bz (GetDP prints the 3 vector components after the coordinates)
    y = data[:, 1]
    order = np.argsort(y)
    return LineResult(r, y[order], data[order, 3], data[order, 4])


def _read_global(path: Path) -> float:
    tokens = path.read_text().split()
    return float(tokens[-1])


def _material(core, mu_r, bh):
    """The core's material: (mu_r, bh) with the core's own when neither is given."""
    if bh not in (None, "steel1010"):
        raise BadInputError("bh", "None or 'steel1010'", bh)
    if core is not None and mu_r is None and bh is None:
        if core.bh == "steel1010":
            bh = "steel1010"
        else:
            mu_r = float(core.relative_permeability)
    return mu_r, bh


def _probe_box(probes, half_window):
    """Checked probes (n, 2) m and the (r_max, z_lo, z_hi) box meshed at the probe size."""
    probes = np.atleast_2d(np.asarray(probes, dtype=float))
    if probes.ndim != 2 or probes.shape[1] != 2 or not np.all(np.isfinite(probes)) \
            or np.any(probes[:, 0] < 0) or np.any(np.hypot(*probes.T) > 0.2):
        raise BadInputError("probes", "finite (r >= 0, z) pairs within 0.2 m of the coil",
                            probes.shape)
    pw = half_window
    pbox = (float(probes[:, 0].max()) + 5e-3, float(probes[:, 1].min()) - pw - 5e-3,
            float(probes[:, 1].max()) + pw + 5e-3)
    return probes, pbox


def _extraction_lines(z_lo, z_hi, margin, sample_step, off_axis_r, probes, probe_half_window):
    """(r0, z0, r1, z1, n, file) of the axis line, the off-axis line and each probe segment."""
    n = int(round((z_hi - z_lo + 2 * margin) / sample_step))
    r_axis = 1e-7  # on r = 0 exactly VolAxiSqu divides by r; 0.1 um off is the axis value
    lines = [(r_axis, z_lo - margin, r_axis, z_hi + margin, n, "line_axis.txt"),
             (off_axis_r, z_lo - margin, off_axis_r, z_hi + margin, n, "line_off.txt")]
    if probes is not None:
        npw = max(16, int(round(2 * probe_half_window / (0.1e-3))))
        for i, (pr, pz) in enumerate(probes):
            rr, pz = max(float(pr), 1e-7), float(pz)
            lines.append((rr, pz - probe_half_window, rr, pz + probe_half_window, npw,
                          f"probe_{i}.txt"))
    return lines


def _read_probes(work: Path, probes, probe_half_window) -> dict:
    """B and its z-derivatives at each probe from the fit along its segment (FemResult.probes)."""
    cols = {k: np.empty(len(probes)) for k in ("br", "bz", "dbr_dz", "dbz_dz")}
    for i, (pr, pz) in enumerate(probes):
        fit = read_line(work / f"probe_{i}.txt", pr).fit(
            np.array([pz]), half_window=probe_half_window)
        for k in cols:
            cols[k][i] = fit[k][0]
    return {"r": probes[:, 0].copy(), "z": probes[:, 1].copy(), **cols}


@dataclass(frozen=True)
class FemSettings:
    """How :func:`solve` models and samples one coil (SI).

    mu_r, bh
        The core's material: linear ``mu_r``, or ``bh`` (B-H curve name, 'steel1010'); by
        default the core's own ``relative_permeability``.
    level : int
        Mesh refinement level (0 coarse ... 6 fine); sizes shrink by sqrt(2) per level.
    line_z : (lo, hi), m
        Range of the extraction lines *above the winding's top face*.
    off_axis_r : float, m
        Radius of the second extraction line.
    out_dir : path or None
        Where to keep the mesh, .pro and raw outputs; None uses a temporary folder.
    export : bool
        Also write .vtu and .xdmf copies of the mesh (meshio).
    sample_step : float, m
        Spacing of B along the extraction lines.
    timeout_s : float
        GetDP's wall-clock limit, s.
    probes : array (n, 2) or None
        (r, z) points in the winding's local frame (m) anywhere around the coil, in air and at
        least ``probe_half_window`` from any material boundary: B there and dB/dz from a
        degree-4 least-squares polynomial through B sampled on the vertical segment
        z +- probe_half_window (the FEM's b is piecewise polynomial; the fit averages its
        inter-element jumps). The region holding them is meshed at 1 mm x 2^(-level/2).
    """

    mu_r: float | None = None
    bh: str | None = None
    level: int = 1
    line_z: tuple = (0.010, 0.105)
    off_axis_r: float = 0.010
    out_dir: str | Path | None = None
    export: bool = False
    sample_step: float = 0.25e-3
    timeout_s: float = 600.0
    probes: object = None
    probe_half_window: float = 2.5e-3


def solve(coil, current: float, settings: FemSettings | None = None, **changes) -> FemResult:
    """Solve the axisymmetric FEM model of ``coil`` at ``current`` (A, > 0) with GetDP.

    ``coil``: a designkit.Coil (its pose is ignored: the model is in the winding's local
    frame; its core, if any, is meshed). ``settings`` (:class:`FemSettings`; None: its
    defaults), ``changes``: fields of it to replace (``solve(coil, 1.0, level=0)``).
    Returns :class:`FemResult`.
    """
    names = {f.name for f in dataclasses.fields(FemSettings)}
    for key in changes:
        if key not in names:
            raise BadInputError("FEM setting", f"one of {sorted(names)}", key)
    st = dataclasses.replace(settings or FemSettings(), **changes)
    mu_r, bh, level, line_z, off_axis_r = st.mu_r, st.bh, st.level, st.line_z, st.off_axis_r
    out_dir, export, sample_step, timeout_s = st.out_dir, st.export, st.sample_step, st.timeout_s
    probes, probe_half_window = st.probes, st.probe_half_window
    exe = find_getdp()
    current = float(current)
    if not (math.isfinite(current) and current > 0):
        raise BadInputError("current", "a finite number > 0 A", current)
    if not (isinstance(level, int) and 0 <= level <= 6):
        raise BadInputError("level", "an integer in [0, 6]", level)
    core = coil.core
    mu_r, bh = _material(core, mu_r, bh)
    top = coil.length / 2
    z_lo, z_hi = top + line_z[0], top + line_z[1]
    margin = 6e-3
    pbox = None
    if probes is not None:
        probes, pbox = _probe_box(probes, probe_half_window)
    spec = MeshSpec(coil.inner_radius, coil.outer_radius, coil.length,
                    core.radius if core else None, core.length if core else None,
                    core.offset if core else 0.0, z_lo - margin, z_hi + margin,
                    off_axis_r + 4e-3, level, probe_box=pbox)
    with work_folder(out_dir, "designkit_fem_") as work:
        t0 = time.perf_counter()
        msh = work / "model.msh"
        stats = build_mesh(spec, msh)
        files = {"mesh": msh}
        if export:
            for p in export_meshio(msh, work / "model"):
                files[p.suffix.lstrip(".")] = p
        t_mesh = time.perf_counter() - t0
        area = (coil.outer_radius - coil.inner_radius) * coil.length
        jd = coil.turns * current / area
        lines = _extraction_lines(z_lo, z_hi, margin, sample_step, off_axis_r, probes,
                                  probe_half_window)
        bh_tab = (STEEL1010_H, STEEL1010_B) if bh == "steel1010" else None
        pro = problem_text(AxiProblem(
            current_density=jd, mu_r=mu_r, bh=bh_tab, has_core=core is not None,
            shell_inner=spec.shell_inner, shell_outer=spec.shell_outer, lines=lines,
            winding_area=area, turns=coil.turns))
        stdout, t_solve = run_getdp(exe, work, pro, msh, timeout_s, verbosity=3,
                                    expect="line_axis.txt")
        files["pro"], files["log"] = work / "model.pro", work / "getdp.log"
        converged = True
        if bh_tab is not None:
            converged = "Non linear" not in stdout or "did not converge" not in stdout
        axis = read_line(work / "line_axis.txt", 0.0)
        off = read_line(work / "line_off.txt", off_axis_r)
        probe_out = None if probes is None else _read_probes(work, probes, probe_half_window)
        # GetDP's axisymmetric Jacobians integrate per radian of azimuth: times 2 pi
        energy = 2 * math.pi * _read_global(work / "energy.txt")
        linkage = 2 * math.pi * _read_global(work / "linkage.txt")
        return FemResult(current, axis, off, energy, linkage, t_solve, t_mesh, stats,
                         files if out_dir is not None else {}, converged, probe_out)


def write_result_json(result: FemResult, path: str | Path, extra: dict | None = None) -> Path:
    """``result.to_dict()`` (plus ``extra``) as JSON at ``path``, written atomically."""
    data = result.to_dict()
    if extra:
        data.update(extra)
    return write_json_atomic(path, data)


__all__ = ["FemResult", "FemSettings", "LineResult", "GetDPNotFoundError", "find_getdp", "solve",
           "write_result_json", "MU0", "json"]
