"""The runner's hold on Python's cyclic garbage collector while the control loop runs.

A collection pass stops the interpreter for as long as it takes to walk every object of the
generations it collects: a young (generation 0) pass walks the objects made since the last
one, a middle (generation 1) pass also every survivor of the recent young passes, a full pass
everything. Left to the interpreter, the middle and full passes land in whichever step
allocates the object that crosses a threshold, and a control step cannot afford them
(docs/runner.md, "The garbage collector"). So, for the loop:

- at start-up, one full collection, and the survivors (the map, the scene, the estimator)
  frozen (``gc.freeze``): no later pass walks them;
- automatic collection off;
- :meth:`LoopCollector.young` at the end of each step, after the coils were written (the
  command is out; what is left of the period is slack): once generation 0 holds the
  interpreter's own threshold of new objects, one young pass (it frees the reference cycles
  made since the last one) and its survivors frozen too. Middle and full passes never run in
  the loop: what survives a young pass is held until :meth:`LoopCollector.release`. The step
  itself makes no reference cycles (tests/test_runner_collector.py), so what is held is what
  the loop keeps anyway, plus any cycle a caller makes and still references at a young pass;
- at stop (also after an exception or Ctrl-C: ``Runner.stop`` in a ``finally``), the
  collector's state as it was before start-up: unfrozen and enabled if it was (what the loop
  held is left to the collector's own passes: a full pass at stop would only delay the caller).

Numpy arrays are not tracked by the collector: they cost nothing here.
"""

from __future__ import annotations

import gc


class LoopCollector:
    """Take (:meth:`take`), use (:meth:`young`) and give back (:meth:`release`) the garbage
    collector for a control loop (module docstring)."""

    def __init__(self):
        self.held = False
        self.was_enabled = gc.isenabled()
        self.young_objects = max(1, gc.get_threshold()[0])

    def take(self) -> None:
        """Collect fully, freeze the survivors and switch automatic collection off; a second
        call while held only collects and freezes again."""
        if not self.held:
            self.was_enabled = gc.isenabled()
            self.young_objects = max(1, gc.get_threshold()[0])
        gc.collect()
        gc.freeze()
        gc.disable()
        self.held = True

    def young(self) -> bool:
        """One young pass and its survivors frozen once generation 0 holds
        ``young_objects`` new objects (the interpreter's own threshold); True if it ran.
        Nothing while the collector is not held."""
        if not self.held or gc.get_count()[0] < self.young_objects:
            return False
        gc.collect(0)
        gc.freeze()
        return True

    def release(self) -> None:
        """The collector as it was before :meth:`take`: unfrozen, automatic collection on if
        it was. Safe to call more than once."""
        if not self.held:
            return
        self.held = False
        gc.unfreeze()
        if self.was_enabled:
            gc.enable()
