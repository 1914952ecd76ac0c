"""Controller-side backends, one module each: :mod:`.zenoh` (a robot process over Zenoh), :mod:`.inprocess`
(a served robot in the controller's process), :mod:`.replay` (a recorded log).

Each module has ``from_config(hal, *, port=None)``, which reads its own sub-table of ``[hal]`` and opens
the backend; :mod:`servotau.hal.registry` finds it by name. Adding a backend is adding a module here
and one ``register(...)`` line there.
"""
