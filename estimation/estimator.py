"""The on-line joint-torque estimator (paper section 2, Algorithm 1): one ``update(frame)`` per tick.

Inputs are HAL types only (:class:`~servotau.hal.types.RobotInfo`, :class:`SensorFrame`).

Filters and time stamp: each sensor group (encoders, IMU, F/T) has its own causal SG filter. With
``eval_at="centre"`` every output is delayed by ``(N - 1) / 2`` samples; with ``align = true`` the
inputs of the shorter windows are delayed so that all outputs refer to one instant,
:attr:`Estimate.time` = frame time - :attr:`TorqueEstimator.delay`. With ``eval_at="last"`` the
values are not delayed (``delay = 0``) but the top derivative of each fit is (see savgol.py):
use :meth:`EstimatorConfig.low_delay`, which raises the orders so that no used output is a top
derivative.

Missing, stale or non-finite readings (policy):
- A sensor whose ``frame.status`` entry is not OK, or whose values are not all finite, is *bad* for
  that tick. Encoders are checked per joint (a NaN angle makes only that joint bad; a non-OK
  encoder status makes all joints bad); the IMU as a whole; each F/T sensor as a whole. Missing
  frames (a jump of ``frame.seq``) make every sensor bad for the missing ticks; a sequence number
  that does not increase raises :class:`~servotau.errors.EstimationError`.
- A bad reading never enters a filter: the filter is fed the sensor's last good reading (zeros
  before the first one), which keeps every filter on the common time grid.

Skipped frames (a jump of ``frame.seq``: the controller was late and read a newer frame) are a *gap*,
not bad readings: the filters are fed, for each missing tick of robot time, the linear interpolation
between the last readings before the gap and those of the new frame, so values and derivatives across
the gap stay finite and continuous. Every gap is counted (:attr:`TorqueEstimator.gaps`,
``missing_frames``, ``longest_gap``) and reported on its frame (:attr:`Estimate.gap`). A gap up to
``max_gap`` [s] keeps the estimate valid; a longer one leaves it finite but invalid
(:attr:`Estimate.gap_flush` > 0) until a full window of real readings follows.
- The sensor stays flagged until a full filter window (plus its alignment delay) of good readings
  has flushed the held values. Meanwhile every output that depends on it is NaN and flagged: the
  torque of joint i depends on the encoders of its subtree, its ancestors and the IMU's chain, on
  the IMU, and on the F/T sensors in its subtree (all sensors for the joints between the base and
  the unknown-wrench body). ``Estimate.valid`` is False while anything is flagged, including the
  start-up (filters not yet full).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from servotau.errors import EstimationError
from servotau.hal.types import STATUS_NAMES, RobotInfo, SensorFrame
from servotau.signal.savgol import CausalSavgol, delay

from .config import EstimatorConfig
from .delay_line import DelayLine
from .dynamics import InverseDynamics
from .model import EstimatorModel
from .prediction import ModelPredictor

logger = logging.getLogger(__name__)

_ENC, _IMU = STATUS_NAMES.index("encoders"), STATUS_NAMES.index("imu")


class Estimate:
    """One tick's estimate. A preallocated holder: :meth:`TorqueEstimator.update` overwrites the same
    arrays every tick, so keep :meth:`copy` if the values must outlive the next update.

    Attributes:
        time: [s] instant the estimate refers to (frame time - filter delay).
        seq: Sequence number of the frame that produced it.
        delay: [s] filter delay (frame time - ``time``).
        valid: True if every output below is valid.
        q, dq, ddq: [rad, rad/s, rad/s^2] (n,) filtered joint state, HAL joint order (NaN if flagged).
        tau: [N m] (n,) estimated joint torques (NaN where ``tau_valid`` is False).
        tau_valid: (n,) bool.
        tau_predicted: [N m] (n,) torque predicted to the frame time by the actuator model (NaN for
            joints without motor parameters, or without ``q_des``); see :mod:`.prediction`.
        encoders_valid: (n,) bool, per joint encoder (flushed of bad readings).
        imu_valid: bool.
        wrenches: [N, N m] (n_ft, 6) external wrench the environment exerts on each end effector
            (foot, hand), in the F/T sensor frame at its origin, weight and inertia of the body beyond
            the sensor compensated. Rows in ``RobotInfo.ft_sensor_names`` order (NaN if flagged).
        wrenches_valid: (n_ft,) bool.
        base_wrench: [N, N m] (6,) unknown external wrench on the unknown-wrench body (the torso by
            default: lift strings, pushes), in that body's frame at its origin.
        residual_force, residual_torque: [N], [N m] norms of ``base_wrench``: the health signal
            (should stay near zero when nothing but the end effectors touches the robot).
        base_angular_velocity, base_angular_acceleration: [rad/s, rad/s^2] (3,) waist, waist frame.
        base_specific_force: [m/s^2] (3,) waist acceleration minus gravity, waist frame.
        gap: Frames skipped just before this one (0: none), interpolated in robot time.
        gap_flush: Ticks until the interpolated samples of a gap longer than ``max_gap`` have left the
            filter windows (0: none; ``valid`` is False while > 0, the values stay finite).
    """

    _ARRAYS = ("q", "dq", "ddq", "tau", "tau_valid", "tau_predicted", "encoders_valid", "wrenches",
               "wrenches_valid", "base_wrench", "base_angular_velocity",
               "base_angular_acceleration", "base_specific_force")
    _SCALARS = ("time", "seq", "delay", "valid", "imu_valid", "residual_force", "residual_torque", "gap",
                "gap_flush")
    __slots__ = _ARRAYS + _SCALARS

    def __init__(self, n: int, n_ft: int):
        nan = np.nan
        self.q, self.dq, self.ddq = np.full(n, nan), np.full(n, nan), np.full(n, nan)
        self.tau = np.full(n, nan)
        self.tau_valid = np.zeros(n, dtype=bool)
        self.tau_predicted = np.full(n, nan)
        self.encoders_valid = np.zeros(n, dtype=bool)
        self.wrenches = np.full((n_ft, 6), nan)
        self.wrenches_valid = np.zeros(n_ft, dtype=bool)
        self.base_wrench = np.full(6, nan)
        self.base_angular_velocity = np.full(3, nan)
        self.base_angular_acceleration = np.full(3, nan)
        self.base_specific_force = np.full(3, nan)
        self.time = nan
        self.seq = -1
        self.delay = 0.0
        self.valid = False
        self.imu_valid = False
        self.residual_force = nan
        self.residual_torque = nan
        self.gap = 0
        self.gap_flush = 0

    def copy(self) -> Estimate:
        """An independent copy (new arrays)."""
        out = Estimate.__new__(Estimate)
        for name in self._ARRAYS:
            setattr(out, name, getattr(self, name).copy())
        for name in self._SCALARS:
            setattr(out, name, getattr(self, name))
        return out

    def __repr__(self) -> str:
        return f"Estimate(seq={self.seq}, time={self.time:.4f}, valid={self.valid})"


class _Filter:
    """Alignment delay line and causal SG filter over a slice of the held input vector."""

    def __init__(self, channels: slice, window: int, order: int, derivs: tuple[int, ...], dt: float, eval_at: str,
                 align_delay: int, held: np.ndarray):
        n = channels.stop - channels.start
        self.line = DelayLine(n, align_delay)
        self.sg = CausalSavgol(n, window, order, dt, derivs=derivs, eval_at=eval_at)
        self.input = held[channels]
        self.flush = window + align_delay  # ticks of good readings before the outputs are valid again

    def push(self) -> None:
        self.sg.update(self.line.push(self.input))


class TorqueEstimator:
    """Joint torques, end-effector wrenches and the unknown wrench from one :class:`SensorFrame` per tick.

    Example::

        est = TorqueEstimator(robot.info, EstimatorConfig.from_toml())
        while True:
            e = est.update(backend.read())  # the same Estimate object every tick
            if e.valid:
                use(e.time, e.tau)

    Memory: everything is allocated at construction (one ``pin.Data``, numpy buffers, views into the
    Pinocchio data, the :class:`Estimate`). A normal tick allocates no numpy array of its own; what
    remains is Pinocchio's (``rnea`` returns a copy of tau, ``Motion``/``Force`` temporaries) and
    Python scalars. Ticks with bad readings (flag bookkeeping) may allocate.

    Args:
        info: The robot behind the HAL; joints are matched to the model by name.
        config: Estimator settings (default: config/estimation.toml).
    """

    def __init__(self, info: RobotInfo, config: EstimatorConfig | None = None):
        config = EstimatorConfig.from_toml() if config is None else config
        self.info = info
        self.config = config
        self.robot = EstimatorModel(info, config)
        self.dynamics = InverseDynamics(self.robot, config.angular_acceleration)
        n, nft = self.robot.n, len(self.robot.ft)
        self.n, self.n_ft = n, nft
        dt = info.period
        self.dt = dt
        ev = config.eval_at
        use_alpha = config.angular_acceleration == "savgol"
        settings = {"encoders": config.encoders, "imu": config.imu, "ft": config.ft}
        value_delay = {k: delay(f.window, f.order, 0, ev) for k, f in settings.items()}  # [samples]
        target = max(value_delay.values()) if config.align else 0.0
        align = {k: int(np.floor(target - d + 1e-9)) if config.align else 0 for k, d in value_delay.items()}
        self.delays = {k: value_delay[k] + align[k] for k in settings}  # [samples] of each group's values
        self.delay = max(self.delays.values()) * dt  # [s]
        # Held input vector [q (n), gyro - bias (3), accel (3), wrenches - offsets (6 n_ft)]: the last good
        # reading of every channel, fed to the filters every tick.
        n_in = n + 6 + 6 * nft
        self._raw = np.zeros(n_in)
        self._held = np.zeros(n_in)
        self._raw_q, self._raw_gyro, self._raw_acc = self._raw[:n], self._raw[n : n + 3], self._raw[n + 3 : n + 6]
        self._raw_w = self._raw[n + 6 :].reshape(nft, 6)
        self._held_q = self._held[:n]
        self._held_imu = self._held[n : n + 6]
        self._held_w = self._held[n + 6 :].reshape(nft, 6)
        imu_derivs = (0, 1) if use_alpha else (0,)
        self._enc = _Filter(slice(0, n), config.encoders.window, config.encoders.order, (0, 1, 2), dt, ev,
                            align["encoders"], self._held)
        if config.imu == config.ft and align["imu"] == align["ft"]:  # one filter for both (cheaper)
            self._imu = self._ft = _Filter(slice(n, n_in), config.imu.window, config.imu.order, imu_derivs, dt, ev,
                                           align["imu"], self._held)
            self._filters = (self._enc, self._imu)
            imu_out, ft_out = self._imu.sg.outputs, self._imu.sg.outputs[0][6:]
        else:
            self._imu = _Filter(slice(n, n + 6), config.imu.window, config.imu.order, imu_derivs, dt, ev,
                                align["imu"], self._held)
            self._ft = _Filter(slice(n + 6, n_in), config.ft.window, config.ft.order, (0,), dt, ev, align["ft"],
                               self._held)
            self._filters = (self._enc, self._imu, self._ft)
            imu_out, ft_out = self._imu.sg.outputs, self._ft.sg.outputs[0]
        self._q_f, self._dq_f, self._ddq_f = self._enc.sg.outputs
        self._gyro_f, self._acc_f = imu_out[0][0:3], imu_out[0][3:6]
        self._dgyro_f = imu_out[1][0:3] if use_alpha else np.zeros(3)
        self._ft_f = ft_out.reshape(nft, 6)
        self._gyro_bias = np.array(config.gyro_bias)
        self._ft_offsets = np.array(config.ft_offsets)
        if self._ft_offsets.shape != (nft, 6):
            raise EstimationError(f"ft_offsets has shape {self._ft_offsets.shape}: expected ({nft}, 6)")
        self.predictor = ModelPredictor(info.joint_names, config.prediction, dt, config.encoders.window,
                                        config.encoders.order, ev, align["encoders"])
        self._dep_enc, self._dep_ft, self._ft_dep_enc = self.robot.dependencies()
        self._enc_count = np.full(n, self._enc.flush, dtype=np.int64)
        self._imu_count = self._imu.flush
        self._ft_count = np.full(nft, self._ft.flush, dtype=np.int64)
        self._pending = True
        self._last_seq = -1
        self._gap_flush = 0  # ticks until a long gap's interpolated samples have left the windows
        self._max_gap = int(math.floor(config.max_gap / dt + 1e-9))  # [frames]
        self._before_gap = np.zeros(n_in)
        self.gaps = 0  # gaps (jumps of frame.seq) so far
        self.missing_frames = 0  # frames skipped in them
        self.longest_gap = 0  # [frames]
        self._nan_tau = np.zeros(n, dtype=bool)
        self.estimate = Estimate(n, nft)
        self.estimate.delay = self.delay
        dyn = self.dynamics  # the dynamics writes straight into the Estimate's arrays
        dyn.bind_outputs(tau=self.estimate.tau, wrenches=self.estimate.wrenches,
                         base_wrench=self.estimate.base_wrench,
                         base_angular_velocity=self.estimate.base_angular_velocity,
                         base_angular_acceleration=self.estimate.base_angular_acceleration,
                         base_specific_force=self.estimate.base_specific_force)

    # -- calibration at run time -----------------------------------------------------------------
    def set_ft_offsets(self, offsets: np.ndarray) -> None:
        """Replace the F/T offsets [N, N m] (n_ft, 6), subtracted from every new reading."""
        offsets = np.asarray(offsets, dtype=float)
        if offsets.shape != self._ft_offsets.shape or not np.all(np.isfinite(offsets)):
            raise EstimationError(f"offsets: expected finite {self._ft_offsets.shape}, got {offsets.shape}")
        self._ft_offsets[:] = offsets

    @property
    def ft_offsets(self) -> np.ndarray:
        return self._ft_offsets.copy()

    # -- the hot path -----------------------------------------------------------------------------
    def update(self, frame: SensorFrame, q_des: np.ndarray | None = None) -> Estimate:
        """Process one frame and return the (preallocated, overwritten) :class:`Estimate`.

        Args:
            frame: The newest sensor frame (one per period, in sequence).
            q_des: [rad] (n,) optional command the servo was tracking when ``frame`` was measured, for
                the model-based prediction (:attr:`Estimate.tau_predicted`).
        """
        seq = frame.seq
        missing = 0
        if seq != self._last_seq + 1 and self._last_seq >= 0:
            if seq <= self._last_seq:
                raise EstimationError(f"frame seq {seq} after {self._last_seq}: expected increasing sequence "
                                      "numbers")
            missing = seq - self._last_seq - 1
            np.copyto(self._before_gap, self._held)
        self._last_seq = seq
        raw, status = self._raw, frame.status
        try:
            np.copyto(self._raw_q, frame.q)
            np.subtract(frame.imu_angular_velocity, self._gyro_bias, out=self._raw_gyro)
            np.copyto(self._raw_acc, frame.imu_linear_acceleration)
            np.subtract(frame.wrenches, self._ft_offsets, out=self._raw_w)
        except ValueError as err:
            raise EstimationError(
                f"frame {seq}: expected q ({self.n},), IMU (3,) + (3,) and wrenches ({self.n_ft}, 6): {err}"
            ) from err
        if status.any() or not math.isfinite(raw.sum()):  # a sum is finite iff every term is (no overflow here)
            self._hold_good(status)
        else:
            np.copyto(self._held, raw)
        out = self.estimate
        out.gap = missing
        if missing:
            self._fill_gap(missing, frame)
        for f in self._filters:
            f.push()
        self.predictor.update(self._held_q, q_des)
        out.time = frame.time - self.delay
        out.seq = frame.seq
        if self._pending:
            self._refresh_validity()
        if not self._enc.sg.ready:  # every filter is as long as its flush count: ready together with it
            return out
        if not (self._imu.sg.ready and self._ft.sg.ready):
            return out
        self.dynamics.compute(self._q_f, self._dq_f, self._ddq_f, self._gyro_f, self._dgyro_f, self._acc_f,
                              self._ft_f)
        np.copyto(out.q, self._q_f)
        np.copyto(out.dq, self._dq_f)
        np.copyto(out.ddq, self._ddq_f)
        bw = out.base_wrench
        out.residual_force = math.sqrt(np.dot(bw[0:3], bw[0:3]))
        out.residual_torque = math.sqrt(np.dot(bw[3:6], bw[3:6]))
        if not out.valid:
            self._mask_invalid(out)
        if self.predictor.n:
            self.predictor.predict(out.tau, out.tau_predicted)
        return out

    # -- input conditioning (only when a reading is bad or frames are missing) ------------------------
    def _fill_gap(self, missing: int, frame: SensorFrame) -> None:
        """``missing`` frames before ``frame`` never arrived: push, for each missing tick, the linear
        interpolation between the inputs before the gap and those of ``frame`` (already in ``_held``), so the
        filters stay on the robot's time grid with finite, continuous values; count and report the gap."""
        held, before = self._held, self._before_gap
        after = held.copy()
        step = (after - before) / (missing + 1)
        longest = max(f.flush for f in self._filters)
        first = max(1, missing - longest + 1)  # the earlier samples would leave every window before this frame
        for j in range(first, missing + 1):
            np.multiply(step, j, out=held)
            held += before
            for f in self._filters:
                f.push()
            self.predictor.update(self._held_q, None)
        np.copyto(held, after)
        self.gaps += 1
        self.missing_frames += missing
        self.longest_gap = max(self.longest_gap, missing)
        if missing > self._max_gap:
            self._gap_flush = longest
            self._pending = True
            logger.warning("%d frames skipped before frame %d (t = %.3f s), more than max_gap = %.3f s: the estimate "
                           "is invalid for the next %d ticks", missing, frame.seq, frame.time,
                           self.config.max_gap, longest)
        else:
            logger.debug("%d frames skipped before frame %d (t = %.3f s): interpolated", missing, frame.seq,
                         frame.time)

    def _hold_good(self, status: np.ndarray) -> None:
        """Copy the good readings of ``_raw`` into ``_held``, keep the last good ones elsewhere, flag."""
        q = self._raw_q
        fin = np.isfinite(q)
        bad = ~fin if status[_ENC] == 0 else np.ones(self.n, dtype=bool)
        self._held_q[~bad] = q[~bad]
        if bad.any():
            self._enc_count[bad] = self._enc.flush
            self._pending = True
        imu = self._raw[self.n : self.n + 6]
        if status[_IMU] == 0 and np.isfinite(imu).all():
            np.copyto(self._held_imu, imu)
        else:
            self._imu_count = self._imu.flush
            self._pending = True
        for s in range(self.n_ft):
            w = self._raw_w[s]
            if status[2 + s] == 0 and np.isfinite(w).all():
                self._held_w[s] = w
            else:
                self._ft_count[s] = self._ft.flush
                self._pending = True

    # -- validity (only while something is flagged) ---------------------------------------------------
    def _refresh_validity(self) -> None:
        out = self.estimate
        enc_bad = self._enc_count > 0
        ft_bad = self._ft_count > 0
        imu_bad = self._imu_count > 0
        np.logical_not(enc_bad, out=out.encoders_valid)
        out.imu_valid = not imu_bad
        tau_bad = (self._dep_enc & enc_bad).any(axis=1) | (self._dep_ft & ft_bad).any(axis=1) | imu_bad
        np.logical_not(tau_bad, out=out.tau_valid)
        w_bad = ft_bad | (self._ft_dep_enc & enc_bad).any(axis=1) | imu_bad
        np.logical_not(w_bad, out=out.wrenches_valid)
        out.gap_flush = self._gap_flush
        out.valid = not (tau_bad.any() or w_bad.any() or self._gap_flush)
        # Re-evaluate next tick while anything was flagged this tick (then once more to clear the flags).
        self._pending = bool(enc_bad.any() or ft_bad.any() or imu_bad or self._gap_flush)
        self._gap_flush = max(self._gap_flush - 1, 0)
        self._enc_count -= 1
        np.maximum(self._enc_count, 0, out=self._enc_count)
        self._ft_count -= 1
        np.maximum(self._ft_count, 0, out=self._ft_count)
        self._imu_count = max(self._imu_count - 1, 0)

    def _mask_invalid(self, out: Estimate) -> None:
        """NaN where a sensor is bad (a long gap alone leaves the interpolated values finite)."""
        np.logical_not(out.tau_valid, out=self._nan_tau)
        out.tau[self._nan_tau] = np.nan
        bad_enc = ~out.encoders_valid
        out.q[bad_enc] = np.nan
        out.dq[bad_enc] = np.nan
        out.ddq[bad_enc] = np.nan
        bad_ft = ~out.wrenches_valid
        out.wrenches[bad_ft] = np.nan
        if not (out.tau_valid.all() and out.wrenches_valid.all()):
            out.base_wrench[:] = np.nan  # the unknown wrench uses every input
            out.residual_force = out.residual_torque = np.nan
        if not out.imu_valid:
            out.base_angular_velocity[:] = np.nan
            out.base_angular_acceleration[:] = np.nan
            out.base_specific_force[:] = np.nan
