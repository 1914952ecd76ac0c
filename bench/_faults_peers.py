"""Zenoh peers and process helpers of bench/faults.py: a peer of our own on the robot's endpoint (frames, status,
claim, raw commands), the malformed-command generator, the robot and controller processes, and the robot-log
analyses. Everything on 127.0.0.1; every process in its own process group, killed on exit."""

from __future__ import annotations

import getpass
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import zenoh

from servotau.apps.processes import free_port, wait_ready
from servotau.hal import keys
from servotau.hal.robot.claim import claim_key, claim_reply, claim_request, token_key
from servotau.hal.wire.protocol import (
    FLAG_HOLDING,
    FLAG_SERVO_OFF,
    FLAG_WAITING,
    HEADER,
    HEADER_SIZE,
    MAGIC,
    PROTOCOL_VERSION,
    MsgType,
    encode_command,
    info_from_json,
)
from servotau.hal.wire.session import Session, callback, zenoh_config

ROOT = Path(__file__).resolve().parent.parent
FAKE = "servotau.simrobot.fake:FakeRobot"
SERVOTAU = [sys.executable, "-c", "import sys; from servotau.cli import main; sys.exit(main())"]  # the CLI
SIM = "servotau.simrobot.sim:SimRobot.from_config"
RUNNING_STATE = 1.0  # FirmwareState.RUNNING in the robot log's hal/state column


