"""The line a command prints when it first compiles the numba kernels it needs, so the wait of
a first run after installing is explained (and said once per command)."""

import sys


# How long the first compilation of everything takes (`cdpm warm` measured on a first install:
# 71 s of CPU; 350 s of wall clock on a 2-core host loaded by other jobs; 40-160 s reported by
# users on first use).
FIRST_COMPILE = "1-2 min of CPU, several minutes on a busy host"
COMPILE_NOTICE = ("cdpm: compiling the per-tick math this command needs for the first time "
                  f"(numba, once: {FIRST_COMPILE} for everything; later runs load it from the "
                  "cache; `cdpm warm` compiles what every command needs in one step)")
# Set in the environment once the notice is said: a process this command starts afterwards
# (an emulator, a worker) inherits it and does not say it again.
COMPILE_NOTICE_SAID = "CDPM_COMPILE_NOTICE_SAID"


def listen_to_compiles(on_compile):
    """Calls `on_compile()` at each of numba's compilations (its "numba:compile" event: a cache
    miss, never a load from the cache) until the returned context is exited; it is entered
    here."""
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev):
            on_compile()

        def on_end(self, ev):
            pass

    installed = event.install_listener("numba:compile", _Listener())
    installed.__enter__()
    return installed


class compile_notice:
    """Within the block, the first compilation of a kernel (numba's "numba:compile" event:
    a cache miss, never a load from the cache) prints COMPILE_NOTICE once on `stream`, so the
    wait of a first run is explained; a run that loads everything from numba's cache says
    nothing, and so does a process started by one that said it already (COMPILE_NOTICE_SAID
    in its environment). Each command after installing may compile what it alone needs (the
    dynamic plant's cables, the workspace statics), hence "this command ... first time"."""

    def __init__(self, stream=None, quiet=False):
        import os

        self._stream = stream
        self._inherited = os.environ.get(COMPILE_NOTICE_SAID)
        self.said = bool(self._inherited) or quiet
        self._installed = None

    def __enter__(self):
        try:
            from numba.core import event  # noqa: F401
        except ImportError:  # no numba event API: no notice, nothing else changes
            return self
        notice = self

        def on_compile():
            if not notice.said:
                import os

                notice.said = True
                os.environ[COMPILE_NOTICE_SAID] = "1"
                print(COMPILE_NOTICE, file=notice._stream or sys.stderr, flush=True)

        self._installed = listen_to_compiles(on_compile)
        return self

    def __exit__(self, *exc):
        import os

        if self._installed is not None:
            self._installed.__exit__(*exc)
            self._installed = None
        if self._inherited is None:  # the command is over: the next one may say it again
            os.environ.pop(COMPILE_NOTICE_SAID, None)
