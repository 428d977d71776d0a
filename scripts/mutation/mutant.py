"""One planted one-line bug: where, what it replaces, why it matters, which tests should
kill it first."""

import dataclasses


@dataclasses.dataclass(frozen=True)
class Mutant:
    name: str
    file: str
    original: str
    replacement: str
    reason: str
    tests: tuple = ()
