"""Real-time scheduling for the control loop and the emulator (Linux, no Drake here).

A 500 Hz loop with a 3-tick watchdog tolerates about 4 ms of scheduling delay. Under the
default scheduler a busy host delays a sleeping thread by more than that now and then
(measured on a shared 2-core VM: 8 ms), which the watchdog rightly treats as a dead link.
SCHED_FIFO puts the process ahead of every normal one; it needs root or CAP_SYS_NICE.
"""

import os


class PriorityError(OSError):
    """The real-time priority could not be set; the message says why and what to do."""


def set_realtime_priority(priority: int) -> None:
    """Run this process (and the threads and children it starts later) under SCHED_FIFO at
    `priority` (1..99; 0 leaves the scheduling alone)."""
    if not (isinstance(priority, int) and 0 <= priority <= 99):
        raise ValueError(f"rt_priority must be an integer in 0..99 (0: normal scheduling), "
                         f"got {priority!r}")
    if priority == 0:
        return
    if not hasattr(os, "sched_setscheduler"):
        raise PriorityError("real-time priority needs Linux (os.sched_setscheduler)")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        raise PriorityError(f"cannot set SCHED_FIFO priority {priority}: run as root, grant "
                            f"CAP_SYS_NICE, or raise `ulimit -r`") from None
