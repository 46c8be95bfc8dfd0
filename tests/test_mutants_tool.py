"""tools/mutants.py: the curated list is well formed and covers every area; a snippet that does
not match is reported, not applied; a dirty work tree is refused before anything runs."""

import importlib.util
import sys

from conftest import ROOT

_spec = importlib.util.spec_from_file_location("tools_mutants", ROOT / "tools" / "mutants.py")
mutants = importlib.util.module_from_spec(_spec)
sys.modules["tools_mutants"] = mutants  # dataclasses look their module up
_spec.loader.exec_module(mutants)

AREAS = {"field", "cores", "coupling", "map", "allocation", "localization", "runner", "optimizer",
         "simulator"}


def test_the_list_covers_every_area_with_existing_killers():
    ms = mutants.load_mutants(mutants.DEFAULT_LIST)
    assert len(ms) >= 30 and {m.area for m in ms} == AREAS
    for m in ms:
        assert m.find != m.replace and m.killers, m.name
        assert all((ROOT / k).is_file() for k in m.killers), m.name
        assert (ROOT / m.file).is_file(), m.name


def test_every_snippet_applies_once_to_the_current_tree():
    # a refactor that moves a mutated line retires its mutant silently; this names it at once
    stale = [f"{m.name}: found {(ROOT / m.file).read_text().count(m.find)} times in {m.file}"
             for m in mutants.load_mutants(mutants.DEFAULT_LIST)
             if (ROOT / m.file).read_text().count(m.find) != 1]
    assert stale == []


def test_a_snippet_that_does_not_match_is_reported_and_nothing_is_written(tmp_path):
    f = tmp_path / "pkg" / "mod.py"
    f.parent.mkdir()
    f.write_text("x = 1\nx = 1\n")
    twice = mutants.Mutant("twice", "field", "pkg/mod.py", "x = 1", "x = 2", ("t.py",))
    absent = mutants.Mutant("absent", "field", "pkg/mod.py", "y = 1", "y = 2", ("t.py",))
    for m in (twice, absent):
        r = mutants.check_mutant(tmp_path, m, full=False, timeout_s=10.0)
        assert r["status"] == "does not apply" and "needs exactly 1" in r["by"]
    assert f.read_text() == "x = 1\nx = 1\n"


def test_a_dirty_tree_is_refused(monkeypatch, capsys):
    monkeypatch.setattr(mutants, "git", lambda *a, **k: " M designkit/model/array.py\n")
    monkeypatch.setattr(mutants, "export_head", lambda dest: (_ for _ in ()).throw(
        AssertionError("exported a dirty tree")))
    assert mutants.main(["--only", "runner-f0-added"]) == 2
    assert "uncommitted changes" in capsys.readouterr().err
