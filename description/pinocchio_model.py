"""The one Pinocchio loader of the robot model (the estimator's and the controller's model)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from servotau.errors import ConfigError

from .robot import MODEL_PATH, ROOT_JOINT


def load_pinocchio(path: str | Path = MODEL_PATH, root_joint: str = ROOT_JOINT) -> pin.Model:
    """Build the Pinocchio model of the MJCF file ``path``, with its free-flyer root joint.

    The parser turns ``<freejoint name="root"/>`` into a ``JointModelFreeFlyer`` by itself (passing a
    root joint would not add a second one), reads ``armature`` and turns sites into frames. It ignores
    ``<option gravity>``, so gravity is copied from the file here.

    Raises:
        ConfigError: the file does not exist, Pinocchio cannot parse it, or joint 1 is not the free
            flyer ``root_joint``; the message names the file.
    """
    path = existing_model_file(path)
    try:
        model = pin.buildModelFromMJCF(str(path))
    except (RuntimeError, ValueError) as err:
        raise ConfigError(f"{path}: Pinocchio cannot parse the robot model: {err}") from err
    if model.njoints < 2 or model.names[1] != root_joint or model.joints[1].shortname() != "JointModelFreeFlyer":
        raise ConfigError(f'{path}: expected joint 1 to be the free flyer "{root_joint}", got {list(model.names)}')
    model.gravity.linear = mjcf_gravity(path)
    return model


def existing_model_file(path: str | Path) -> Path:
    """``path`` as a Path if it is a file, else ConfigError naming it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"robot model file {path} does not exist: expected an MJCF file")
    return path


def mjcf_gravity(path: str | Path) -> np.ndarray:
    """[m/s^2] (3,) ``<option gravity>`` of the MJCF file ``path`` (MuJoCo's default if absent)."""
    option = ET.parse(path).getroot().find("option")
    text = option.get("gravity") if option is not None else None
    return np.array([float(x) for x in text.split()]) if text else np.array([0.0, 0.0, -9.81])
