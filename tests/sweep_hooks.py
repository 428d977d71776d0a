"""Test-only `before_run` hooks for cdpm_drake.runs.sweep, passed as parameters (never switched on
by the environment). Module-level, so a spawned worker or a Ray worker can unpickle them."""

import os
import signal
import time


def kill_worker_if(field, value, task):
    """The worker kills itself (SIGKILL, like the OOM killer) on the run where field == value."""
    if task.values.get(field) == value:
        os.kill(os.getpid(), signal.SIGKILL)


def raise_if(field, value, task):
    """The run where field == value fails with an exception, as a diverging run would."""
    if task.values.get(field) == value:
        raise RuntimeError(f"injected failure at {field} = {value}")


def signal_parent_if(field, value, signum, task):
    """Signal the sweep's parent process when the run where field == value starts, then hang so
    that run never finishes: until the parent stops the worker or, killed outright, is gone
    (the worker is then reparented) or 30 s have passed."""
    if task.values.get(field) == value:
        parent = os.getppid()
        os.kill(parent, signum)
        deadline = time.monotonic() + 30.0
        while os.getppid() == parent and time.monotonic() < deadline:
            time.sleep(0.05)
        os._exit(1)
