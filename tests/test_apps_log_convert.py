"""servotau log convert: ROS 1 and ROS 2 bags (MCAP, SQLite), written here with rosbags, as servotau logs."""

import numpy as np
import pytest

from servotau.apps.log_convert import convert_bag
from servotau.cli import main
from servotau.description import JOINT_NAMES
from servotau.errors import ConfigError
from servotau.hal.log import LogReader, read_log
from servotau.hal.types import STATUS_INVALID, STATUS_NAMES, STATUS_OK

N = 400  # joint_state messages at 1 kHz
BAG_NAMES = [f"j{k}" for k in range(30)]  # the bag's joint names, renamed by [joints]; shuffled in each message
MAPPING = """
[robot]
name = "bagbot"

[joint_state]
topic = "/joint_states"
effort = true

[joint_command]
topic = "/joint_commands"

[imu]
topic = "/imu"

[ft.right_ankle]
topic = "/ft/right_ankle"

[joints]
""" + "\n".join(f'{b} = "{j}"' for b, j in zip(BAG_NAMES, JOINT_NAMES, strict=True)) + "\n"


def _q(t: np.ndarray) -> np.ndarray:
    """[rad] (len(t), 30): joint k swings at 1 + k/10 Hz."""
    return 0.1 * np.sin(2 * np.pi * np.outer(t, 1 + np.arange(30) / 10))


def write_bag(path, kind: str, quiet=range(0)) -> None:
    """joint_states and joint_commands at 1 kHz, imu at 1 kHz, the right ankle's F/T at 500 Hz; the commands
    start 5 ms late (those rows are dropped) and skip the ticks in ``quiet``."""
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        writer, serialize = Writer(path), ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        ts = get_typestore(Stores.ROS2_HUMBLE)
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer, serialize = Writer(path, version=9, storage_plugin=plugin), ts.serialize_cdr
    T = ts.types
    Time, Vec = T["builtin_interfaces/msg/Time"], T["geometry_msgs/msg/Vector3"]
    t0 = 1_700_000_000_000_000_000

    def header(ns):
        stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        if kind == "ros1":
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="")
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="")

    rng = np.random.default_rng(0)
    t = np.arange(N) * 1e-3
    q = _q(t)
    with writer:
        c_js = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        c_cmd = writer.add_connection("/joint_commands", "sensor_msgs/msg/JointState", typestore=ts)
        c_imu = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        c_ft = writer.add_connection("/ft/right_ankle", "geometry_msgs/msg/WrenchStamped", typestore=ts)
        for k in range(N):
            ns = t0 + k * 1_000_000
            perm = rng.permutation(30)
            names = [BAG_NAMES[i] for i in perm]
            js = T["sensor_msgs/msg/JointState"](header=header(ns), name=names, position=q[k, perm],
                                                 velocity=np.zeros(0), effort=2.0 * q[k, perm])
            writer.write(c_js, ns, serialize(js, "sensor_msgs/msg/JointState"))
            if k >= 5 and k not in quiet:
                cmd = T["sensor_msgs/msg/JointState"](header=header(ns), name=BAG_NAMES, position=q[k] + 0.01,
                                                      velocity=np.zeros(0), effort=np.zeros(0))
                writer.write(c_cmd, ns, serialize(cmd, "sensor_msgs/msg/JointState"))
            imu = T["sensor_msgs/msg/Imu"](
                header=header(ns), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9), angular_velocity=Vec(x=0.1, y=0.2, z=k * 1e-3),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=Vec(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9))
            writer.write(c_imu, ns, serialize(imu, "sensor_msgs/msg/Imu"))
            if k % 2 == 0:
                w = T["geometry_msgs/msg/WrenchStamped"](header=header(ns), wrench=T["geometry_msgs/msg/Wrench"](
                    force=Vec(x=1.0, y=2.0, z=float(k)), torque=Vec(x=0.1, y=0.2, z=0.3)))
                writer.write(c_ft, ns, serialize(w, "geometry_msgs/msg/WrenchStamped"))


