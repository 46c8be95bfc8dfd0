"""Mutation check: does the default test suite kill each curated physics mutant?

Each mutant in ``tools/mutants.toml`` is a small, named, plausible error: a file, an exact
snippet of it and its replacement, and the test files expected to kill it. The script refuses
a checkout with uncommitted changes, exports the committed tree (``git archive HEAD``) to a
temporary folder, and for each mutant: applies it there (a snippet found zero or several times
is reported as 'does not apply'), runs the mutant's killer files with ``pytest -x`` (the
default markers: slow tests excluded), optionally the whole default suite when those pass, and
restores the file. The checkout it runs from is never written. A baseline run first checks
that the killer files pass unmutated (a mutant 'killed' by a failing suite proves nothing).

Output: a table mutant -> status (killed / SURVIVED / does not apply) -> the first failing
test; exit status 0 when every applied mutant is killed, 1 otherwise, 2 on bad input.
Usage: ``python tools/mutants.py [--only NAME,...] [--full] [--list FILE] [--timeout S]``.
Reference: DeMillo, Lipton, Sayward, "Hints on test data selection", Computer 11(4), 1978.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_LIST = ROOT / "tools" / "mutants.toml"


@dataclass(frozen=True)
class Mutant:
    """One planted error: ``find`` (exact text, once in ``file``) -> ``replace``."""

    name: str
    area: str
    file: str
    find: str
    replace: str
    killers: tuple
    why: str = ""


def load_mutants(path: Path) -> list[Mutant]:
    """The curated list (TOML ``[[mutant]]`` tables); duplicate names are an error."""
    data = tomllib.loads(Path(path).read_text())
    out = [Mutant(m["name"], m["area"], m["file"], m["find"], m["replace"],
                  tuple(m["killers"]), m.get("why", "")) for m in data["mutant"]]
    names = [m.name for m in out]
    if len(set(names)) != len(names):
        raise SystemExit(f"error: duplicate mutant names in {path}")
    return out


def git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout


def export_head(dest: Path) -> None:
    """The committed tree of the checkout (HEAD), written under ``dest``."""
    archive = subprocess.run(["git", "archive", "--format=tar", "HEAD"], cwd=ROOT, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)


def run_pytest(copy: Path, targets: list[str], timeout_s: float) -> tuple[bool, str, float]:
    """(passed, first failing test or a short reason, seconds) of pytest -x on ``targets``."""
    env = dict(os.environ, PYTHONPATH=str(copy), PYTHONDONTWRITEBYTECODE="1")
    env.pop("DESIGNKIT_CI", None)  # a skipped FEM test is a skip here, not a kill
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-rf",
           *targets]
    t0 = time.perf_counter()
    try:
        res = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True,
                             timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return False, f"timeout after {timeout_s:.0f} s", time.perf_counter() - t0
    dt = time.perf_counter() - t0
    if res.returncode == 0:
        return True, "", dt
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", res.stdout, flags=re.M)
    if failed:
        return False, failed[0], dt
    tail = (res.stdout + res.stderr).strip().splitlines()[-1:] or ["?"]
    return False, f"pytest exit {res.returncode}: {tail[0][:80]}", dt


def check_mutant(copy: Path, m: Mutant, full: bool, timeout_s: float) -> dict:
    """Apply ``m`` in ``copy``, run its killers (then the default suite if ``full``), restore."""
    target = copy / m.file
    if not target.is_file():
        return {"status": "does not apply", "by": f"no file {m.file}", "s": 0.0}
    original = target.read_text()
    n = original.count(m.find)
    if n != 1:
        return {"status": "does not apply",
                "by": f"snippet found {n} times in {m.file} (needs exactly 1)", "s": 0.0}
    target.write_text(original.replace(m.find, m.replace))
    try:
        passed, by, dt = run_pytest(copy, list(m.killers), timeout_s)
        if passed and full:
            passed, by, dt2 = run_pytest(copy, ["tests"], timeout_s * 4)
            dt += dt2
    finally:
        target.write_text(original)
    return {"status": "SURVIVED" if passed else "killed", "by": by, "s": dt}


def print_table(mutants: list[Mutant], results: dict) -> None:
    w = max(len(m.name) for m in mutants)
    print(f"| {'mutant':{w}} | area | status | killed by | s |")
    print(f"| {'-' * w} | --- | --- | --- | --- |")
    for m in mutants:
        r = results[m.name]
        print(f"| {m.name:{w}} | {m.area} | {r['status']} | {r['by']} | {r['s']:.0f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Apply each curated mutant to a temporary copy "
                                 "of the committed tree and run the tests that should kill it.")
    ap.add_argument("--list", type=Path, default=DEFAULT_LIST, help="mutant list (TOML)")
    ap.add_argument("--only", default=None, help="comma-separated mutant names")
    ap.add_argument("--full", action="store_true",
                    help="when a mutant's killer files pass, run the whole default suite too")
    ap.add_argument("--timeout", type=float, default=900.0,
                    help="seconds allowed per pytest run of the killer files (default 900)")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the unmutated run of the killer files")
    a = ap.parse_args(argv)
    if not a.list.is_file():
        print(f"error: --list {a.list} is not a file", file=sys.stderr)
        return 2
    if a.timeout <= 0:
        print(f"error: --timeout must be > 0 s; instead received {a.timeout}", file=sys.stderr)
        return 2
    mutants = load_mutants(a.list)
    if a.only:
        wanted = a.only.split(",")
        unknown = sorted(set(wanted) - {m.name for m in mutants})
        if unknown:
            print(f"error: --only names unknown mutants {unknown}", file=sys.stderr)
            return 2
        mutants = [m for m in mutants if m.name in wanted]
    dirty = git("status", "--porcelain", "--untracked-files=normal").strip()
    if dirty:
        print("error: the work tree has uncommitted changes (commit or stash them: the "
              "mutants run on the committed tree):\n" + dirty, file=sys.stderr)
        return 2
    head = git("rev-parse", "--short", "HEAD").strip()
    with tempfile.TemporaryDirectory(prefix="designkit-mutants-") as tmp:
        copy = Path(tmp)
        export_head(copy)
        print(f"mutants of {head} in {copy} ({len(mutants)} mutants)", flush=True)
        if not a.no_baseline:
            files = sorted({k for m in mutants for k in m.killers})
            ok, by, dt = run_pytest(copy, files, a.timeout * 2)
            print(f"baseline (unmutated killer files): {'pass' if ok else 'FAIL ' + by} "
                  f"({dt:.0f} s)", flush=True)
            if not ok:
                print("error: the killer files fail without a mutant; fix them first",
                      file=sys.stderr)
                return 1
        results = {}
        for m in mutants:
            results[m.name] = check_mutant(copy, m, a.full, a.timeout)
            r = results[m.name]
            print(f"  {m.name}: {r['status']} {r['by']} ({r['s']:.0f} s)", flush=True)
    print_table(mutants, results)
    survived = [k for k, r in results.items() if r["status"] != "killed"]
    print(f"{len(results) - len(survived)} of {len(results)} killed" +
          (f"; not killed: {', '.join(survived)}" if survived else ""))
    return 1 if survived else 0


if __name__ == "__main__":
    raise SystemExit(main())
