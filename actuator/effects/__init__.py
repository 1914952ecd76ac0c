"""The built-in effects of the actuator model, one file per effect (found by :mod:`servotau.actuator.registry`).

Each effect adds ``c * phi`` [rad] to ``dq_err = q_des - q``. Torques in the servo enter ``dq_err`` divided by
the position gain, so a friction torque ``f`` appears as ``k_tau f``: the coefficients are in [rad] per unit of
``phi``. ``u = k_tau tau + k_v dq`` is the linear part of the model the effect is added to (``u_tau``, ``u_v``
its two parts). ``s(x, v) = tanh(x / v)`` is a sign smoothed over ``v`` (``v = 0``: plain sign).

Adding an effect is adding one file ``<name>.py`` here (and its test ``tests/test_actuator_effects_<name>.py``)
that holds everything about it::

    \"\"\"``<name>``: one line of physics. ``phi = ...``; on-line: the signals it reads.\"\"\"

    ORDER = 150                       # place in the library (rankings keep it on ties); distinct
    GRID = ({"shape_param": 0.1}, ...)  # shapes the diagnosis tries (or a function of the Signals)

    def <name>(s: Signals, shape_param: float) -> np.ndarray: ...   # batch regressor phi
    def scalar(x, shape_param) -> float: ...           # phi on one sample (no memory), or
    class <Name>Online: ...                            # on-line state: value(sample), commit(sample)
    def needs(e: Excitation) -> str | None: ...        # why the data cannot test it (the excitation it needs)

    EFFECT = Effect("<name>", <name>, GRID, signals=(...), signature=..., family=..., description=...,
                    needs=needs, scalar=scalar or online=<Name>Online, history=..., online_signals="...",
                    coefficient_range=None or (low, high), confusable=(...),
                    experiments={"<look-alike>": "the experiment that tells them apart"})

Shared helpers (smoothed sign, the command's lead, the acceleration, on-line lags) are in
:mod:`servotau.actuator.signals`; shared excitation requirements in :mod:`servotau.actuator.excitation`.
"""
