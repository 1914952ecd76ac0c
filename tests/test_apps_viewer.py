"""servotau.apps.viewer: streaming robot signals to a Rerun recording, and its errors on bad input."""

import warnings

import numpy as np
import pytest

from servotau.apps.viewer import RerunStream, open_recording


def test_rerun_stream_saves_a_recording_with_gaps_in_signals(tmp_path):
    """Streaming to a .rrd file works, including a signal that is missing on some ticks, without warnings."""
    path = tmp_path / "s.rrd"
    from servotau.description import JOINT_NAMES as joints
    from servotau.description import MODEL_PATH

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stream = RerunStream(open_recording(f"save:{path}"), joints, str(MODEL_PATH), flush_every=50)
        for k in range(120):
            extra = {"tau_true": np.ones(30)} if k % 3 else {}
            stream.add(k * 1e-3, q=np.full(30, k * 1e-3), **{"imu/gyro": np.zeros(3)}, **extra)
        stream.close()
    assert path.stat().st_size > 1000


def test_bad_rerun_target_or_joint_names_are_clear_errors(tmp_path):
    """An unknown --rerun target names the expected forms; joints missing from the model are named."""
    from servotau.description import MODEL_PATH
    from servotau.errors import ConfigError

    with pytest.raises(ConfigError, match="save:FILE, connect:ADDR, spawn"):
        open_recording("view:here")
    with pytest.raises(ConfigError, match=r"joints \['J9'\] are not in the model"):
        RerunStream(open_recording(f"save:{tmp_path / 'x.rrd'}"), ("J9",), str(MODEL_PATH))
