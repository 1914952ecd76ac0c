"""Real-time scheduling of a HAL process (Linux SCHED_FIFO), as a robot's control loop runs.

On a loaded machine an ordinary process waits for the CPU for whole time slices (milliseconds): the
1 kHz loop then misses ticks. Under SCHED_FIFO a runnable thread preempts ordinary ones. The
priority is set on the calling thread *before* the Zenoh session opens, so that zenoh's I/O and
callback threads, created afterwards, inherit it. The kernel keeps 5 % of each second for
ordinary processes (``/proc/sys/kernel/sched_rt_runtime_us``), so a runaway loop cannot lock the
machine up. It needs root or CAP_SYS_NICE; without them the process warns and runs normally.
"""

from __future__ import annotations

import logging
import os

from ..errors import HalError

logger = logging.getLogger(__name__)


def check_priority(priority: int, field: str = "realtime_priority") -> int:
    """``priority`` if it is 0 (ordinary scheduling) or a SCHED_FIFO priority 1..99, else :class:`HalError`."""
    if isinstance(priority, bool) or not isinstance(priority, int) or not 0 <= priority <= 99:
        raise HalError(f"{field} = {priority!r}: expected 0 (ordinary scheduling) or a SCHED_FIFO priority 1..99")
    return priority


def set_realtime_priority(priority: int) -> bool:
    """Run the calling thread, and the threads it starts later, under SCHED_FIFO ``priority`` (1..99;
    0 does nothing). Returns whether the policy is in effect; a refusal is logged, never raised."""
    if not check_priority(priority):
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        logger.warning("realtime_priority %d: SCHED_FIFO refused (%s); running with ordinary scheduling "
                       "(run as root or grant CAP_SYS_NICE)", priority, exc)
        return False
    logger.info("SCHED_FIFO priority %d (this thread and the threads it starts)", priority)
    return True


_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30  # linux/prctl.h


def set_timer_slack(ns: int) -> bool:
    """Let the kernel wake the calling thread's sleeps at most ``ns`` [ns] late (Linux's default:
    50 us; SCHED_FIFO threads have none). Returns whether it took effect; elsewhere it does nothing."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def timer_slack() -> int | None:
    """The calling thread's timer slack [ns] (Linux), or None where it cannot be read."""
    import ctypes

    try:
        value = ctypes.CDLL(None, use_errno=True).prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
    except (OSError, AttributeError):
        return None
    return value if value >= 0 else None
