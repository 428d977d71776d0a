"""`cdpm list`: the robots, scenarios and sweeps shipped with the package, one line each."""

import sys
from pathlib import Path


def list_main(out=None) -> int:
    """Print the built-in robots, scenarios and sweeps, one line each."""
    from cdpm_drake import data

    out = sys.stdout if out is None else out
    ROBOTS_DIR, SCENARIOS_DIR, sweeps_dir = data.ROBOTS_DIR, data.SCENARIOS_DIR, data.SWEEPS_DIR
    for title, directory in (("robots", ROBOTS_DIR), ("scenarios", SCENARIOS_DIR),
                             ("sweeps", sweeps_dir)):
        files = sorted(directory.glob("*.yaml")) if directory.is_dir() else []
        if title == "sweeps" and not files:
            continue
        print(f"{title} ({directory}):", file=out)
        rows = [(f.stem, _one_line(f)) for f in files]
        width = max((len(n) for n, _ in rows), default=0)
        for name, line in rows:
            print(f"  {name:<{width}}  {line}", file=out)
    return 0


def _one_line(path: Path) -> str:
    """A YAML file's `description`, else its first comment line."""
    from pydrake.common.yaml import yaml_load

    try:
        raw = yaml_load(filename=str(path))
    except Exception as e:  # listed all the same: say why there is no description
        return f"(not readable: {type(e).__name__})"
    description = raw.get("description") if isinstance(raw, dict) else None
    if isinstance(description, str) and description.strip():
        return _first_sentence(" ".join(description.split()))
    comment = []  # the file's leading comment block, as one paragraph
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            if comment or line.strip():
                break
            continue
        comment.append(line.lstrip("#").strip())
    return _first_sentence(" ".join(w for w in comment if w))


def _first_sentence(text: str, limit: int = 110) -> str:
    import re

    # A sentence ends at ". " before a capital ("Fig. 7" does not end one).
    end = re.search(r"[.:;](?=\s+[A-Z])", text)
    text = text if end is None else text[:end.start() + 1]
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."


def cmd_list(args) -> int:
    """`cdpm list`."""
    return list_main()
