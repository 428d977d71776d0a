"""The line a command prints when it first compiles the numba kernels it needs, so the seconds
of a first run after installing are explained (and said once per command)."""

import sys


COMPILE_NOTICE = ("cdpm: compiling per-tick math this command needs for the first time "
                  "(numba, a few seconds, once: later runs load it from the cache)")
# Set in the environment once the notice is said: a process this command starts afterwards
# (an emulator, a worker) inherits it and does not say it again.
COMPILE_NOTICE_SAID = "CDPM_COMPILE_NOTICE_SAID"


class compile_notice:
    """Within the block, the first compilation of a kernel (numba's "numba:compile" event:
    a cache miss, never a load from the cache) prints COMPILE_NOTICE once on `stream`, so the
    seconds of a first run are explained; a run that loads everything from numba's cache says
    nothing, and so does a process started by one that said it already (COMPILE_NOTICE_SAID
    in its environment). Each command after installing may compile what it alone needs (the
    dynamic plant's cables, the workspace statics), hence "this command ... first time"."""

    def __init__(self, stream=None):
        import os

        self._stream = stream
        self._inherited = os.environ.get(COMPILE_NOTICE_SAID)
        self.said = bool(self._inherited)
        self._installed = None

    def __enter__(self):
        try:
            from numba.core import event
        except ImportError:  # no numba event API: no notice, nothing else changes
            return self
        notice = self

        class _Listener(event.Listener):
            def on_start(self, ev):
                if not notice.said:
                    import os

                    notice.said = True
                    os.environ[COMPILE_NOTICE_SAID] = "1"
                    print(COMPILE_NOTICE, file=notice._stream or sys.stderr, flush=True)

            def on_end(self, ev):
                pass

        self._installed = event.install_listener("numba:compile", _Listener())
        self._installed.__enter__()
        return self

    def __exit__(self, *exc):
        import os

        if self._installed is not None:
            self._installed.__exit__(*exc)
            self._installed = None
        if self._inherited is None:  # the command is over: the next one may say it again
            os.environ.pop(COMPILE_NOTICE_SAID, None)
