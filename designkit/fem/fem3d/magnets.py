"""The 3-D model of a device's cores magnetized by several finger magnets (no coil current).

Every core of a :class:`~designkit.model.array.CoilArray` (linear, in its pose) and N uniformly
magnetized cylinders, each its own region (:mod:`.bodies`). One GetDP run per magnet on one
mesh, that magnet driven and the others passive (M = 0: air), gives the cores' response to
each magnet alone; with linear cores the responses superpose, so the pull of the cores a magnet
magnetizes on itself (its F0) and on the other magnets (the cross terms) are separated exactly.
From each run: the field of the magnetized iron B_ind at output points (its FEM magnetization
as point dipoles, :func:`.iron.core_dipoles`; no magnet's own field enters) and on every
magnet's end faces, whence the force and torque on magnet i from the cores magnetized by
magnet k: the face charges +-M_i of i's uniform magnetization in B_ind,

    F_ik = M_i [int_top B_ind dA - int_bottom B_ind dA],  tau_ik = M_i [int_top (r - c_i) x
    B_ind dA - int_bottom ...],

exact for a uniformly magnetized body in a curl-free field (Gauss in r^2 times the trapezoid
rule in the azimuth). Lengths in m, moments in A m^2, B in T, forces in N, torques in N m.
The reference for :meth:`designkit.model.array.CoilArray.bias_force_matrix` (docs/coupling.md,
"Several magnets").
"""

from __future__ import annotations

import math
import time

import numpy as np

from firmware_io.cylinder_magnet import CylinderMagnet, check_apart
from firmware_io.magnet_pair import face_nodes

from ...errors import BadInputError
from ..runner import find_getdp, run_getdp, work_folder
from .bodies import CORE0, Cyl, model_symmetry
from .device import BODY_SIZE_M, core_bodies
from .iron import core_dipoles, dipoles_field
from .mesh import MeshSettings, build_mesh
from .problem import problem_text

MAGNET_REFINE_M = 2.5e-3
"""Element size (level 0) in a box around each magnet down to the cores' tops, m."""
FACE_NODES = (6, 16)
"""Gauss nodes in r^2 and trapezoid azimuths per end face of the force integral (B_ind is
smooth on a face >= 10 mm from the iron: 6 x 16 is within 1e-6 of 12 x 32)."""
_ORDER = {"none": 0, "half": 1, "quarter": 2}


def magnet_body(magnet: CylinderMagnet, active: bool = True) -> Cyl:
    """The :class:`Cyl` of a magnet (axis along its moment, M = |m| / volume; ``active``
    False: M = 0, a passive region of air)."""
    m = np.asarray(magnet.moment_a_m2, float)
    mag = float(np.linalg.norm(m)) / (math.pi * magnet.radius_m ** 2 * magnet.length_m)
    return Cyl.on_axis("magnet", magnet.position_m, m, magnet.length_m / 2, magnet.radius_m,
                       magnetization=mag if active else 0.0)


