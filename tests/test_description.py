"""servotau.description: the one Pinocchio loader gives the estimator and the controller the models they had."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from servotau.control.dynamics import RobotDynamics
from servotau.description import FT_FRAMES, FT_SENSOR_NAMES, JOINT_NAMES, MODEL_PATH, ROOT_JOINT, load_pinocchio
from servotau.errors import ConfigError
from servotau.estimation.config import EstimatorConfig
from servotau.estimation.model import EstimatorModel, perturb_inertias, split_sensor_bodies
from servotau.hal.types import RobotInfo


def _raw() -> pin.Model:
    """The model as the estimator loaded it before (``buildModelFromMJCF``, gravity as Pinocchio parses it)."""
    return pin.buildModelFromMJCF(str(MODEL_PATH))


def _states(model: pin.Model, n: int = 5, seed: int = 0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq)), \
            rng.standard_normal(model.nv), rng.standard_normal(model.nv)


def test_the_loader_gives_the_parsed_model_with_the_file_gravity():
    """Same joints, inertias, armature and gravity as the raw parse: RNEA equal on random states."""
    new, old = load_pinocchio(), _raw()
    assert list(new.names) == list(old.names) and new.names[1] == ROOT_JOINT
    assert np.array_equal(new.gravity.linear, old.gravity.linear)  # the file's <option gravity> is Pinocchio's
    assert np.array_equal(new.armature, old.armature) and new.nframes == old.nframes
    d_new, d_old = new.createData(), old.createData()
    for q, v, a in _states(new):
        assert np.array_equal(pin.rnea(new, d_new, q, v, a), pin.rnea(old, d_old, q, v, a))


def test_the_estimators_model_is_unchanged():
    """EstimatorModel's split model (sensor frames from RobotInfo) equals the one built from the raw parse with
    the frames the estimator's config used to hold: same RNEA on random states."""
    info = RobotInfo("test", JOINT_NAMES, -np.ones(30), np.ones(30), 1e-3, str(MODEL_PATH))
    cfg = EstimatorConfig()
    robot = EstimatorModel(info, cfg)
    old, _ = split_sensor_bodies(perturb_inertias(_raw(), cfg.perturbation), {s: f"ft_{s}" for s in FT_SENSOR_NAMES})
    old.gravity = pin.Motion.Zero()
    new = robot.model
    assert list(new.names) == list(old.names)
    d_new, d_old = new.createData(), old.createData()
    for q, v, a in _states(new):
        assert np.array_equal(pin.rnea(new, d_new, q, v, a), pin.rnea(old, d_old, q, v, a))


@pytest.mark.parametrize("base", ["fixed", "floating"])
def test_the_controllers_model_is_unchanged(base):
    """RobotDynamics' model equals the raw parse with the file's gravity (fixed: root locked): same RNEA."""
    old = _raw()
    old.gravity.linear = np.array([0.0, 0.0, -9.81])  # <option gravity> of hrp2.xml, as simrobot copied it
    if base == "fixed":
        old = pin.buildReducedModel(old, [old.getJointId(ROOT_JOINT)], pin.neutral(old))
    else:
        old.gravity.linear = np.zeros(3)
    new = RobotDynamics(MODEL_PATH, JOINT_NAMES, base).model
    assert list(new.names) == list(old.names)
    d_new, d_old = new.createData(), old.createData()
    for q, v, a in _states(new):
        assert np.array_equal(pin.rnea(new, d_new, q, v, a), pin.rnea(old, d_old, q, v, a))


def test_every_ft_sensor_has_its_frame_in_the_model():
    """FT_FRAMES names a frame of the Pinocchio model for each HAL F/T sensor, in the HAL's row order."""
    model = load_pinocchio()
    assert tuple(FT_FRAMES) == FT_SENSOR_NAMES == RobotInfo("x", ("a",), [0], [1], 1e-3, "").ft_sensor_names
    assert all(model.existFrame(f) for f in FT_FRAMES.values())


def test_loader_errors_name_the_file(tmp_path):
    """A missing file, an unparsable file or a model without the free flyer raise ConfigError naming the file."""
    with pytest.raises(ConfigError, match="nope.xml does not exist: expected an MJCF file"):
        load_pinocchio(tmp_path / "nope.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body name='b'><joint name='j'/></body></worldbody>")
    with pytest.raises(ConfigError, match="bad.xml: Pinocchio cannot parse the robot model"):
        load_pinocchio(bad)
    fixed = tmp_path / "fixed.xml"
    fixed.write_text("<mujoco><worldbody><body name='b'><joint name='j' type='hinge'/>"
                     "<inertial pos='0 0 0' mass='1' diaginertia='1 1 1'/></body></worldbody></mujoco>")
    with pytest.raises(ConfigError, match='fixed.xml: expected joint 1 to be the free flyer "root"'):
        load_pinocchio(fixed)
    with pytest.raises(ConfigError, match='expected joint 1 to be the free flyer "waist"'):
        load_pinocchio(MODEL_PATH, "waist")


def test_importing_the_description_loads_neither_pinocchio_nor_mujoco():
    """The names are free to import (the HAL's types read them); Pinocchio loads with the loader only."""
    code = ("import sys, servotau.description as d; assert not {'pinocchio', 'mujoco'} & set(sys.modules); "
            "d.load_pinocchio; assert 'pinocchio' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