@pytest.fixture
def mapping(tmp_path):
    path = tmp_path / "mapping.toml"
    path.write_text(MAPPING)
    return path


@pytest.mark.parametrize("kind", ["mcap", "sqlite", "ros1"])
def test_bag_converts_to_a_log_the_workbench_loads(tmp_path, mapping, kind):
    """Each bag format: joints renamed and reordered to the HAL's, commands and sensors held at their latest
    message, rows before the first command dropped, unmapped sensors invalid; the workbench loads the joint."""
    from servotau.identification.workbench.data import load_dataset

    bag = tmp_path / ("b.bag" if kind == "ros1" else "b")
    write_bag(bag, kind)
    r = convert_bag(bag, mapping, tmp_path / "log.parquet")
    assert (r.rows, r.dropped) == (N - 5, 5) and r.joints == JOINT_NAMES
    info, cols = read_log(r.path)
    assert info.name == "bagbot" and info.joint_names == JOINT_NAMES and info.period == pytest.approx(1e-3)
    t = np.arange(5, N) * 1e-3
    assert np.allclose(cols["t"], t - t[0]) and np.array_equal(cols["seq"], np.arange(N - 5))
    q = _q(t)
    for k in (0, 9, 29):
        j = JOINT_NAMES[k]
        assert np.allclose(cols[f"q/{j}"], q[:, k]) and np.allclose(cols[f"q_des/{j}"], q[:, k] + 0.01)
        assert np.allclose(cols[f"est/tau/{j}"], 2.0 * q[:, k])
    assert np.allclose(cols["imu/gyro_z"], np.arange(5, N) * 1e-3) and np.allclose(cols["imu/acc_z"], 9.81)
    assert np.allclose(cols["ft/right_ankle/fz"], 2 * (np.arange(5, N) // 2))  # held between 500 Hz messages
    assert np.isnan(cols["ft/left_wrist/tx"]).all()
    assert (cols["status/left_wrist"] == STATUS_INVALID).all() and (cols["status/right_ankle"] == STATUS_OK).all()
    assert set(STATUS_NAMES) <= {c.removeprefix("status/") for c in cols}
    assert LogReader(r.path).metadata["bag.start_ns"] == str(1_700_000_000_000_000_000 + 5_000_000)
    assert any("5 rows" in n for n in r.notes) and any("left_wrist" in n for n in r.notes)
    ds = load_dataset(r.path, joint="RLEG_JOINT3")
    assert ds.n > 300 and np.allclose(ds.target, 0.01, atol=1e-9)  # target = q_des - q


def test_a_command_topic_gone_quiet_gives_no_command_not_an_old_one(tmp_path, mapping):
    """No joint_commands message for 100 ms: q_des is NaN from 1.5 periods after the last one until the next, with
    a note (the workbench drops those rows); the IMU and the other rows keep their values."""
    bag = tmp_path / "b"
    write_bag(bag, "mcap", quiet=range(200, 300))
    r = convert_bag(bag, mapping, tmp_path / "log.parquet")
    _, cols = read_log(r.path)
    qd = cols[f"q_des/{JOINT_NAMES[0]}"]  # row i is tick i + 5
    assert np.isnan(qd[196:295]).all() and np.isfinite(qd[:195]).all() and np.isfinite(qd[295:]).all()
    assert any("99 rows without a command" in n for n in r.notes), r.notes


def test_cli_log_convert_writes_the_log_and_prints_notes(tmp_path, mapping, capsys):
    bag = tmp_path / "b"
    write_bag(bag, "mcap")
    assert main(["log", "convert", str(bag), "--map", str(mapping), "-o", str(tmp_path / "x.parquet")]) == 0
    out = capsys.readouterr().out
    assert "wrote" in out and "395 rows" in out and "note: not mapped" in out
    assert main(["log", "convert", str(tmp_path / "nobag"), "--map", str(mapping), "-o", "x.parquet"]) == 2
    assert "bag not found" in capsys.readouterr().err


def test_bad_mappings_and_bags_are_errors_naming_the_topic_or_field(tmp_path, mapping):
    """A missing topic, a joint missing from a message, a wrong message type, bad mapping fields, a joint that is
    not in the model: each error names the topic or the field and what was expected."""
    bag = tmp_path / "b"
    write_bag(bag, "mcap")
    out = tmp_path / "x.parquet"

    def fails(text: str, match: str):
        path = tmp_path / "m.toml"
        path.write_text(text)
        with pytest.raises(ConfigError, match=match):
            convert_bag(bag, path, out)

    fails(MAPPING.replace('"/imu"', '"/imu_data"'),
          r"field 'imu.topic' = '/imu_data': topic not in .*expected one of \['/ft/right_ankle', '/imu'")
    fails(MAPPING.replace('[imu]\ntopic = "/imu"', '[imu]\ntopic = "/joint_states"'),
          "topic /joint_states .*carries sensor_msgs/msg/JointState: expected sensor_msgs/msg/Imu")
    fails(MAPPING.replace("[ft.right_ankle]", "[ft.right_foot]"), r"field 'ft.right_foot'.*expected a known field")
    fails(MAPPING.replace('name = "bagbot"', 'name = "bagbot"\nstamp = "wall"'),
          r"field 'robot.stamp' = 'wall': expected one of \['header', 'bag'\]")
    fails(MAPPING.replace('[joint_state]\ntopic = "/joint_states"', "[joint_state]"),
          r"field 'joint_state.topic' missing")
    fails(MAPPING.replace('j3 = "RLEG_JOINT3"', 'j3 = "KNEE"'), "joint 'KNEE' .*is not in the model")
    short = tmp_path / "short"
    _write_short_commands(short)
    fails_on = tmp_path / "m2.toml"
    fails_on.write_text(MAPPING.replace('[imu]\ntopic = "/imu"\n', "").replace(
        '[ft.right_ankle]\ntopic = "/ft/right_ankle"\n', ""))
    with pytest.raises(ConfigError, match=r"topic /joint_commands .*joint 'j7' is not in the message"):
        convert_bag(short, fails_on, out)


def _write_short_commands(path) -> None:
    """A bag whose command messages name 29 joints (j7 missing)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {name: w.add_connection(name, "sensor_msgs/msg/JointState", typestore=ts)
                 for name in ("/joint_states", "/joint_commands")}
        for k in range(10):
            ns = 1_000_000_000 + k * 1_000_000
            header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=k * 1_000_000),
                                              frame_id="")
            for name, names in (("/joint_states", BAG_NAMES), ("/joint_commands", BAG_NAMES[:7] + BAG_NAMES[8:])):
                msg = T["sensor_msgs/msg/JointState"](header=header, name=names, position=np.zeros(len(names)),
                                                      velocity=np.zeros(0), effort=np.zeros(len(names)))
                w.write(conns[name], ns, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


@pytest.mark.slow
def test_identify_fit_accepts_a_converted_bag(tmp_path, mapping, monkeypatch, capsys):
    """`servotau identify fit` on a converted 3.6 s bag (no torque column: the off-line estimator's, from the
    encoders, IMU and F/T): it estimates, splits and fits; the fit's numbers are not checked (synthetic motion)."""
    import json
    import sys

    monkeypatch.setattr(sys.modules[__name__], "N", 3600)
    bag = tmp_path / "b"
    write_bag(bag, "mcap")
    mapping.write_text(MAPPING.replace("effort = true", "effort = false"))
    log = convert_bag(bag, mapping, tmp_path / "log.parquet").path
    assert main(["identify", "fit", str(log), "--joints", "RLEG_JOINT3", "--no-write", "--json"]) == 0
    fit = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert fit["log"] == str(log)
    text = json.dumps(fit)
    assert "RLEG_JOINT3" in text and '"n_samples": 0' not in text  # training and held-out samples both