def progress(msg: str) -> None:
    print(f"[faults {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------- processes

def spawn(args: list[str], out: Path, **kw) -> subprocess.Popen:
    """A child process in its own process group (stdout and stderr to ``out``)."""
    with open(out, "w") as f:
        return subprocess.Popen(args, stdout=f, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT, **kw)


def kill_group(p: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int | None:
    """Signal ``p``'s process group (``sig``, then SIGKILL after ``timeout`` [s]); its exit code."""
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGCONT)
            os.killpg(p.pid, sig)
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        except ProcessLookupError:
            pass
    return p.wait()


@contextmanager
def _served(args: list[str], out: Path, ready: Path, what: str):
    """The process of ``args`` (output to ``out``), once it touched ``ready``; its process group killed at the end."""
    p = spawn(args, out)
    try:
        wait_ready(p, ready, 60.0, f"{what}: {out}")
        yield p
    finally:
        kill_group(p)


@contextmanager
def robot_process(tmp: Path, *, robot: str = FAKE, clock: str = "lockstep", log: Path | None = None,
                  safety: dict | None = None, kwargs: dict | None = None, scenario: str | None = None,
                  security: Path | None = None, tls: bool = False, name: str | None = None):
    """``python -m servotau.hal`` on 127.0.0.1 (a free port): yields ``(process, endpoint)``; SIGTERM at the end
    (the robot's log is then complete)."""
    port = free_port()
    ep = f"{'tls' if tls else 'tcp'}/127.0.0.1:{port}"
    ready = tmp / f"ready-{port}"
    args = [sys.executable, "-m", "servotau.hal", "--robot", robot, "--listen", ep, "--clock", clock,
            "--ready-file", str(ready), "--no-truth", "--kwargs", json.dumps(kwargs or {})]
    args += ["--scenario", scenario] if scenario else []
    args += ["--log", str(log)] if log else []
    args += ["--safety", json.dumps(safety)] if safety else []
    args += ["--security", str(security)] if security else []
    args += ["--name", name] if name else []
    with _served(args, tmp / f"robot-{port}.out", ready, f"robot process ({' '.join(args)})") as p:
        yield p, ep


@contextmanager
def sim_process(tmp: Path, *, clock: str = "lockstep", log: Path | None = None, config: Path | None = None,
                hal: Path | None = None):
    """``servotau sim`` (the simulated HRP-2) on 127.0.0.1: yields ``(process, port)``."""
    port = free_port()
    ready = tmp / f"ready-{port}"
    args = [*SERVOTAU, "sim", "--port", str(port), "--clock", clock, "--ready-file", str(ready)]
    args += ["--log", str(log)] if log else []
    args += ["--config", str(config)] if config else []
    args += ["--hal", str(hal)] if hal else []
    with _served(args, tmp / f"sim-{port}.out", ready, "servotau sim") as p:
        yield p, port


def sim_config_with_faults(tmp: Path, start: float, duration: float) -> Path:
    """A copy of config/sim.toml whose sensors file has NaN encoders from ``start`` for ``duration`` [s]."""
    cfg = ROOT / "config"
    sensors = tmp / f"sensors-nan-{start}-{duration}.toml"
    sensors.write_text((cfg / "sensors.toml").read_text()
                       + f'\n[[faults]]\nsensor = "encoders"\nkind = "nan"\nstart = {start}\nduration = {duration}\n')
    sim = tmp / f"sim-nan-{start}-{duration}.toml"
    sim.write_text(f'scenario = "{cfg / "scenarios" / "hanging.toml"}"\nservo = "{cfg / "servo.toml"}"\n'
                   f'sensors = "{sensors}"\nseed = 0\n')
    return sim


def control_process(tmp: Path, port: int, *extra: str, tag: str = "control", hal: Path | None = None) \
        -> subprocess.Popen:
    """``servotau control --port PORT`` (its output in ``tmp/<tag>-<port>.out``)."""
    args = [*SERVOTAU, "control", "--port", str(port), *extra]
    args += ["--hal", str(hal)] if hal else []
    return spawn(args, tmp / f"{tag}-{port}.out")


# ---------------------------------------------------------------------------------------------- the peer

class Peer:
    """A Zenoh session of our own connected to the robot: watches every frame (header and encoders, wall time of
    arrival, in zenoh's network thread), queries status and info, claims, and puts raw command payloads."""

    def __init__(self, robot: str, endpoint: str, security=None, keep: int = 4096):
        self.k = keys(robot)
        self.session = Session(zenoh_config(connect=[endpoint], security=security))
        self.z = self.session.z
        self._cond = threading.Condition()
        self.keep = keep
        self.frames: dict[int, float] = {}  # seq -> robot time [s] of the last ``keep`` frames
        self.newest: tuple | None = None  # (seq, time [s], flags, q [rad], wall time of arrival [s])
        self.n_frames = 0
        self._watch: tuple[int, float] | None = None  # (flag mask, from wall time [s])
        self.watch_hit: float | None = None  # wall time [s] of the first frame matching the watch
        self.token: bytes | None = None
        self._pub = None
        self.on_frame = None  # called with (seq, time, flags, q) after recording (zenoh's network thread)
        self.session.keep(self.z.declare_subscriber(self.k.frame, callback(self._frame, direct=True)))

    def _frame(self, sample: zenoh.Sample) -> None:
        t = time.monotonic()
        buf = sample.payload.to_bytes()
        if len(buf) < HEADER_SIZE:
            return
        _, _, mtype, flags, seq, ftime, n, _, _ = HEADER.unpack_from(buf)
        if mtype != MsgType.FRAME:
            return
        q = np.frombuffer(buf, "<f8", n, HEADER_SIZE).copy()
        with self._cond:
            self.frames[seq] = ftime
            if len(self.frames) > self.keep:
                self.frames.pop(next(iter(self.frames)))
            if self.newest is None or seq >= self.newest[0]:
                self.newest = (seq, ftime, flags, q, t)
            self.n_frames += 1
            if self._watch is not None and self.watch_hit is None and flags & self._watch[0] and t >= self._watch[1]:
                self.watch_hit = t
            self._cond.notify_all()
        if self.on_frame is not None:
            self.on_frame(seq, ftime, flags, q)

    def watch(self, mask: int, since: float) -> None:
        """Record the wall time of the first frame with a flag of ``mask`` arriving after ``since``."""
        with self._cond:
            self._watch, self.watch_hit = (mask, since), None

    def wait(self, predicate, timeout: float) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    def next_frame(self, after: int, timeout: float = 10.0) -> tuple | None:
        """The newest frame with a seq above ``after`` (None after ``timeout`` [s])."""
        with self._cond:
            ok = self._cond.wait_for(lambda: self.newest is not None and self.newest[0] > after, timeout)
            return self.newest if ok else None

    def query(self, key: str, payload: bytes | None = None, timeout: float = 5.0) -> bytes | None:
        for r in self.z.get(key, payload=payload, timeout=timeout):
            if r.ok is not None:
                return r.ok.payload.to_bytes()
        return None

    def status(self) -> dict:
        body = self.query(self.k.status)
        if body is None:
            raise RuntimeError(f"the robot did not answer {self.k.status}")
        return json.loads(body)

    def info(self):
        return info_from_json(self.query(self.k.info))

    def claim(self) -> bytes:
        """Claim the robot as a controller does (its zid token, then the claim query): the token."""
        zid = str(self.z.zid())
        self.session.keep(self.z.liveliness().declare_token(token_key(self.k.alive_controller, zid)))
        reply = self.query(claim_key(self.k.prefix), claim_request(zid, socket.gethostname(), os.getpid(),
                                                                 getpass.getuser()))
        if reply is None:
            raise RuntimeError("no answer to the claim (access control dropped it?)")
        self.token = claim_reply(reply, self.k.prefix.rsplit("/", 1)[-1])
        return self.token

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        if self._pub is None:
            self._pub = self.session.keep(self.z.declare_publisher(
                self.k.command, express=True, congestion_control=zenoh.CongestionControl.BLOCK,
                priority=zenoh.Priority.REAL_TIME))
            # let the publisher find the robot's subscriber (access control may hide it: then put after 2 s)
            deadline = time.monotonic() + 2.0
            while not self._pub.matching_status.matching and time.monotonic() < deadline:
                time.sleep(0.01)
        self._pub.put(payload, attachment=attachment)

    def close(self) -> None:
        self.session.close()


def wait_status(peer: Peer, until, timeout: float = 30.0) -> dict:
    """The robot's status once ``until(status)`` holds (or the last one after ``timeout`` [s])."""
    deadline = time.monotonic() + timeout
    while True:
        st = peer.status()
        if until(st) or time.monotonic() > deadline:
            return st
        time.sleep(0.02)


# ---------------------------------------------------------------------------------------------- fuzz

def malformed_commands(n: int, n_joints: int, seq: int, t: float, q: np.ndarray, rng: np.random.Generator):
    """``n`` malformed commands for a robot whose current frame is ``(seq, t)``, each with one defect (or random
    bytes), round-robin over the kinds: yields ``(kind, payload)``."""
    good = encode_command(seq, t, q)

    def header(magic=MAGIC, version=PROTOCOL_VERSION, mtype=int(MsgType.COMMAND), flags=0, s=seq, tt=t, nj=n_joints,
               nft=0, nv=n_joints, body=None):
        return HEADER.pack(magic, version, mtype, flags, s, tt, nj, nft, nv) + (q.tobytes() if body is None else body)

    def bad_values():
        v = q.copy()
        idx = rng.choice(n_joints, size=rng.integers(1, 4), replace=False)
        v[idx] = rng.choice([np.nan, np.inf, -np.inf], size=idx.size)
        return header(body=v.astype("<f8").tobytes())

    def bad_time():
        tt = float(rng.choice([np.nan, np.inf, -np.inf, t + 1e-3, t - 1e-3, t + 1.0, -1.0, 1e300,
                               np.nextafter(t, np.inf)]))
        return header(tt=tt)

    kinds = {
        "random_bytes": lambda: rng.bytes(int(rng.integers(0, 600))),
        "random_after_header": lambda: good[:8] + rng.bytes(int(rng.integers(0, 24 + 16 * n_joints))),
        "truncated": lambda: good[:int(rng.integers(0, len(good)))],
        "extended": lambda: good + rng.bytes(int(rng.integers(1, 17))),
        "magic": lambda: header(magic=bytes(rng.integers(0, 256, 4, dtype=np.uint8)).replace(b"S", b"s")),
        "version": lambda: header(version=int(rng.choice([0, *range(2, 256)]))),
        "type": lambda: header(mtype=int(rng.choice([0, 1, 3, *range(4, 256)]))),
        "n_joints": lambda: header(nj=int(rng.choice([0, n_joints - 1, n_joints + 1, 65535]))),
        "n_ft": lambda: header(nft=int(rng.integers(1, 65536))),
        "n_values": lambda: header(nv=[0, n_joints - 1, n_joints + 1, 2**32 - 1][int(rng.integers(4))]),
        "values_nan_inf": bad_values,
        "time": bad_time,
        # any bit beyond COMMAND_HOLD (bit 0, a valid hold command)
        "flags": lambda: header(flags=int(rng.choice([0xFFFF, 2, 3, 0x8000, int(rng.integers(1, 32768)) << 1]))),
        "future_seq": lambda: header(s=[seq + 1, seq + 1000, 2**63, 2**64 - 1][int(rng.integers(4))]),
    }
    names = list(kinds)
    for i in range(n):
        kind = names[i % len(names)]
        yield kind, kinds[kind]()


# ---------------------------------------------------------------------------------------------- logs

def over_limit(q_des: np.ndarray, state: np.ndarray, period: float, v_max: float, a_max: float) -> dict:
    """Applied commands (robot-log rows in state RUNNING after a finite row) whose q_des velocity or acceleration,
    tick to tick, exceeds ``v_max`` [rad/s] / ``a_max`` [rad/s^2] on some joint."""
    v = np.diff(q_des, axis=0) / period  # v[k-1]: row k - row k-1
    a = np.diff(v, axis=0) / period
    run = (state[1:] == RUNNING_STATE) & np.isfinite(v).all(axis=1)
    run_a = run[1:] & run[:-1]
    v_abs = np.abs(np.where(run[:, None], v, 0.0))
    a_abs = np.abs(np.where(run_a[:, None], a, 0.0))
    tol = 1e-6
    return {"applied": int(run.sum()),
            "over_velocity": int((v_abs > v_max * (1 + tol)).any(axis=1).sum()),
            "over_acceleration": int((a_abs > a_max * (1 + tol)).any(axis=1).sum()),
            "max_velocity_rad_s": float(v_abs.max(initial=0.0)),
            "max_acceleration_rad_s2": float(a_abs.max(initial=0.0))}


__all__ = ["FLAG_HOLDING", "FLAG_SERVO_OFF", "FLAG_WAITING", "Peer", "control_process", "kill_group",
           "malformed_commands", "over_limit", "progress", "robot_process", "sim_config_with_faults",
           "sim_process", "spawn", "wait_status"]
