"""Plain-text tables for the CLI's summaries and the benchmark scripts."""


def format_table(headers, rows) -> str:
    """Columns padded to their widest cell: the first left-aligned, the others right-aligned
    (numbers), a dashed rule under the headers."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    lines = ["  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                       for k, (c, w) in enumerate(zip(r, widths))) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)
