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


def format_vector(v, digits=3) -> str:
    """A vector as `[1.500, 3.000, 1.000]`: each value with `digits` decimals."""
    import numpy as np

    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"


def format_number(x, digits=2, sign=False) -> str:
    """x with `digits` decimals (`sign`: a + before positives), never "-0.00": a value that
    rounds to zero prints as zero (a distance 1.5 nm below d_l is not "-0.00 mm" below it)."""
    x = float(x)
    if round(x, digits) == 0.0:
        x = 0.0
    return f"{x:+.{digits}f}" if sign else f"{x:.{digits}f}"


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


def did_you_mean(word, choices) -> str:
    """"; did you mean 'mass'?" for the choice closest to a misspelt `word` (difflib's ratio
    of at least 0.6), or "" when none is close."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def yaml_line(keys, *, filename=None, data=None) -> int | None:
    """The line (from 1) where the key path `keys` (mapping keys as str, list indices as int)
    is written in a YAML file or text, or None when it is not there or the YAML does not
    parse. Tags (`!SpringHandOperator`) are kept as they are: only the layout is read."""
    import yaml

    try:
        text = data if data is not None else open(filename, encoding="utf-8").read()
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return None
    line = None
    for key in keys:
        if isinstance(node, yaml.MappingNode) and not isinstance(key, int):
            found = [(k, v) for k, v in node.value if k.value == str(key)]
            if not found:
                return None
            line, node = found[-1][0].start_mark.line + 1, found[-1][1]
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) \
                and 0 <= key < len(node.value):
            node = node.value[key]
            line = node.start_mark.line + 1
        else:
            return None
    return line


def _yaml_nodes(filename, data):
    """The YAML file's or text's node tree (None when it is empty, unreadable or does not
    parse: the loader says why)."""
    import yaml

    try:
        text = data if data is not None else open(filename, encoding="utf-8").read()
        return yaml.compose(text, Loader=yaml.SafeLoader)
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return None


def duplicate_yaml_keys(*, filename=None, data=None) -> list[str]:
    """Each key written twice in one mapping of a YAML file or text, as `'key' (path) on lines
    A and B`; [] when there is none or the YAML does not parse (the loader says why). YAML
    loaders keep the last one silently, so a value the user wrote is lost."""
    import yaml

    root = _yaml_nodes(filename, data)
    found = []

    def walk(node, path):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for k, v in node.value:
                key = str(k.value)
                where = f"{path}.{key}" if path else key
                if key in seen:
                    found.append(f"{key!r} ({where}) on lines {seen[key]} and "
                                 f"{k.start_mark.line + 1}")
                else:
                    seen[key] = k.start_mark.line + 1
                walk(v, where)
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                walk(v, f"{path}[{i}]")

    if root is not None:
        walk(root, "")
    return found


def quoted_numbers(*, filename=None, data=None) -> list[tuple[str, int, str]]:
    """Each quoted scalar of a YAML file or text that reads as a number (`mass: "3.0"`), as
    (path, line, text), path like `platform.mass` or `reels[0][1]`; [] when there is none or
    the YAML does not parse. Drake's loader turns such a string into a float without a
    word, so a value the user quoted (perhaps meaning something else) passes unseen."""
    import yaml

    root = _yaml_nodes(filename, data)
    found = []

    def walk(node, path):
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                walk(v, f"{path}.{k.value}" if path else str(k.value))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                walk(v, f"{path}[{i}]")
        elif isinstance(node, yaml.ScalarNode) and node.style in ("'", '"'):
            try:
                float(node.value)
            except ValueError:
                return
            found.append((path, node.start_mark.line + 1, node.value))

    if root is not None:
        walk(root, "")
    return found
