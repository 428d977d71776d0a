"""Plain text for the command line: tables for the summaries and the benchmark scripts, and
log records printed as `warning: ...`."""

import contextlib
import logging
import sys


def format_table(headers, rows) -> str:
    """Columns padded to their widest cell: the first left-aligned, the others right-aligned
    (numbers), a dashed rule under the headers."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    lines = ["  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                       for k, (c, w) in enumerate(zip(r, widths))) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


class _LevelPrefix(logging.Formatter):
    def format(self, record):
        return f"{record.levelname.lower()}: {record.getMessage()}"


@contextlib.contextmanager
def prefixed_log_records(stream=None):
    """Within the block, warnings and errors logged by the package and by Drake print as
    `warning: ...` / `error: ...` on stderr (like the commands' `error:` lines), not as a bare
    message."""
    handler = logging.StreamHandler(sys.stderr if stream is None else stream)
    handler.setFormatter(_LevelPrefix())
    handler.setLevel(logging.WARNING)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)
