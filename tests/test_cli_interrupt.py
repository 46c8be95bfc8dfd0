"""Ctrl-C while a command works: one line on stderr, exit 130, nothing left behind.

Each command runs in its own process; a wrapper around its main computation writes a flag file
when the work starts, the test waits for it, lets the work run a little, sends SIGINT and
checks the exit code, the single line and that the working folder is as empty as before. The
wrapped computation repeats until the signal arrives, so the test does not depend on how fast
the machine is.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

DRIVER = """
import importlib, pathlib, sys, time
target, flag, hold = sys.argv[1], sys.argv[2], float(sys.argv[3])
mod, _, name = target.rpartition(".")
module = importlib.import_module(mod)
original = getattr(module, name)
def started(*args, **kwargs):
    pathlib.Path(flag).write_text("started")
    time.sleep(hold)  # a step that takes this long (its earlier outputs already staged)
    # The real work, repeated until Ctrl-C comes (a fast machine could finish it once before
    # the signal, and the test would then prove nothing); bounded so a lost signal cannot hang.
    end = time.monotonic() + 600
    while True:
        result = original(*args, **kwargs)
        if time.monotonic() > end:
            return result
setattr(module, name, started)
from designkit.cli import main
sys.exit(main(sys.argv[4:]))
"""

# command line, the computation the flag wraps, seconds of work before Ctrl-C (a negative
# number: the wrapped step holds that long before it starts, Ctrl-C comes within it). The
# wrapped step is one that leaves its output staged (repeating it must not publish anything):
# for cad the writing of the parts into the staging folder, not the whole export.
CASES = {
    "report": (["report", "--quick", "--out", "rep"], "designkit.commands.report._run", 3.0),
    "optimize": (["optimize", "--out", "opt"], "designkit.commands.optimize.solve_device", 2.0),
    "map": (["map", "--out", "map.npz"], "designkit.fieldmap.build", 3.0),
    "scene": (["scene", "compile", "wedge", "--out", "scene.npz"],
              "designkit.render.force_constant", 2.0),
    "viz": (["viz", "fieldlines", "--vtk", "vtk", "--out", "f.png"],
            "designkit.viz.export_vtk", 2.0),
    "fem": (["fem", "--level", "1", "--out", "fem"], "designkit.commands.fem.solve", 4.0),
    "cad": (["cad", "--out", "cad"], "cad.export._write_parts", 4.0),
    "run": (["run", "--simulate", "--out", "run"], "designkit.commands.run.run_simulation", 3.0),
    # the figure is written into the staging folder, after sensors.toml and plan.json
    "sensors": (["sensors", "plan", "--heights", "30:60", "--lattice", "30", "--spacing", "25",
                 "--max-current", "2", "--count", "8", "--out", "sp"],
                "designkit.commands.sensors.bound_figure", 2.0),
    # the shipped optimized design: no rule every row breaks (the thesis' 36 V supply is one,
    # and the sweep says so on stderr before it starts)
    "sweep": (["sweep", "--param", "inner_radius_m=0.006:0.01:3", "--design", "optimized",
               "--workers", "1", "--out", "sw"], "designkit.commands.sweep.plot", -60.0),
}


def _as_from_a_terminal() -> None:
    """SIGINT at its default, as a shell leaves it for a program run in the foreground: a test
    run started in the background (``cmd &`` without job control) ignores SIGINT, and Python
    then installs no KeyboardInterrupt handler, so Ctrl-C could not be tested at all."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


FAST = ("map", "scene", "sweep")
"""In the default suite; the others take tens of seconds each (slow)."""


@pytest.mark.parametrize("command", [c if c in FAST else pytest.param(c, marks=pytest.mark.slow)
                                     for c in sorted(CASES)])
def test_ctrl_c_is_one_line_exit_130_and_leaves_nothing(tmp_path, command):
    args, target, work_s = CASES[command]
    if command == "fem" and shutil.which("getdp") is None:
        pytest.skip("needs getdp")
    work = tmp_path / "work"
    work.mkdir()
    flag = tmp_path / "started"
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYVISTA_OFF_SCREEN="true", MPLBACKEND="Agg")
    hold = max(-work_s, 0.0)
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, target, str(flag), str(hold), *args,
                             *(["--no-progress"] if command not in ("viz", "fem") else [])],
                            cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_as_from_a_terminal)
    try:
        deadline = time.monotonic() + 600
        while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert flag.exists(), "the work never started"
        time.sleep(max(work_s, 1.0))
        assert proc.poll() is None, f"the work ended before Ctrl-C: {proc.communicate()[1][-2000:]}"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert proc.returncode == 130, err[-3000:]
    assert lines == [f"designkit {command}: interrupted; nothing written"], err[-3000:]
    assert sorted(p.name for p in work.rglob("*")) == []



FORK_DRIVER = """
import multiprocessing, os, signal, sys, time
from designkit.support.parallel import quiet_pool
armed = []
os.register_at_fork(after_in_parent=lambda: armed and os.kill(os.getpid(), signal.SIGINT))
import threading
first = quiet_pool(1, "fork")
# a thread that can take the signal (BLAS's and the progress bar's threads do in a map build)
threading.Thread(target=time.sleep, args=(60,), daemon=True).start()
armed.append(True)
try:
    pool = quiet_pool(2, "fork")
except KeyboardInterrupt:
    armed.clear()
    first.terminate()
    deadline = time.monotonic() + 10
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.05)
    print("interrupted", len(multiprocessing.active_children()))
    sys.exit(0)
armed.clear()
pool.terminate()
first.terminate()
print("lost")
"""


def test_a_ctrl_c_that_lands_while_a_pool_forks_is_not_lost():
    """A SIGINT delivered inside the fork's at-fork hooks (where logging's lock hook swallows
    the KeyboardInterrupt: a map build under load worked on after Ctrl-C) is held until the
    pool exists, then raised, and the pool's workers are gone (a fresh interpreter's main
    thread, as the command runs)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", FORK_DRIVER], env=env, capture_output=True,
                         text=True, timeout=120, preexec_fn=_as_from_a_terminal)
    assert out.stdout.split() == ["interrupted", "0"], out.stdout + out.stderr[-2000:]
