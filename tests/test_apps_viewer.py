"""servotau.apps.viewer (+ viewer_layout, viewer_robot): what a Rerun recording holds, its views, its errors."""

import subprocess
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from servotau.apps.viewer import RerunHook, RerunStream, open_recording
from servotau.apps.viewer_layout import channels, joint_groups
from servotau.apps.viewer_robot import RobotTree
from servotau.control.terms import COMPONENTS, ControlTerms
from servotau.description import JOINT_NAMES, MODEL_PATH
from servotau.errors import ConfigError
from servotau.hal.types import FT_SENSOR_NAMES


class FakeRecording:
    """Stands in for a RecordingStream: keeps what the stream sends."""

    def __init__(self):
        self.columns, self.logged, self.blueprint = [], [], None

    def send_blueprint(self, bp):
        self.blueprint = bp

    def log(self, path, *archetypes, static=False):
        self.logged.append((path, archetypes, static))

    def set_time(self, *_args, **_kw):
        pass

    def send_columns(self, entity, indexes, columns):
        self.columns.append((entity, indexes, {str(c.component_descriptor().component): c for c in columns}))

    def flush(self):
        pass

    def disconnect(self):
        pass


def _values(col) -> np.ndarray:
    """(ticks, instances) of one sent component column."""
    arr = col.as_arrow_array()  # a list array: one list of instances per tick
    flat, offsets = arr.values.to_numpy(zero_copy_only=False), arr.offsets.to_numpy()
    return np.stack([flat[a:b] for a, b in zip(offsets[:-1], offsets[1:], strict=True)]), arr.values.type


def test_signals_go_to_one_entity_as_float32_components_per_joint_and_sensor():
    """A tick costs one row of /signals; tracking:<joint> holds q_ref, q, q_des of that joint (float32); a signal
    missing on a tick is NaN there; F/T and IMU carry their axes; names outside the set are skipped."""
    rec = FakeRecording()
    joints = JOINT_NAMES
    stream = RerunStream(rec, joints, str(MODEL_PATH), flush_every=50, robot_hz=0)
    for k in range(120):
        truth = {"tau_true": np.full(30, 2.0)} if k % 3 else {}
        stream.add(k * 1e-3, q=np.arange(30) * 0.01 + k * 1e-3, q_des=np.full(30, 0.5), q_ref=np.full(30, 0.25),
                   **{"imu/gyro": np.array([1.0, 2.0, 3.0]), "ft/right_ankle/force": np.array([0.0, 0.0, 600.0])},
                   not_a_signal=np.zeros(4), **truth)
    stats = stream.close()
    assert stats.rows == 120 and stats.robot_seconds == pytest.approx(0.119)
    assert [c[0] for c in rec.columns] == ["signals"] * 3  # 50 + 50 + 20 ticks
    comps = rec.columns[0][2]
    j3 = joints.index("RLEG_JOINT3")
    tracking, dtype = _values(comps["tracking:RLEG_JOINT3"])
    assert str(dtype) == "float" and tracking.shape == (50, 3)  # pyarrow names float32 "float"
    assert np.allclose(tracking[:, 0], 0.25) and np.allclose(tracking[:, 2], 0.5)
    assert np.allclose(tracking[:, 1], j3 * 0.01 + np.arange(50) * 1e-3, atol=1e-6)
    torque, _ = _values(comps["torque:RLEG_JOINT3"])  # tau_d, tau_est, tau_true
    assert np.isnan(torque[0::3, 2]).all() and np.allclose(torque[1::3, 2], 2.0) and np.isnan(torque[:, 0]).all()
    assert np.allclose(_values(comps["imu:gyro"])[0], [1.0, 2.0, 3.0])
    assert np.allclose(_values(comps["ft:right_ankle_force"])[0][:, 2], 600.0)
    assert np.isnan(_values(comps["ft:left_wrist_torque"])[0]).all()
    assert len([c for c in comps if c.startswith("command:")]) == 30
    assert not any("not_a_signal" in c for c in comps)


