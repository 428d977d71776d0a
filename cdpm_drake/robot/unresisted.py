"""The wrenches a robot's cables cannot resist, in words: where the wrench matrix W (6, m;
forces in N and moments in N m about the platform centre, base frame) has rank r < 6, the
cables produce only an r-dimensional set of wrenches, and 6 - r directions are missing.

They come from the null space of W^T (the wrenches orthogonal to everything the cables
produce): each of its 6 - r dimensions is named by the coordinate axis it holds most of
(pivoted elimination of an orthonormal basis), so a rank-3 robot names three directions, not
the two largest components of one. Each named direction (e.g. "moment about x") is a wrench
the cables cannot balance, and the named directions together with W's range span every
wrench. A direction that mixes axes is named as a unit axis [x, y, z] (base frame), with the
moment per newton where it couples a force with a moment."""

import numpy as np

from cdpm_drake.kernels.nullspace import RANK_TOL

AXES = ("force along x", "force along y", "force along z", "moment about x",
        "moment about y", "moment about z")
# Components of a direction below this share of its largest are left out of its name (the
# direction named is then close to, not exactly, the null space's: still one the cables
# cannot produce, since the pivot axis dominates).
_PURE = 0.25


def wrench_rank(W) -> int:
    """The numerical rank of W (singular values above RANK_TOL of the largest)."""
    s = np.linalg.svd(np.asarray(W, dtype=float), compute_uv=False)
    return int(np.sum(s > RANK_TOL * max(s[0], 1e-300))) if s.size else 0


def unresisted_directions(W) -> tuple[int, list[tuple[int, np.ndarray]]]:
    """(rank of W, [(axis, d), ...]): per missing direction (6 - rank of them) the index into
    AXES of the axis it is named by and the direction d (6,) in the null space of W^T, scaled
    so d[axis] = 1, every other direction's axis 0 in it (reduced row echelon form)."""
    W = np.asarray(W, dtype=float)
    U, s, _ = np.linalg.svd(W)  # U (6, 6): its columns from `rank` on span null(W^T)
    rank = int(np.sum(s > RANK_TOL * max(s[0], 1e-300))) if s.size else 0
    A = U[:, rank:].T.copy()  # (k, 6), rows an orthonormal basis of null(W^T)
    k = A.shape[0]
    pivots: list[int] = []
    for row in range(k):
        # The largest remaining entry picks the axis: the best-conditioned choice, so the
        # named axes with W's range span every wrench.
        rest = np.abs(A[row:])
        rest[:, pivots] = 0.0
        i, axis = np.unravel_index(int(np.argmax(rest)), rest.shape)
        A[[row, row + i]] = A[[row + i, row]]
        A[row] /= A[row, axis]
        for other in range(k):
            if other != row:
                A[other] -= A[other, axis] * A[row]
        pivots.append(int(axis))
    A[np.abs(A) < 1e-12] = 0.0
    order = np.argsort(pivots)  # forces first, then moments, x y z
    return rank, [(pivots[j], A[j]) for j in order]


def _vector(v) -> str:
    return "[" + ", ".join(f"{x:.2f}" for x in np.asarray(v) + 0.0) + "]"


def _direction_text(axis: int, d) -> str:
    """One direction in words: its axis where the others are small (below _PURE of the
    largest), else a moment about (or a force along) a unit axis [x, y, z], or both with the
    moment per newton of force (m)."""
    d = np.asarray(d, dtype=float)
    big = np.abs(d) >= _PURE * np.abs(d).max()
    if big.sum() == 1:
        return AXES[int(np.argmax(big))]
    f, n = np.where(big[:3], d[:3], 0.0), np.where(big[3:], d[3:], 0.0)
    nf, nn = np.linalg.norm(f), np.linalg.norm(n)
    if nf == 0.0:
        return f"moment about the axis {_vector(n / nn)}"
    if nn == 0.0:
        return f"force along {_vector(f / nf)}"
    return (f"force along {_vector(f / nf)} with a moment about {_vector(n / nn)} of "
            f"{nn / nf:.3g} N m per N")


def _group(kind: str, letters: list[str]) -> str:
    """'moments about x, y and z', 'a force along z'."""
    if len(letters) == 1:
        return f"a {kind} {letters[0]}"
    word, prep = kind.split(" ")
    return f"{word}s {prep} {', '.join(letters[:-1])} and {letters[-1]}"


def unresisted_text(W) -> str:
    """Every direction the cables cannot resist, in words (module docstring), e.g. "moments
    about x, y and z"; "" at rank 6."""
    _, directions = unresisted_directions(W)
    pure = {"force along": [], "moment about": []}
    coupled = []
    for axis, d in directions:
        text = _direction_text(axis, d)
        if text in AXES:
            named = AXES.index(text)
            pure["force along" if named < 3 else "moment about"].append("xyz"[named % 3])
        else:
            coupled.append(f"a {text}")
    parts = [_group(kind, letters) for kind, letters in pure.items() if letters] + coupled
    if len(parts) <= 1:
        return "".join(parts)
    return ", ".join(parts[:-1]) + " and " + parts[-1]