def _face_points(magnet: CylinderMagnet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (2 k, 3) m on the top then bottom end face, their offsets from the centre (2 k,
    3) m and the face charges (2 k,) A m (M times the signed area weights)."""
    u, e1, e2 = magnet.frame()
    r, ph, w = face_nodes(*FACE_NODES)
    a = magnet.radius_m
    disc = a * ((r * np.cos(ph))[:, None] * e1 + (r * np.sin(ph))[:, None] * e2)
    half = 0.5 * magnet.length_m * u
    rel = np.r_[disc + half, disc - half]
    mag = float(np.linalg.norm(magnet.moment_a_m2)) / (math.pi * a * a * magnet.length_m)
    return magnet.position_m + rel, rel, mag * a * a * np.r_[w, -w]


def _refine_boxes(magnets, symmetry: str, size: float) -> list:
    """A box per magnet, from the cores' tops (z = 0) to 4 mm above it, 5 mm wider than its
    radius, cut to the modelled part."""
    out = []
    for mg in magnets:
        c, w = mg.position_m, mg.bounding_radius_m + 5e-3
        x0, y0 = c[0] - w, c[1] - w
        if symmetry in ("half", "quarter"):
            y0 = max(y0, 0.0)
        if symmetry == "quarter":
            x0 = max(x0, 0.0)
        out.append((x0, c[0] + w, y0, c[1] + w, min(0.0, c[2] - w), c[2] + w, size))
    return out


def _check(magnets) -> None:
    for i, a in enumerate(magnets):
        if not isinstance(a, CylinderMagnet):
            raise BadInputError(f"magnets[{i}]", "a firmware_io.cylinder_magnet.CylinderMagnet",
                                type(a).__name__)
    check_apart(magnets, error=BadInputError)


def magnets_case(array, magnets, points, *, level: int = 0, out_dir=None,
                 timeout_s: float = 3600.0) -> dict:
    """The cores of ``array`` magnetized by each of ``magnets`` (a list of
    :class:`firmware_io.cylinder_magnet.CylinderMagnet`) alone, from the 3-D FEM at mesh ``level``
    (one mesh, one GetDP run per magnet; the model cut to the largest mirror symmetry every
    run allows).

    Returns a dict: ``b_t`` (n_magnets, n, 3) T, the field at ``points`` (n, 3) m of the
    cores magnetized by magnet k; ``force_n`` (n_magnets, n_magnets, 3) N and ``torque_n_m``
    (same shape) N m, entry [i, k] on magnet i (about its centre) from the cores magnetized
    by magnet k (the diagonal: each magnet's F0); ``symmetry``, ``tetrahedra``, ``seconds``
    (GetDP's wall time summed over the runs), ``mesh_seconds``.
    """
    magnets = list(magnets)
    _check(magnets)
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    cores = core_bodies(array)
    if not cores:
        raise BadInputError("array", "an array with at least one core", "no cores")
    runs = [cores + [magnet_body(mg, active=(j == k)) for j, mg in enumerate(magnets)]
            for k in range(len(magnets))]
    sym = min((model_symmetry(b) for b in runs), key=_ORDER.get)
    exe = find_getdp()
    faces = [_face_points(mg) for mg in magnets]
    nm = len(magnets)
    out = {"b_t": np.zeros((nm, len(pts), 3)), "force_n": np.zeros((nm, nm, 3)),
           "torque_n_m": np.zeros((nm, nm, 3)), "symmetry": sym, "seconds": 0.0}
    with work_folder(out_dir, "designkit_fem3d_magnets_") as work:
        t0 = time.perf_counter()
        msh = work / "model.msh"
        stats = build_mesh(runs[0], msh, MeshSettings(
            symmetry=sym, level=level, body_size=BODY_SIZE_M,
            refine=tuple(_refine_boxes(magnets, sym, MAGNET_REFINE_M))))
        out["mesh_seconds"] = time.perf_counter() - t0
        out["tetrahedra"] = int(stats["tetrahedra"])
        for k, bodies in enumerate(runs):
            out["seconds"] += run_getdp(exe, work, problem_text(bodies, stats, core_table=True),
                                        msh, timeout_s)[1]
            pos, mom = _iron_dipoles(work, stats, bodies, sym)
            allp = np.concatenate([pts] + [f[0] for f in faces])
            b = dipoles_field(allp, pos, mom)[0]
            out["b_t"][k] = b[:len(pts)]
            s = len(pts)
            for i, (_, rel, q) in enumerate(faces):
                bf = b[s:s + len(q)]
                s += len(q)
                out["force_n"][i, k] = q @ bf
                out["torque_n_m"][i, k] = q @ np.cross(rel, bf)
    return out


def _iron_dipoles(work, stats, bodies, symmetry) -> tuple[np.ndarray, np.ndarray]:
    """Every core's FEM magnetization as point dipoles (positions (k, 3) m, moments (k, 3)
    A m^2; the mirror images of a symmetric model included)."""
    pos, mom = [], []
    for t in stats["cores"]:
        d = np.loadtxt(work / f"bcore_{t}.txt", ndmin=2)
        p, m = core_dipoles(d[:, :12].reshape(-1, 4, 3), d[:, 12:24].reshape(-1, 4, 3),
                            bodies[t - CORE0].mu_r, symmetry)
        pos.append(p)
        mom.append(m)
    return np.concatenate(pos), np.concatenate(mom)

