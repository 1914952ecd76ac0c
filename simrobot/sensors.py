"""Sensor models of the simulated robot: quantised encoders, a noisy biased IMU, noisy F/T sensors
with offsets and saturation, and scripted faults (stale or NaN readings) for testing."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.config import Section, load_dataclass, load_toml, read_setting, setting
from servotau.hal.types import (
    FT_SENSOR_NAMES,
    STATUS_INVALID,
    STATUS_NAMES,
    STATUS_SATURATED,
    STATUS_STALE,
    SensorFrame,
)


@dataclass(frozen=True)
class SensorFault:
    """A scripted sensor fault: ``sensor`` (one of STATUS_NAMES) gives ``kind`` ("nan" or "stale")
    readings from ``start`` for ``duration`` seconds of sim time."""

    sensor: str = setting(choices=STATUS_NAMES)
    kind: str = setting(choices=("nan", "stale"))
    start: float = setting(unit="s", min=0)
    duration: float = setting(unit="s", min=0)


@dataclass(frozen=True)
class SensorConfig:
    encoder_resolution: float = setting(unit="rad", min=0)
    gyro_noise: float = setting(unit="rad/s", min=0)
    gyro_bias: np.ndarray = setting(unit="rad/s", shape=(3,))
    accel_noise: float = setting(unit="m/s^2", min=0)
    accel_bias: np.ndarray = setting(unit="m/s^2", shape=(3,))
    force_noise: float = setting(unit="N", min=0)
    torque_noise: float = setting(unit="N m", min=0)
    offset_scale: np.ndarray = setting(unit="N, N m", shape=(2,))
    ranges: np.ndarray = setting(unit="N, N m", shape=(len(FT_SENSOR_NAMES), 6))  # per F/T sensor
    faults: tuple[SensorFault, ...] = ()

    @classmethod
    def from_toml(cls, path: str | Path) -> SensorConfig:
        """Read a sensors file: ``[encoders]``, ``[imu]``, ``[ft]`` (keys: :data:`TABLES`, and the ranges
        of the ankle and wrist F/T sensors) and ``[[faults]]``."""
        root = load_toml(path)
        root.check_keys([*TABLES, "faults"])
        values = {}
        for table, keys in TABLES.items():
            sec = root.section(table)
            sec.check_keys([*keys, *(("ankle_range", "wrist_range") if table == "ft" else ())])
            values.update({field_: read_setting(cls, field_, sec, key) for key, field_ in keys.items()})
        ft = root.section("ft")
        ankle = ft.floats("ankle_range", 6, unit="N, N m")
        wrist = ft.floats("wrist_range", 6, unit="N, N m")
        raw_faults = root.data.get("faults", [])
        if not isinstance(raw_faults, list) or not all(isinstance(f, dict) for f in raw_faults):
            raise root.error("faults", raw_faults, "an array of tables [[faults]]")
        faults = [load_dataclass(SensorFault, Section(raw, root.file, f"faults[{i}]"))
                  for i, raw in enumerate(raw_faults)]
        return cls(**values, ranges=np.array([ankle, ankle, wrist, wrist]), faults=tuple(faults))


TABLES = {
    "encoders": {"resolution": "encoder_resolution"},
    "imu": {k: k for k in ("gyro_noise", "gyro_bias", "accel_noise", "accel_bias")},
    "ft": {k: k for k in ("force_noise", "torque_noise", "offset_scale")},
}
"""The tables of a sensors file: key -> field of :class:`SensorConfig`."""


class SensorModel:
    """Turns true signals into sensor readings (seeded, deterministic)."""

    def __init__(self, config: SensorConfig, n_joints: int, rng: np.random.Generator):
        self.config = config
        self.n = n_joints
        self.rng = rng
        scale = np.repeat(config.offset_scale, 3)
        self.ft_offsets = rng.uniform(-1.0, 1.0, size=(len(FT_SENSOR_NAMES), 6)) * scale  # [N, N m]
        self._noise_std = np.concatenate(
            [np.full(3, config.gyro_noise), np.full(3, config.accel_noise),
             np.tile(np.repeat([config.force_noise, config.torque_noise], 3), len(FT_SENSOR_NAMES))]
        )
        self._last: SensorFrame | None = None

    def measure(
        self,
        time: float,
        seq: int,
        q: np.ndarray,
        gyro: np.ndarray,
        accel: np.ndarray,
        wrenches: np.ndarray,
    ) -> SensorFrame:
        """Sensor frame from true encoder-side angles [rad], IMU-frame gyro [rad/s] and specific force
        [m/s^2], and true F/T wrenches (4, 6) in the HAL convention."""
        c = self.config
        noise = self.rng.standard_normal(self._noise_std.size) * self._noise_std
        res = c.encoder_resolution
        q_meas = np.round(q / res) * res if res > 0 else q.copy()
        w = wrenches + self.ft_offsets + noise[6:].reshape(-1, 6)
        status = np.zeros(len(STATUS_NAMES), dtype=np.uint8)
        sat = np.abs(w) >= c.ranges
        if sat.any():
            status[2:][sat.any(axis=1)] = STATUS_SATURATED
            np.clip(w, -c.ranges, c.ranges, out=w)
        frame_parts = {
            "q": q_meas,
            "imu_angular_velocity": gyro + c.gyro_bias + noise[0:3],
            "imu_linear_acceleration": accel + c.accel_bias + noise[3:6],
            "wrenches": w,
        }
        for fault in c.faults:
            if fault.start <= time < fault.start + fault.duration:
                k = STATUS_NAMES.index(fault.sensor)
                _apply_fault(frame_parts, self._last, fault, k)
                status[k] = STATUS_INVALID if fault.kind == "nan" else STATUS_STALE
        for arr in frame_parts.values():
            arr.setflags(write=False)
        status.setflags(write=False)
        frame = SensorFrame(time=time, seq=seq, status=status, **frame_parts)
        self._last = frame
        return frame


def _apply_fault(parts: dict, last: SensorFrame | None, fault: SensorFault, k: int) -> None:
    """Replace one sensor's reading with NaN or with its previous value."""
    if fault.sensor == "encoders":
        keys, rows = ["q"], None
    elif fault.sensor == "imu":
        keys, rows = ["imu_angular_velocity", "imu_linear_acceleration"], None
    else:
        keys, rows = ["wrenches"], k - 2
    for key in keys:
        arr = parts[key] if rows is None else parts[key][rows]
        if fault.kind == "nan" or last is None:
            arr[...] = np.nan
        else:
            prev = getattr(last, key)
            arr[...] = prev if rows is None else prev[rows]