def test_signal_sets_choose_what_is_recorded():
    """minimal: tracking and tau_est; control adds tau_d, tau_true, the command's components, IMU, F/T; all adds
    the internal errors and the force task; an unknown set is a clear error."""
    minimal, control, full = (channels(s, FT_SENSOR_NAMES) for s in ("minimal", "control", "all"))
    assert set(minimal) == {"q_ref", "q", "q_des", "tau_est"}
    assert set(COMPONENTS) | {"tau_d", "tau_true", "imu/gyro", "imu/acc", "ft/left_ankle/torque"} <= set(control)
    assert set(control) < set(full) and {"e_q", "de_q", "dde_q", "task/f_d"} <= set(full)
    assert [c.field for c in joint_groups(control)["torque"]] == ["tau_d", "tau_est", "tau_true"]
    assert control["ft/right_ankle/torque"].names == ("tx", "ty", "tz")
    assert control["imu/acc"].names == ("acc_x", "acc_y", "acc_z") and control["imu/acc"].unit == "m/s^2"
    rec = FakeRecording()
    stream = RerunStream(rec, JOINT_NAMES, str(MODEL_PATH), signals="minimal", robot_hz=0)
    stream.add(0.0, q=np.zeros(30), ff_torque=np.ones(30), **{"imu/gyro": np.zeros(3)})
    stream.close()
    assert sorted({c.split(":")[0] for c in rec.columns[0][2]}) == ["torque", "tracking"]
    with pytest.raises(ConfigError, match="rerun signal set 'most': expected one of minimal, control, all"):
        channels("most", FT_SENSOR_NAMES)


def test_hook_records_command_components_mode_changes_and_trips():
    """RerunHook sends the command's components, tau_d and the reference; a mode change and a trip are safety
    events; the mode is logged only when it changes."""
    rec = FakeRecording()
    stream = RerunStream(rec, JOINT_NAMES, str(MODEL_PATH), robot_hz=0)
    hook = RerunHook(stream)
    terms = ControlTerms(30)
    terms.ff_torque[:] = 0.003
    terms.tau_d[:] = 7.0
    frame = SimpleNamespace(time=0.0, q=np.zeros(30), imu_angular_velocity=np.zeros(3),
                            imu_linear_acceleration=np.array([0, 0, 9.81]), wrenches=np.zeros((4, 6)))
    tick = SimpleNamespace(frame=frame, terms=terms, truth=None, estimate=SimpleNamespace(tau=np.ones(30), dq=None),
                           reference=SimpleNamespace(q=np.full(30, 0.1)))
    for k, mode in enumerate(["position"] * 3 + ["torque"] * 3):
        frame.time, terms.mode = k * 1e-3, mode
        hook.on_tick(tick)
    hook.tripped(tick, SimpleNamespace(message="joint_velocity RLEG_JOINT3 12 rad/s > 10 rad/s"))
    stream.close()
    comps = {k: v for _, _, c in rec.columns for k, v in c.items()}
    command, _ = _values(comps["command:RLEG_JOINT0"])
    assert np.allclose(command[:, COMPONENTS.index("ff_torque")], 0.003)
    assert np.allclose(_values(comps["torque:RLEG_JOINT0"])[0][:, :2], [7.0, 1.0])
    assert np.allclose(_values(comps["tracking:RLEG_JOINT0"])[0][:, 0], 0.1)
    modes = [a[0] for p, a, _ in rec.logged if p == "safety/mode" and type(a[0]).__name__ == "Scalars"]
    assert len(modes) == 2  # position, then torque
    events = [str(a[0].text.as_arrow_array()[0]) for p, a, _ in rec.logged if p == "safety/events"]
    assert events == ["mode: position -> torque", "SAFETY TRIP: joint_velocity RLEG_JOINT3 12 rad/s > 10 rad/s"]


