"""``designkit sweep`` as a user meets it on a big job: the plan and the bar at once, chunks
that start at one design, Ctrl-C that stops every worker at once, units refused or converted.

The Ctrl-C test replaces the per-chunk work by a chunk that would take ten minutes: the
command must end on the signal (exit 130, one line, nothing written, no worker left), not
when the chunks in flight finish. Nothing here depends on the machine's speed: the waits are
hang guards, not timings.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from designkit.cli import main
from designkit.commands.common import parse_length, parse_lengths
from designkit.errors import BadInputError
from designkit.optimize.sweep import Grid, grid, parse_param
from designkit.support.parallel import run_chunks

ROOT = Path(__file__).resolve().parents[1]
WITHIN_RATING = "[drive]\nsupply_voltage_v = 30.0\n"
"""The thesis design with its supply at the driver's rating (no rule every row breaks)."""

DRIVER = """
import os, pathlib, sys, time
import designkit.optimize.sweep as sw
flags = pathlib.Path(sys.argv[1])
def slow_chunk(*args, **kwargs):
    (flags / f"worker-{os.getpid()}").write_text("started")
    time.sleep(600)  # a chunk of ten minutes: Ctrl-C must not wait for it
sw.evaluate_chunk = slow_chunk
from designkit.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie has ended)."""
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state


@pytest.mark.parametrize("to", ["group", "main"])
def test_ctrl_c_stops_a_sweep_with_workers_at_once(tmp_path, to):
    # 'group': Ctrl-C at a terminal (every process of the job gets SIGINT); 'main': `timeout
    # -s INT` or `kill -INT` (only the command gets it: it must stop the workers itself)
    work, flags = tmp_path / "work", tmp_path / "flags"
    work.mkdir()
    flags.mkdir()
    design = tmp_path / "d.toml"
    design.write_text(WITHIN_RATING)
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    args = ["sweep", "--param", "inner_radius_m=0.006:0.01:40", "--design", str(design),
            "--workers", "2", "--out", "sw", "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, str(flags), *args], cwd=work,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 300  # a hang guard
        while len(list(flags.iterdir())) < 2 and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = [int(p.name.split("-")[1]) for p in flags.iterdir()]
        assert len(workers) == 2, proc.communicate()[1][-2000:] if proc.poll() is not None else ""
        assert proc.poll() is None
        if to == "group":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert proc.returncode == 130, err[-3000:]
    assert lines == ["designkit sweep: interrupted; nothing written"], err[-3000:]
    assert sorted(p.name for p in work.rglob("*")) == []
    end = time.monotonic() + 30  # SIGTERM'd workers are reaped by the pool; a guard only
    while any(_alive(pid) for pid in workers) and time.monotonic() < end:
        time.sleep(0.05)
    assert not [pid for pid in workers if _alive(pid)]


class _Stop(Exception):
    pass


def test_a_million_design_sweep_shows_its_plan_and_bar_before_the_first_design(
        tmp_path, monkeypatch, capsys):
    import designkit.optimize.sweep as sw

    sizes = []

    def first_chunk(problem, base, names, values):
        sizes.append(len(values))
        seen = capsys.readouterr()
        assert "planned: 1000000 designs (100 inner_radius_m x 100 length_m x 100 " \
               "outer_radius_m)" in seen.out
        assert "0/1000000" in seen.err  # the bar with its total, before any design
        raise _Stop

    monkeypatch.setattr(sw, "evaluate_chunk", first_chunk)
    design = tmp_path / "d.toml"
    design.write_text(WITHIN_RATING)
    with pytest.raises(_Stop):
        main(["sweep", "--param", "inner_radius_m=0.005:0.012:100", "--param",
              "length_m=0.02:0.1:100", "--param", "outer_radius_m=0.015:0.024:100",
              "--design", str(design), "--workers", "1", "--out", str(tmp_path / "sw")])
    assert sizes == [1]  # the first progress comes after one design, not one chunk of 250
    assert not (tmp_path / "sw").exists()


def rows_of(tag, rows):
    """A chunk function for :func:`run_chunks` (module level: the workers import it)."""
    return [(tag, *map(float, r)) for r in rows]


@pytest.mark.parametrize("workers", [1, 2])
def test_chunks_start_at_one_row_and_cover_every_row_once_in_order(workers):
    g = Grid.of([parse_param("inner_radius_m=0.005:0.01:7"), parse_param("length_m=0.02:0.1:5"),
                 parse_param("current_a=1:6:3")])
    run = run_chunks(rows_of, ("t",), g, workers=workers, progress=None, max_chunk=4)
    got = [r for ch in run.results for r in ch]
    _, whole = grid(g.ranges)
    assert got == [("t", *map(float, r)) for r in whole]
    assert len(run.results[0]) == 1 and max(len(ch) for ch in run.results) <= 4
    assert run.backend == ("serial" if workers == 1 else "processes")


def test_a_rule_the_sweep_cannot_fix_is_named_at_once_and_one_it_varies_is_not(
        tmp_path, monkeypatch, capsys):
    import designkit.optimize.sweep as sw

    def stop(*a, **k):
        raise _Stop

    monkeypatch.setattr(sw, "evaluate_chunk", stop)
    bad = tmp_path / "d.toml"
    # the magnet cannot reach 15 mm above the coil tops: optimize.height_m fixes it
    bad.write_text("[optimize]\nheight_m = 0.015\n[drive]\nsupply_voltage_v = 30.0\n")
    for params, named in ((["length_m=0.02:0.1:3"], True), (["height_m=0.03:0.05:3"], False)):
        with pytest.raises(_Stop):
            main(["sweep", *[a for p in params for a in ("--param", p)], "--design", str(bad),
                  "--workers", "1", "--no-progress", "--out", str(tmp_path / "sw")])
        err = capsys.readouterr().err
        assert ("rule magnet_at_design_height" in err) is named, err
        if named:
            assert "optimize.height_m, sensors.offset_m are not varied" in err


@pytest.mark.parametrize("text,bare,metres", [
    ("10", "mm", 0.010), ("10mm", "mm", 0.010), ("1cm", "mm", 0.010), ("0.01m", "mm", 0.010),
    ("0.01", "m", 0.010), ("10mm", "m", 0.010), ("500um", "mm", 5e-4), (" 2.5e1 MM", "mm", 0.025),
])
def test_a_length_on_the_command_line(text, bare, metres):
    assert parse_length(text, "--x", valid_m=(1e-4, 1.0), bare=bare) == pytest.approx(metres)


@pytest.mark.parametrize("text,bare,says", [
    ("0.04", "mm", "Metres where mm are expected? Write 0.04m"),
    ("40", "m", "Millimetres where m are expected? Write 40mm or 0.04"),
    ("40 furlongs", "mm", "a length in [0.1, 1000] mm"),
    ("nan", "mm", "a length in"),
    ("-5", "mm", "a length in"),
])
def test_a_wrong_length_is_one_line_naming_the_option_range_and_unit(text, bare, says):
    with pytest.raises(BadInputError) as exc:
        parse_length(text, "--spacing", valid_m=(1e-4, 1.0), bare=bare)
    msg = str(exc.value)
    assert "--spacing" in msg and says in msg and "\n" not in msg


def test_lists_of_lengths():
    assert parse_lengths("40mm:6cm", "--pitch-range", 2, sep=":", valid_m=(1e-3, 1.0)) \
        == pytest.approx((0.04, 0.06))
    with pytest.raises(BadInputError, match="2 lengths separated by ':'"):
        parse_lengths("40", "--pitch-range", 2, sep=":", valid_m=(1e-3, 1.0))
