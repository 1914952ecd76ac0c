"""A test controller: sinusoids around the first measured posture, over any HAL backend.

As a script it connects over Zenoh and exits with code 4 and a clear message if the robot is lost.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from servotau.errors import HalError
from servotau.hal import Backend, LogWriter


def run(backend: Backend, ticks: int, amplitude: float = 0.2, frequency: float = 1.0, log: str | None = None,
        on_tick=None) -> int:
    """``ticks`` read/write cycles of q_des = q0 + amplitude sin(2 pi f t) on every joint; returns ticks done."""
    writer = LogWriter(log, backend.info, truth=False, extra=[]) if log else None
    try:
        frame = backend.read()
        q0 = frame.q.copy()
        for k in range(ticks):
            if k:
                frame = backend.read()
            q_des = q0 + amplitude * np.sin(2 * np.pi * frequency * frame.time)
            backend.write(dict(zip(backend.info.joint_names, q_des, strict=True)))
            if writer is not None:
                writer.append(frame, q_des)
            if on_tick is not None:
                on_tick(k, frame)
        return ticks
    finally:
        if writer is not None:
            writer.close()


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--robot", default="fake")
    p.add_argument("--ticks", type=int, default=10_000)
    p.add_argument("--amplitude", type=float, default=0.2)
    p.add_argument("--log")
    p.add_argument("--announce", type=int, default=0, help="print 'running' after this many ticks")
    p.add_argument("--frame-timeout", type=float, default=5.0,
                   help="[s] read timeout: a safety net only (a robot process descheduled on a loaded machine is "
                        "not a hung robot; a killed one is seen by its liveliness token)")
    a = p.parse_args()
    from servotau.hal import ZenohBackend

    def on_tick(k, frame):
        if a.announce and k == a.announce:
            print("running", flush=True)

    backend = None
    try:
        backend = ZenohBackend(a.robot, connect=[a.connect], frame_timeout=a.frame_timeout)
        run(backend, a.ticks, a.amplitude, log=a.log, on_tick=on_tick)
    except HalError as exc:
        print(json.dumps({"t_detect": time.monotonic(), "error": type(exc).__name__}), flush=True)
        print(f"servotau control: {exc}", file=sys.stderr)
        return 4
    finally:
        if backend is not None:
            backend.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
