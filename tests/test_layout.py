"""The library and the studies keep the house rules of their layout (tests/layout.py measures
them): modules of one concept (<= 700 lines), functions in named phases (<= 100 lines), short
module docstrings without run logs, imports at the top except heavy optional ones, and no import
cycle."""

import re

import pytest

import layout


@pytest.fixture(scope="module")
def found():
    return layout.report()


@pytest.mark.parametrize("rule", ["module lines", "function lines", "docstring lines",
                                  "stale docstring", "lazy import", "cycle"])
def test_layout_rule(found, rule):
    assert found[rule] == [], f"{rule}: " + "; ".join(found[rule])


def test_the_checker_sees_a_cycle_and_a_long_function():
    # the checker itself: a planted cycle and a planted long function are found
    assert layout.cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert layout.cycles({"a": {"b"}, "b": set()}) == []
    src = "def f():\n" + "    x = 1\n" * (layout.MAX_FUNCTION_LINES + 1)
    import ast
    fn = ast.parse(src).body[0]
    assert fn.end_lineno - fn.lineno + 1 > layout.MAX_FUNCTION_LINES


def test_the_checker_covers_the_studies_and_knows_heavy_modules():
    # the default report reads studies/ too, and one study file is found in it
    assert "studies" in layout.CHECKED
    assert layout.ROOT / "studies" / "bench_field.py" in layout.modules(layout.CHECKED)
    # a module importing a heavy optional dependency at its top is heavy, and so is one that
    # imports it; a light one is not
    eager = {"a": {"pyvista", "numpy"}, "b": {"a", "numpy"}, "c": {"numpy"}}
    assert layout.heavy(eager) == {"a", "b"}


def test_the_readme_module_table_names_every_module_of_a_package_it_lists():
    # a row of README.md's module table for one package that names its modules (`name`)
    # names all of them (private ones aside): a new module is not left out of the map
    rows = 0
    for line in (layout.ROOT / "README.md").read_text().splitlines():
        m = re.match(r"\| `([a-z_/]+)/` \| (.*) \|$", line)
        if not m:
            continue
        named = set(re.findall(r"`([a-z_0-9]+)/?`", m.group(2)))
        if not named:
            continue
        pkg = layout.ROOT / m.group(1)
        have = {p.stem for p in pkg.glob("*.py") if not p.stem.startswith("_")}
        have |= {p.name for p in pkg.iterdir() if (p / "__init__.py").is_file()}
        assert have <= named, f"README row {m.group(1)}/ leaves out {sorted(have - named)}"
        rows += 1
    assert rows >= 10
