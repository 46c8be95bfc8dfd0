"""Sensor layouts as estimation problems: the Cramer-Rao bound of finger-magnet poses from a
Hall-sensor layout (:mod:`.crb`, with the readings' Jacobians of :mod:`.response`), the sets
of poses it is evaluated over (:mod:`.region`), where a board can carry a sensor (:mod:`.sites`),
the planner that places sensors to minimize the worst bound (:mod:`.planner`), the bound maps of
a layout (:mod:`.maps`) and their figure (:mod:`.figure`). docs/sensors.md.
"""
