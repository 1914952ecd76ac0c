"""The floor under the HAL's round trip: a bare Zenoh Python ping-pong between two processes.

A helper that bench/hal.py starts twice (robot and controller roles), not a benchmark of its own: `make bench`
skips the bench/_*.py helpers.

Same session settings as the HAL (hal/wire/session.py: loopback, express publishers, REAL_TIME
priority, the HAL's GIL switch interval) and the same payload sizes (a 30-joint frame and
command), but no decoding, firmware, robot or bookkeeping. The "robot" publishes a ping and sends
the next one from the callback that receives the pong (as the HAL server ticks in its command
callback). Two threading patterns:

- ``channel`` (the HAL's): the robot's callback runs in zenoh's network thread (``direct``), the
  controller's main thread takes each ping from a ring channel (as ``ZenohBackend.read``);
- ``threads`` (the HAL before): both callbacks run in zenoh-python's callback thread and the
  controller hands each ping to its main thread through a ``threading.Condition``.

bench/hal.py reports the HAL's round trip as a ratio to ``channel``, measured in the same run, and
``threads`` as a ratio to ``channel`` (what the channel pattern saves). The robot also reports its
process's CPU time per round trip (all threads, zenoh's included).

    python bench/_zenoh_pingpong.py robot PORT N [channel|threads]   # prints {"rtt_p50_us": ..., "cpu_us_per_rt": ...}
    python bench/_zenoh_pingpong.py controller PORT N [channel|threads]
"""

from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np
import zenoh

from servotau.hal.wire.session import Session, callback, zenoh_config

FRAME_BYTES, COMMAND_BYTES, WARMUP = 518, 272, 200
PATTERNS = ("channel", "threads")


def _publisher(s: Session, key: str):
    return s.keep(s.z.declare_publisher(key, express=True, congestion_control=zenoh.CongestionControl.BLOCK,
                                        priority=zenoh.Priority.REAL_TIME))


def robot(port: int, n: int, pattern: str) -> dict:
    s = Session(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"]))
    pub, ping = _publisher(s, "bench/ping"), bytes(FRAME_BYTES)
    rtt, t_sent, done, cpu = [], [0.0], threading.Event(), [0.0, 0.0]

    def on_pong(_sample) -> None:
        rtt.append(time.perf_counter() - t_sent[0])
        if len(rtt) == WARMUP:
            cpu[0] = time.process_time()
        if len(rtt) >= n + WARMUP:
            cpu[1] = time.process_time()
            done.set()
            return
        t_sent[0] = time.perf_counter()
        pub.put(ping)

    s.keep(s.z.declare_subscriber("bench/pong", callback(on_pong, direct=pattern == "channel")))
    while not pub.matching_status.matching:  # the controller subscribed
        time.sleep(0.01)
    time.sleep(0.2)
    t_sent[0] = time.perf_counter()
    pub.put(ping)
    done.wait(120)
    s.close()
    r = np.array(rtt[WARMUP:]) * 1e6
    return {"rtt_p50_us": float(np.percentile(r, 50)), "rtt_p99_us": float(np.percentile(r, 99)),
            "cpu_us_per_rt": (cpu[1] - cpu[0]) / n * 1e6}


def controller(port: int, n: int, pattern: str) -> None:
    s = Session(zenoh_config(connect=[f"tcp/127.0.0.1:{port}"]))
    pub, pong = _publisher(s, "bench/pong"), bytes(COMMAND_BYTES)
    if pattern == "channel":
        pings = s.keep(s.z.declare_subscriber("bench/ping", zenoh.handlers.RingChannel(64)))
        for _ in range(n + WARMUP):
            pings.recv().payload.to_bytes()
            pub.put(pong)
    else:
        cond, box = threading.Condition(), []

        def on_ping(sample) -> None:
            buf = sample.payload.to_bytes()
            with cond:
                box.append(buf)
                cond.notify()

        s.keep(s.z.declare_subscriber("bench/ping", callback(on_ping)))
        for _ in range(n + WARMUP):
            with cond:
                if not cond.wait_for(lambda: box, 10.0):
                    break
                box.clear()
            pub.put(pong)
    s.close()


if __name__ == "__main__":
    role, port, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    pattern = sys.argv[4] if len(sys.argv) > 4 else "channel"
    if pattern not in PATTERNS:
        sys.exit(f"pattern {pattern!r}: expected one of {list(PATTERNS)}")
    if role == "robot":
        print(json.dumps(robot(port, count, pattern)), flush=True)
    else:
        controller(port, count, pattern)