def test_robot_transform_tree_reproduces_the_world_poses():
    """Composing each body's transform with its parents' gives MuJoCo's world pose of the body."""
    tree = RobotTree(str(MODEL_PATH), JOINT_NAMES)
    q = np.linspace(-0.3, 0.3, 30)
    t, xyzw = tree.transforms(q)
    m, d = tree.model, tree.data
    world = {0: (np.zeros(3), np.array([1.0, 0, 0, 0]))}
    for i, b in enumerate(tree.bodies):  # bodies come parents first
        pp, pq = world[int(tree.parents[i])]
        rel_wxyz = xyzw[i][[3, 0, 1, 2]]
        pos, quat = np.empty(3), np.empty(4)
        mujoco.mju_rotVecQuat(pos, t[i], pq)
        mujoco.mju_mulQuat(quat, pq, rel_wxyz)
        world[b] = (pp + pos, quat)
        assert np.allclose(world[b][0], d.xpos[b], atol=1e-9)
        assert np.allclose(np.abs(quat @ d.xquat[b]), 1.0, atol=1e-9)
    assert tree.paths[tree.bodies.index(m.body("RLEG_LINK3").id)].startswith("robot/BODY/RLEG_LINK0/")


def test_recording_file_is_valid_and_batches_robot_transforms(tmp_path):
    """A saved recording passes `rerun rrd verify`; every body has its transform, each batch a chunk per body."""
    path = tmp_path / "s.rrd"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stream = RerunStream(open_recording(f"save:{path}"), JOINT_NAMES, str(MODEL_PATH), flush_every=50,
                             robot_hz=100.0, robot_batch=5)
        for k in range(100):
            stream.add(k * 1e-3, q=np.full(30, k * 1e-3), **{"imu/gyro": np.zeros(3)})
            stream.robot(k * 1e-3, np.full(30, k * 1e-3))
        stream.close()
    rerun_cli = str(Path(sys.executable).with_name("rerun"))
    assert subprocess.run([rerun_cli, "rrd", "verify", str(path)], capture_output=True).returncode == 0
    stats = subprocess.run([rerun_cli, "rrd", "stats", str(path)], capture_output=True, text=True).stdout
    assert "/signals: 2" in stats  # two batches of 50 ticks
    assert "/robot/BODY/RLEG_LINK0/RLEG_LINK1: 2" in stats  # 10 poses in batches of 5
    assert "tracking:RLEG_JOINT3:" in stats and "Capsules3D:radii" in stats


def test_bad_rerun_target_joint_names_plot_joints_or_rate_are_clear_errors(tmp_path):
    """An unknown --rerun target names the expected forms; joints missing from the model are named."""
    with pytest.raises(ConfigError, match=r"save:FILE, connect:ADDR, spawn\[:PORT\]"):
        open_recording("view:here")
    with pytest.raises(ConfigError, match="expected spawn or spawn:PORT"):
        open_recording("spawn:here")
    with pytest.raises(ConfigError, match=r"joints \['J9'\] are not in the model"):
        RerunStream(open_recording("memory"), ("J9",), str(MODEL_PATH))
    with pytest.raises(ConfigError, match=r"rerun plot joints \['J9'\]: expected names among"):
        RerunStream(open_recording("memory"), JOINT_NAMES, str(MODEL_PATH), plot_joints=["J9"])
    with pytest.raises(ConfigError, match=r"rerun robot rate -1.0: expected >= 0 \[Hz\]"):
        RerunStream(open_recording("memory"), JOINT_NAMES, str(MODEL_PATH), robot_hz=-1.0)


def test_spawn_starts_a_viewer_bound_to_loopback_and_waits_for_it(monkeypatch):
    """spawn:PORT starts `rerun --bind 127.0.0.1 --port PORT` (stubbed here: tests never start a viewer) and returns
    its address once the port listens; a viewer that never listens is a clear error."""
    import socket

    from servotau.apps import viewer

    started = []
    monkeypatch.setattr(viewer.subprocess, "Popen", lambda args, **kw: started.append(args))
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        assert viewer._spawn_local(port) == f"rerun+http://127.0.0.1:{port}/proxy"
    assert started[0][1:] == ["--bind", "127.0.0.1", "--port", str(port)]
    monkeypatch.setattr(viewer, "VIEWER_START_S", 0.2)
    with pytest.raises(ConfigError, match=rf"did not listen on 127.0.0.1:{port} within 0.2 s"):
        viewer._spawn_local(port)
