"""What the Rerun recording holds and how it is shown: signal sets, channels with units, the blueprint.

Every signal is a float32 component (7 digits: the encoders, torques and sensors at their resolution) of one
entity, :data:`ENTITY`, so that a tick costs one row (one time stamp, one row id) for everything; each plot maps
one component to the ``SeriesLines`` visualizer's ``Scalars:scalars`` input and names its series. Components,
``<group>:<name>``:

- per joint, its instances the group's signals: ``tracking:<joint>`` (q_ref, q, q_des [rad]), ``torque:<joint>``
  (tau_d, tau_est, tau_true [N m]; tau_true NaN, no line, when the backend has no ground truth),
  ``command:<joint>`` (the command's components [rad], control/terms.py: ff_torque, fb_position, ...; their sum
  is dq_err = q_des - q)
- per sensor quantity, its instances the axes: ``imu:gyro`` (gyro_x, gyro_y, gyro_z [rad/s]), ``imu:acc``
  (acc_x, acc_y, acc_z [m/s^2]), ``ft:<sensor>_force`` (fx, fy, fz [N]), ``ft:<sensor>_torque`` (tx, ty, tz
  [N m]): the Parquet log's axis names
- set ``all`` adds ``error:<joint>`` (e_q [rad]), ``velocity:<joint>`` (de_q, dq_est [rad/s]),
  ``acceleration:<joint>`` (dde_q [rad/s^2]), tau_star and e_tau in ``torque``, and the force task's
  ``task:f_d|f_hat|e_f`` (fx..tz [N, N m])

Other entities: ``safety/mode`` (0 position, 1 torque, 2 hold; logged when it changes), ``safety/events`` (text),
``robot/...`` (the transform tree, servotau/apps/viewer_robot.py).

Signal sets (``--rerun-signals``): ``minimal`` (tracking, tau_est, safety), ``control`` (every signal the
controller uses: adds tau_d, tau_true, the command's components, IMU and F/T; the default), ``all`` (adds the
controller's internal errors and the force task's wrenches).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from servotau.control.terms import COMPONENTS

ENTITY = "signals"
MODES = ("position", "torque", "hold")  # safety/mode codes 0, 1, 2
SIGNAL_SETS = ("minimal", "control", "all")
WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


@dataclass(frozen=True)
class Channel:
    """Where one signal goes. A joint signal (``names`` None) is instance ``field`` of the components
    ``<entity>:<joint>``; a sensor signal is component ``<entity>:<field>`` with instances ``names``."""

    entity: str
    field: str
    unit: str
    names: tuple[str, ...] | None = None

    @property
    def component(self) -> str:
        return f"{self.entity}:{self.field}"

    @property
    def per_joint(self) -> bool:
        return self.names is None


def _joint(entity: str, unit: str, *fields: str) -> dict[str, Channel]:
    return {f: Channel(entity, f, unit) for f in fields}


TRACKING = _joint("tracking", "rad", "q_ref", "q", "q_des")
TORQUE = _joint("torque", "N m", "tau_d", "tau_est", "tau_true")
COMMAND = _joint("command", "rad", *COMPONENTS)  # their sum dq_err = q_des - q: both in tracking
INTERNAL = {**_joint("torque", "N m", "tau_star", "e_tau"), **_joint("error", "rad", "e_q"),
            **_joint("velocity", "rad/s", "de_q", "dq_est"), **_joint("acceleration", "rad/s^2", "dde_q")}
IMU = {"imu/gyro": Channel("imu", "gyro", "rad/s", ("gyro_x", "gyro_y", "gyro_z")),
       "imu/acc": Channel("imu", "acc", "m/s^2", ("acc_x", "acc_y", "acc_z"))}
TASK = {f"task/{n}": Channel("task", n, "N, N m", WRENCH_AXES) for n in ("f_d", "f_hat", "e_f")}


def ft_channels(sensors: Sequence[str]) -> dict[str, Channel]:
    """F/T channels of ``sensors``: ``ft/<sensor>/force`` [N] and ``ft/<sensor>/torque`` [N m]."""
    out = {}
    for s in sensors:
        out[f"ft/{s}/force"] = Channel("ft", f"{s}_force", "N", WRENCH_AXES[:3])
        out[f"ft/{s}/torque"] = Channel("ft", f"{s}_torque", "N m", WRENCH_AXES[3:])
    return out


def channels(signal_set: str, ft_sensors: Sequence[str]) -> dict[str, Channel]:
    """Signal name -> channel for ``signal_set`` (one of :data:`SIGNAL_SETS`)."""
    from servotau.errors import ConfigError

    if signal_set not in SIGNAL_SETS:
        raise ConfigError(f"rerun signal set {signal_set!r}: expected one of {', '.join(SIGNAL_SETS)}")
    if signal_set == "minimal":
        return {**TRACKING, "tau_est": TORQUE["tau_est"]}
    out = {**TRACKING, **TORQUE, **COMMAND, **IMU, **ft_channels(ft_sensors)}
    if signal_set == "all":
        out.update(INTERNAL)
        out.update(TASK)
    return out


def joint_groups(chans: dict[str, Channel]) -> dict[str, list[Channel]]:
    """Joint group (tracking, torque, ...) -> its signals in instance order."""
    out: dict[str, list[Channel]] = {}
    for c in chans.values():
        if c.per_joint:
            out.setdefault(c.entity, []).append(c)
    return out


def series_names(chs: Sequence[Channel]) -> list[str]:
    """Legend names: per instance ``<signal> [unit]`` (a joint group) or ``<axis> [unit]`` (a sensor channel)."""
    if len(chs) == 1 and not chs[0].per_joint:
        return [f"{n} [{chs[0].unit}]" for n in chs[0].names]
    return [f"{c.field} [{c.unit}]" for c in chs]


def blueprint(chans: dict[str, Channel], plot_joints: Sequence[str]):
    """The default layout: a tab per question (tracking, torque, command, sensors, safety) beside the 3D robot;
    a plot per joint of ``plot_joints`` in the joint tabs."""
    import rerun as rr
    import rerun.blueprint as rrb
    from rerun.blueprint.encodings import ComponentSourceKind, VisualizerComponentMapping

    def line(component: str, names: list[str]):
        mapping = VisualizerComponentMapping(target="Scalars:scalars", source_kind=ComponentSourceKind.SourceComponent,
                                             source_component=component)
        return rr.SeriesLines(names=names).visualizer(mappings=[mapping])

    def plot(name: str, lines: list):
        return rrb.TimeSeriesView(name=name, origin=ENTITY, overrides={ENTITY: lines})

    tabs = []
    for group, chs in joint_groups(chans).items():
        units = ", ".join(dict.fromkeys(c.unit for c in chs))
        tabs.append(rrb.Grid(*[plot(f"{j} {group} [{units}]", [line(f"{group}:{j}", series_names(chs))])
                               for j in plot_joints], name=group))
    sensors = [plot(f"IMU {c.field} [{c.unit}]", [line(c.component, series_names([c]))])
               for c in chans.values() if c.entity == "imu"]
    for quantity, unit in (("force", "N"), ("torque", "N m")):  # the F/T sensors: one plot per quantity
        fts = [c for c in chans.values() if c.entity == "ft" and c.field.endswith(quantity)]
        if fts:
            sensors.append(plot(f"F/T {quantity} [{unit}]", [line(c.component, [
                f"{c.field.removesuffix('_' + quantity)} {n} [{unit}]" for n in c.names]) for c in fts]))
    if sensors:
        tabs.append(rrb.Grid(*sensors, name="sensors"))
    task = [plot(f"force task {c.field} [{c.unit}]", [line(c.component, series_names([c]))])
            for c in chans.values() if c.entity == "task"]
    if task:
        tabs.append(rrb.Grid(*task, name="force task"))
    tabs.append(rrb.Vertical(rrb.TimeSeriesView(name="safety mode (0 position, 1 torque, 2 hold)",
                                                origin="safety/mode"),
                             rrb.TextLogView(name="safety events", origin="safety/events"), name="safety"))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(name="robot", origin="robot"), rrb.Tabs(*tabs), column_shares=[1, 2]),
        collapse_panels=True,
    )
