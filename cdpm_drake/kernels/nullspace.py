"""W's nullspace, compiled: a pivoted Householder QR of W^T, the minimum-norm solution T_p of
W T = -w and the nullspace's unit vectors from it, the interval of a one-dimensional
nullspace's coordinate that keeps every cable above a floor, and the same form by SVD for any
W. numpy and numba, no Drake. Shared by the tension kernels (tension.py, full_pose.py,
kinetostatics.py): every T with W T = -w is T = T_p + N lam, N (m, k) an orthonormal basis of
W's nullspace."""

import math

import numba
import numpy as np

# W (r x m) counts as rank-deficient when the last pivot of its pivoted QR (or its smallest
# singular value) is below this fraction of the first: the nullspace is then treated as having
# more than m - r dimensions and the general solver decides. Far above round-off of unit
# vectors and moments of a few tenths of a metre, far below any pose a robot is used at.
RANK_TOL = 1e-9

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def pivoted_qr(W, A, V, beta, perm):
    """Householder QR with column pivoting of W^T (m x r, r = W's rows): A[:r] holds R
    (upper triangular), V[k] and beta[k] the reflections H_k = I - beta_k v_k v_k^T, perm the
    pivot order of W's rows. Returns |R_rr| / |R_11| (0 for a zero W)."""
    r, m = W.shape
    for i in range(m):
        for j in range(r):
            A[i, j] = W[j, i]
    for j in range(r):
        perm[j] = j
    for k in range(r):
        best, best_norm = k, -1.0
        for j in range(k, r):
            s = 0.0
            for i in range(k, m):
                s += A[i, j] * A[i, j]
            if s > best_norm:
                best, best_norm = j, s
        if best != k:
            for i in range(m):
                A[i, k], A[i, best] = A[i, best], A[i, k]
            perm[k], perm[best] = perm[best], perm[k]
        for i in range(m):
            V[k, i] = 0.0
        norm = math.sqrt(best_norm)
        if norm == 0.0:
            beta[k] = 0.0
            continue
        alpha = -norm if A[k, k] >= 0.0 else norm
        vv = 0.0
        for i in range(k, m):
            V[k, i] = A[i, k]
        V[k, k] -= alpha
        for i in range(k, m):
            vv += V[k, i] * V[k, i]
        beta[k] = 2.0 / vv
        for j in range(k, r):
            s = 0.0
            for i in range(k, m):
                s += V[k, i] * A[i, j]
            s *= beta[k]
            for i in range(k, m):
                A[i, j] -= s * V[k, i]
    first = abs(A[0, 0])
    return abs(A[r - 1, r - 1]) / first if first > 0.0 else 0.0


@_jit
def _apply_q(V, beta, z):
    """z <- Q z, Q = H_0 H_1 ... H_{r-1}."""
    r, m = V.shape
    for k in range(r - 1, -1, -1):
        s = 0.0
        for i in range(k, m):
            s += V[k, i] * z[i]
        s *= beta[k]
        for i in range(k, m):
            z[i] -= s * V[k, i]


@_jit
def particular_solution(A, V, beta, perm, w, T_p):
    """T_p, the minimum-norm T with W T = -w, from the QR of W^T: R^T y = -w[perm],
    T_p = Q [y; 0]."""
    r, m = V.shape
    for j in range(r):
        s = -w[perm[j]]
        for i in range(j):
            s -= A[i, j] * T_p[i]
        T_p[j] = s / A[j, j]
    for i in range(r, m):
        T_p[i] = 0.0
    _apply_q(V, beta, T_p)


@_jit
def null_vector(V, beta, n, k=0):
    """The unit vector n = Q e_(r+k), Q's column r + k: W's nullspace is spanned by columns
    r..m-1 of Q (m = r + 1: n spans it)."""
    r = V.shape[0]
    for i in range(n.size):
        n[i] = 0.0
    n[r + k] = 1.0
    _apply_q(V, beta, n)


@_jit
def lam_interval(T_p, n, floor):
    """[lo, hi]: the lam with T_p[i] + n[i] lam >= floor for every cable with n[i] != 0."""
    lo, hi = -math.inf, math.inf
    for i in range(T_p.size):
        if n[i] > 0.0:
            lo = max(lo, (floor - T_p[i]) / n[i])
        elif n[i] < 0.0:
            hi = min(hi, (floor - T_p[i]) / n[i])
    return lo, hi


def nullspace_form(W, w):
    """(T_p, N, residual): the minimum-norm T with W T = -w, an orthonormal nullspace basis
    (m, k), and the largest |W T_p + w| (above round-off: w is outside W's range)."""
    U, s, Vt = np.linalg.svd(W)
    rank = int(np.sum(s > RANK_TOL * s[0])) if s.size and s[0] > 0 else 0
    T_p = Vt[:rank].T @ ((U[:, :rank].T @ -w) / s[:rank])
    return T_p, Vt[rank:].T, float(np.max(np.abs(W @ T_p + w), initial=0.0))
