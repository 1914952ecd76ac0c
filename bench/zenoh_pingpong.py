"""The floor under the HAL's round trip: a bare Zenoh Python ping-pong between two processes.

Same session settings as the HAL (hal/zenoh_session.py: loopback, express publishers, REAL_TIME
priority, the HAL's GIL switch interval) and the same payload sizes (a 30-joint frame and
command), but no decoding, firmware, robot or bookkeeping. The "robot" publishes a ping and sends
the next one from the callback that receives the pong (as the HAL server ticks in its command
callback); the "controller" hands each ping from its callback thread to its main thread, which
answers (as ``ZenohBackend.read``/``write`` do). bench/hal.py reports the HAL's round trip as a
ratio to this one, measured in the same run.

    python bench/zenoh_pingpong.py robot PORT N     # prints {"rtt_p50_us": ..., "rtt_p99_us": ...}
    python bench/zenoh_pingpong.py controller PORT N
"""

from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np
import zenoh

from servotau.hal.zenoh_session import Session, zenoh_config

FRAME_BYTES, COMMAND_BYTES, WARMUP = 518, 272, 200


def _publisher(s: Session, key: str):
    return s.keep(s.z.declare_publisher(key, express=True, congestion_control=zenoh.CongestionControl.BLOCK,
                                        priority=zenoh.Priority.REAL_TIME))


def robot(port: int, n: int) -> dict:
    s = Session(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"]))
    pub, ping = _publisher(s, "bench/ping"), bytes(FRAME_BYTES)
    rtt, t_sent, done = [], [0.0], threading.Event()

    def on_pong(_sample) -> None:
        rtt.append(time.perf_counter() - t_sent[0])
        if len(rtt) >= n + WARMUP:
            done.set()
            return
        t_sent[0] = time.perf_counter()
        pub.put(ping)

    s.keep(s.z.declare_subscriber("bench/pong", zenoh.handlers.Callback(on_pong)))
    while not pub.matching_status.matching:  # the controller subscribed
        time.sleep(0.01)
    time.sleep(0.2)
    t_sent[0] = time.perf_counter()
    pub.put(ping)
    done.wait(120)
    s.close()
    r = np.array(rtt[WARMUP:]) * 1e6
    return {"rtt_p50_us": float(np.percentile(r, 50)), "rtt_p99_us": float(np.percentile(r, 99))}


def controller(port: int, n: int) -> None:
    s = Session(zenoh_config(connect=[f"tcp/127.0.0.1:{port}"]))
    pub, pong = _publisher(s, "bench/pong"), bytes(COMMAND_BYTES)
    cond, box = threading.Condition(), []

    def on_ping(sample) -> None:
        buf = sample.payload.to_bytes()
        with cond:
            box.append(buf)
            cond.notify()

    s.keep(s.z.declare_subscriber("bench/ping", zenoh.handlers.Callback(on_ping)))
    for _ in range(n + WARMUP):
        with cond:
            if not cond.wait_for(lambda: box, 10.0):
                break
            box.clear()
        pub.put(pong)
    s.close()


if __name__ == "__main__":
    role, port, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    if role == "robot":
        print(json.dumps(robot(port, count)), flush=True)
    else:
        controller(port, count)
