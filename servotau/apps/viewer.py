"""Stream robot signals and the 3D robot to Rerun.

Targets (``--rerun``): ``save:FILE`` (a .rrd file), ``connect:ADDR`` (a running viewer, possibly on
another host, e.g. ``connect:rerun+http://127.0.0.1:9876/proxy``), ``spawn`` (start a local viewer),
``off``. Scalars are buffered and sent in columns (one ``rr.log`` per scalar per tick would cost
about 1 ms for 12 scalars) from a background thread, so that the control loop never waits for
Rerun (a flush of 30 joints x 15 signals takes tens of ms, longer than the robot's command
watchdog); the 3D robot is sent at ``robot_hz``.

Entity layout: ``joints/<joint>/<signal>`` (q, q_des, dq_err, tau_est, tau_true, ...),
``imu/gyro``, ``imu/acc``, ``ft/<sensor>/force``, ``ft/<sensor>/torque``, ``robot/...`` (3D).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Sequence

import mujoco
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from servotau.errors import ConfigError

TIMELINE = "sim_time"


def _blueprint(joints: Sequence[str]) -> rrb.Blueprint:
    plots = [rrb.TimeSeriesView(name=j, origin=f"joints/{j}") for j in joints]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.Spatial3DView(name="robot", origin="robot"),
                         rrb.TimeSeriesView(name="F/T", origin="ft"), rrb.TimeSeriesView(name="IMU", origin="imu")),
            rrb.Grid(*plots),
            column_shares=[1, 2],
        ),
        collapse_panels=True,
    )


def open_recording(target: str, app_id: str = "servotau") -> rr.RecordingStream | None:
    """A recording stream for ``target`` (see module doc); None for ``off``."""
    kind, _, arg = target.partition(":")
    if kind == "off":
        return None
    rec = rr.RecordingStream(app_id)
    if kind == "save" and arg:
        rec.save(arg)
    elif kind == "connect":
        rec.connect_grpc(arg) if arg else rec.connect_grpc()
    elif kind == "spawn":
        rec.spawn()
    elif kind == "memory":
        rec.memory_recording()
    else:
        raise ConfigError(f"--rerun {target!r}: expected save:FILE, connect:ADDR, spawn, memory or off")
    return rec


class RerunStream:
    """Buffered streaming of per-joint signals, IMU, F/T and the 3D robot to one recording."""

    def __init__(
        self,
        rec: rr.RecordingStream | None,
        joint_names: Sequence[str],
        model_path: str,
        *,
        plot_joints: Sequence[str] | None = None,
        flush_every: int = 200,
        robot_hz: float = 25.0,
    ):
        self.rec = rec
        self.joint_names = tuple(joint_names)
        self.flush_every = flush_every
        self._ticks = 0
        self._series: dict[str, tuple[list[float], list[np.ndarray]]] = {}  # name -> (times, values)
        self._last_robot_t = -np.inf
        self._robot_dt = 1.0 / robot_hz
        if rec is None:
            return
        rec.send_blueprint(_blueprint(plot_joints or self.joint_names[:6]))
        self._model = mujoco.MjModel.from_xml_path(model_path)
        self._data = mujoco.MjData(self._model)
        m = self._model
        model_joints = {m.joint(i).name for i in range(m.njnt)}
        unknown = [j for j in self.joint_names if j not in model_joints]
        if unknown:
            raise ConfigError(f"{model_path}: joints {unknown} are not in the model: expected names among "
                              f"{sorted(model_joints)}")
        self._qadr = np.array([m.joint(j).qposadr[0] for j in self.joint_names])
        self._boxes = np.flatnonzero(m.geom_type == mujoco.mjtGeom.mjGEOM_BOX)
        self._caps = np.flatnonzero(m.geom_type == mujoco.mjtGeom.mjGEOM_CAPSULE)
        rec.log("robot/floor", rr.Boxes3D(centers=[[0, 0, -0.005]], half_sizes=[[1.0, 1.0, 0.005]],
                                          colors=[[200, 200, 200, 80]]), static=True)
        self._queue: queue.Queue = queue.Queue(maxsize=8)
        self._worker = threading.Thread(target=self._send_loop, name="rerun-flush", daemon=True)
        self._worker.start()

    def add(self, time: float, **signals: np.ndarray) -> None:
        """Buffer one tick of signals at sim time ``time`` [s]. Per-joint arrays (length = number of
        joints) go to ``joints/<joint>/<name>``; other arrays go to ``<name>`` as one series per entry."""
        if self.rec is None:
            return
        for name, value in signals.items():
            times, values = self._series.setdefault(name, ([], []))
            times.append(time)
            values.append(np.asarray(value, dtype=float).ravel())
        self._ticks += 1
        if self._ticks >= self.flush_every:
            self.flush()

    def robot(self, time: float, q: np.ndarray, base_position=None, base_quat_wxyz=None) -> None:
        """Send the 3D robot at joint angles ``q`` [rad] (rate-limited to ``robot_hz``)."""
        if self.rec is None or time - self._last_robot_t < self._robot_dt:
            return
        self._last_robot_t = time
        m, d = self._model, self._data
        d.qpos[:] = m.qpos0
        d.qpos[2] = 0.75
        if base_position is not None:
            d.qpos[0:3] = base_position
        if base_quat_wxyz is not None:
            d.qpos[3:7] = base_quat_wxyz
        d.qpos[self._qadr] = q
        mujoco.mj_kinematics(m, d)
        self.rec.set_time(TIMELINE, duration=time)
        quat = np.empty((m.ngeom, 4))
        for g in range(m.ngeom):
            mujoco.mju_mat2Quat(quat[g], d.geom_xmat[g])
        xyzw = quat[:, [1, 2, 3, 0]]
        b, c = self._boxes, self._caps
        self.rec.log("robot/boxes", rr.Boxes3D(centers=d.geom_xpos[b], half_sizes=m.geom_size[b],
                                               quaternions=xyzw[b], colors=[[150, 160, 200]]))
        half = m.geom_size[c, 1]
        axis = d.geom_xmat[c].reshape(-1, 3, 3)[:, :, 2]
        self.rec.log("robot/capsules", rr.Capsules3D(lengths=2 * half, radii=m.geom_size[c, 0],
                                                     translations=d.geom_xpos[c] - axis * half[:, None],
                                                     quaternions=xyzw[c], colors=[[150, 160, 200]]))

    def flush(self) -> None:
        """Hand the buffered scalars to the sending thread."""
        if self.rec is None or not self._series:
            return
        self._queue.put({k: (np.asarray(t), np.vstack(v)) for k, (t, v) in self._series.items()})
        self._ticks = 0
        self._series = {}

    def _send_loop(self) -> None:
        while (item := self._queue.get()) is not None:
            self._send(item)

    def _send(self, series: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
        n = len(self.joint_names)
        for name, (times, values) in series.items():
            index = [rr.TimeColumn(TIMELINE, duration=times)]
            if values.shape[1] == n and not name.startswith(("imu", "ft")):
                for j, joint in enumerate(self.joint_names):
                    self.rec.send_columns(f"joints/{joint}/{name}", index, rr.Scalars.columns(scalars=values[:, j]))
            else:
                for k in range(values.shape[1]):
                    self.rec.send_columns(f"{name}/{k}", index, rr.Scalars.columns(scalars=values[:, k]))

    def close(self) -> None:
        """Send what is buffered, wait for the sending thread, flush the recording."""
        if self.rec is None:
            return
        self.flush()
        self._queue.put(None)
        self._worker.join()
        self.rec.flush()
