"""SIGTERM handled like Ctrl-C, and the exit codes of an interrupted command.

A batch scheduler or `timeout` stops a program with SIGTERM; Python's default is to die at once
(exit 143, nothing written). Inside `terminate_raises()` SIGTERM raises `Terminated`, a
KeyboardInterrupt, so every `except KeyboardInterrupt` that keeps a log keeps it for SIGTERM
too. No Drake import.

A signal that is ignored when a command starts stays ignored, as Unix programs do: a shell
without job control starts background commands (`cmd &` in a script, `nohup`) with SIGINT
ignored so that a Ctrl-C at the terminal does not reach them. Every handler here is installed
only for a signal that `honoured` says is not ignored.
"""

import contextlib
import signal
import threading

# 128 + the signal number, as a shell reports a process killed by it.
EXIT_SIGINT = 128 + signal.SIGINT    # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143


class Terminated(KeyboardInterrupt):
    """SIGTERM was received."""


def exit_code(interrupt: BaseException | str | None) -> int:
    """130 for Ctrl-C (KeyboardInterrupt or "SIGINT"), 143 for SIGTERM (Terminated or
    "SIGTERM")."""
    if isinstance(interrupt, Terminated) or interrupt == "SIGTERM":
        return EXIT_SIGTERM
    return EXIT_SIGINT


def honoured(sig) -> bool:
    """False when `sig` is ignored (SIG_IGN), as it is in a process started with it ignored:
    the command then keeps ignoring it instead of installing its own handler."""
    return signal.getsignal(sig) is not signal.SIG_IGN


def _raise_terminated(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def terminate_raises():
    """Within the block, SIGTERM raises Terminated in the main thread (elsewhere: no-op)."""
    if threading.current_thread() is not threading.main_thread() or not honoured(
            signal.SIGTERM):
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
