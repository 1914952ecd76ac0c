"""Tests of the estimator settings (estimation/config.py, config/estimation.toml)."""

import numpy as np
import pytest

from servotau.errors import ConfigError, EstimationError
from servotau.estimation.config import EstimatorConfig, FilterSettings, ModelPerturbation, PredictionSettings


def test_default_file_gives_the_paper_windows_with_higher_orders():
    """config/estimation.toml: the paper's 80-sample centred windows; orders 4 encoders, 2 IMU, 1 F/T
    (paper: 2, 1, 1; bench/estimation.py measures both)."""
    cfg = EstimatorConfig.from_toml()
    assert cfg.encoders == FilterSettings(80, 4)
    assert cfg.imu == FilterSettings(80, 2) and cfg.ft == FilterSettings(80, 1)
    assert cfg.eval_at == "centre" and cfg.angular_acceleration == "savgol"
    assert cfg.unknown_wrench_link == "CHEST_LINK1"
    assert not cfg.ft_offsets.any() and not cfg.gyro_bias.any() and cfg.armature and cfg.align
    assert not cfg.perturbation.enabled and not cfg.prediction.enabled


def test_low_delay_variant_evaluates_at_the_newest_sample_with_one_order_more():
    """variant="low_delay": eval_at "last", encoders order 3 and IMU order 2 (no delayed top derivative)."""
    cfg = EstimatorConfig.from_toml(variant="low_delay")
    assert cfg.eval_at == "last"
    assert cfg.encoders.order == 3 and cfg.imu.order == 2 and cfg.ft.order == 1
    assert EstimatorConfig().low_delay(window=30).encoders == FilterSettings(30, 3)


def test_toml_errors_name_the_file_and_field(tmp_path):
    """A bad window, an unknown field or a bad choice raise ConfigError naming the field."""
    bad = tmp_path / "est.toml"
    bad.write_text("[filters.encoders]\nwindow = 2\norder = 2\n")
    with pytest.raises(ConfigError, match="filters.encoders.window"):
        EstimatorConfig.from_toml(bad)
    bad.write_text("eval_at = 'middle'\n")
    with pytest.raises(ConfigError, match="eval_at"):
        EstimatorConfig.from_toml(bad)
    bad.write_text("windw = 3\n")
    with pytest.raises(ConfigError, match="windw"):
        EstimatorConfig.from_toml(bad)


def test_toml_reads_calibration_perturbation_and_motor_parameters(tmp_path):
    """Offsets, gyro bias, model perturbation and k_tau/k_v (from the motor file named there) are read."""
    motors = tmp_path / "motors.toml"
    motors.write_text('version = 1\n[joints.RLEG_JOINT3]\nk_tau = 5e-5\nk_v = 6.5e-3\nloss = "least_squares"\n'
                      'provenance = "test"\n')
    path = tmp_path / "est.toml"
    path.write_text(
        "[calibration]\ngyro_bias = [0.001, 0.0, -0.002]\n[calibration.ft_offsets]\n"
        "left_wrist = [1, 2, 3, 0.1, 0.2, 0.3]\n[model]\nmass_scale_std = 0.1\nseed = 4\n"
        f"[prediction]\nmotors = '{motors}'\n"
    )
    cfg = EstimatorConfig.from_toml(path)
    assert np.allclose(cfg.gyro_bias, [0.001, 0.0, -0.002])
    assert np.allclose(cfg.ft_offsets[3], [1, 2, 3, 0.1, 0.2, 0.3]) and not cfg.ft_offsets[:3].any()
    assert cfg.perturbation == ModelPerturbation(0.1, 0.0, 4)
    assert cfg.prediction.k_tau == {"RLEG_JOINT3": 5e-5} and cfg.prediction.enabled


def test_invalid_direct_construction_raises_estimation_error():
    """Direct construction validates: order >= window, bad shapes, mismatched motor tables."""
    with pytest.raises(EstimationError, match="window"):
        FilterSettings(3, 2)
    with pytest.raises(EstimationError, match="ft_offsets"):
        EstimatorConfig(ft_offsets=np.zeros((3, 6)))
    with pytest.raises(EstimationError, match="same joints"):
        PredictionSettings(k_tau={"RLEG_JOINT3": 1e-4}, k_v={})
    with pytest.raises(EstimationError, match="encoders.order"):
        EstimatorConfig(encoders=FilterSettings(20, 1))



def test_prediction_reads_k_tau_and_k_v_from_the_motor_file(tmp_path):
    """[prediction] takes k_tau, k_v of the listed joints from a motor file of config/motors/, the same numbers."""
    from servotau.actuator import MotorParameters
    from servotau.config import CONFIG_DIR
    from servotau.errors import ConfigError

    def cfg(name, text):
        (tmp_path / name).write_text(text)
        return EstimatorConfig.from_toml(tmp_path / name)

    example = MotorParameters.load_toml(CONFIG_DIR / "motors" / "example.toml")
    pred = cfg("one.toml", '[prediction]\nmotors = "motors/example.toml"\njoints = ["RLEG_JOINT3"]\n').prediction
    assert pred.k_tau == {"RLEG_JOINT3": 5.1e-5} and pred.k_v == {"RLEG_JOINT3": 6.561e-3}
    assert pred.k_tau["RLEG_JOINT3"] == example["RLEG_JOINT3"].k_tau
    every = cfg("all.toml", '[prediction]\nmotors = "motors/example.toml"\n').prediction
    assert set(every.k_tau) == set(example) and every.velocity_window == 20
    with pytest.raises(ConfigError, match="joints"):
        cfg("bad.toml", '[prediction]\nmotors = "motors/example.toml"\njoints = ["LARM_JOINT0"]\n')
    with pytest.raises(ConfigError, match="prediction.motors"):
        cfg("none.toml", '[prediction]\nmotors = "motors/none.toml"\n')
    with pytest.raises(ConfigError, match="k_tau"):  # the motor parameters live only in config/motors/
        cfg("copy.toml", "[prediction.k_tau]\nRLEG_JOINT3 = 5e-5\n")
    assert not EstimatorConfig.from_toml().prediction.enabled


def test_partial_tables_keep_the_dataclass_defaults(tmp_path):
    """A [filters.X] table with one key keeps the other of the default filter; [low_delay] and
    [model] take LowDelaySettings' and ModelPerturbation's defaults; errors name the dotted field."""
    from servotau.estimation.config import LowDelaySettings

    path = tmp_path / "est.toml"
    path.write_text("[filters.imu]\nwindow = 40\n[low_delay]\nimu_order = 3\n")
    cfg = EstimatorConfig.from_toml(path)
    assert cfg.imu == FilterSettings(40, EstimatorConfig().imu.order) and cfg.encoders == EstimatorConfig().encoders
    assert cfg.perturbation == ModelPerturbation()
    low = EstimatorConfig.from_toml(path, variant="low_delay")
    assert low.imu == FilterSettings(80, 3) and low.encoders.order == LowDelaySettings.encoders_order
    path.write_text("[filters.imu]\norder = 79\n")
    with pytest.raises(ConfigError, match=r"est.toml: field 'filters.imu.window' = 80: expected an integer >= "
                                          r"order \+ 2 = 81"):
        EstimatorConfig.from_toml(path)
    path.write_text("[model]\ncom_offset_std = 0.6\n")
    with pytest.raises(ConfigError, match=r"field 'model.com_offset_std' = 0.6: expected a finite number >= 0 "
                                          r"<= 0.5 \[m\]"):
        EstimatorConfig.from_toml(path)
