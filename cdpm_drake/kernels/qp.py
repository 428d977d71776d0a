"""A small dense quadratic program, exactly: the point closest to z0 in a weighted norm subject
to linear inequalities. numpy and numba, no Drake. The safety filter solves one every tick
(3 or 6 unknowns, a few dozen constraints) and the tension distribution of a robot with more
than seven cables one more; `scripts/bench/bench_safety_filter.py` compares it with Drake's
MathematicalProgram solvers (Clarabel, OSQP) on the filter's own problems.

    minimise  1/2 sum_i w_i (z_i - z0_i)^2   subject to   C z >= d   (rows of C, d)

Method: the dual active-set method of Goldfarb and Idnani (Math. Programming 27, 1983), as in
quadprog, on y = sqrt(w) (z - z0) (the objective becomes 1/2 |y|^2: the projection of the
origin onto a polyhedron). It starts from the unconstrained minimum and adds the most violated
constraint, dropping active ones whose multiplier would turn negative: every iterate is dual
feasible, the objective only grows, and it ends after finitely many steps with the exact
optimum (to round-off) or a proof that no z satisfies C z >= d. The projections it needs are
recomputed from the active normals at each step (a Cholesky factor of at most n x n), which for
n <= 8 costs less than updating a factorisation.
"""

import math

import numba
import numpy as np

# Compiled once (cached); error_model="numpy": x / 0 is inf or nan, never an exception.
_jit = numba.njit(cache=True, error_model="numpy")

# Status of `solve_qp`.
QP_OPTIMAL, QP_INFEASIBLE, QP_MAX_ITERATIONS = 0, 1, 2

# A constraint counts as met when C z - d >= -FEAS_TOL * (1 + |d|), and a normal as lying in
# the span of the active ones when what is left of it after projection is below
# SPAN_TOL times its norm: both far above round-off for normals of unit size, far below the
# millimetre-per-tick scale of the filter's constraints.
FEAS_TOL = 1e-10
SPAN_TOL = 1e-9


@_jit
def _step_direction(Cs, n, active, q, p, z, r, Qw, Rw):
    """For the pending constraint p: r, the coefficients of its normal on the active normals,
    and z, what is left of it orthogonal to them, from a QR factorisation of the active
    normals by modified Gram-Schmidt, each projection done twice (stable where the normals
    are nearly dependent). Returns |z|^2 (0 when q == n), or -1 when the active normals are
    numerically dependent. Qw, Rw: work buffers of >= (n + 1) n and (n + 1)^2 floats."""
    Q = Qw[:(q + 1) * n].reshape((q + 1, n))
    R = Rw[:(q + 1) * (q + 1)].reshape((q + 1, q + 1))
    for a in range(q + 1):
        for b in range(q + 1):
            R[a, b] = 0.0
    for a in range(q + 1):
        row = active[a] if a < q else p
        for k in range(n):
            Q[a, k] = Cs[row, k]
        for _ in range(2):
            for b in range(a):
                s = 0.0
                for k in range(n):
                    s += Q[b, k] * Q[a, k]
                R[b, a] += s
                for k in range(n):
                    Q[a, k] -= s * Q[b, k]
        if a < q:
            norm = 0.0
            for k in range(n):
                norm += Q[a, k] * Q[a, k]
            norm = math.sqrt(norm)
            if norm <= SPAN_TOL:
                return -1.0
            R[a, a] = norm
            for k in range(n):
                Q[a, k] /= norm
    # What is left of the pending normal (row q of Q), and its coefficients R r = R[:q, q].
    zz = 0.0
    for k in range(n):
        z[k] = Q[q, k] if q < n else 0.0
        zz += z[k] * z[k]
    for a in range(q - 1, -1, -1):
        s = R[a, q]
        for b in range(a + 1, q):
            s -= R[a, b] * r[b]
        r[a] = s / R[a, a]
    return zz


def qp_scratch(rows: int, n: int):
    """The work arrays of `solve_qp_in` for at most `rows` constraints on n unknowns, as
    two flat buffers (floats, integers) a caller allocates once (`owned_scratch`)."""
    size = n * (rows + 5) + 2 * rows + (n + 1) * n + (n + 1) * (n + 1)
    return np.zeros(size), np.zeros(n, dtype=np.int64)


@_jit
def solve_qp(w, z0, C, d, count, z, u, max_iterations):
    """min 1/2 sum w_i (z_i - z0_i)^2 subject to C[:count] z >= d[:count] (module docstring).
    w (n,) > 0 the weights, z0 (n,), C (>= count, n), d (>= count,); the solution goes into
    z (n,) and the constraints' multipliers into u (>= count,) (zero for inactive ones).
    Returns (status, number of constraints active at the optimum): QP_OPTIMAL, QP_INFEASIBLE
    (no z satisfies the constraints; z then holds the last iterate) or QP_MAX_ITERATIONS.
    Allocates its work arrays; `solve_qp_in` takes them from the caller."""
    n = w.size
    floats = np.empty(n * (count + 5) + 2 * count + (n + 1) * n + (n + 1) * (n + 1))
    return solve_qp_in(w, z0, C, d, count, z, u, max_iterations,
                       (floats, np.empty(n, dtype=np.int64)))


@_jit
def solve_qp_in(w, z0, C, d, count, z, u, max_iterations, work):
    """`solve_qp` in the caller's work arrays, work = (floats, ints) of `qp_scratch`'s sizes
    for >= count rows (no allocation): the same numbers."""
    n = w.size
    floats, ints = work
    o = 0
    sw = floats[o:o + n]
    o += n
    for k in range(n):
        sw[k] = math.sqrt(w[k])
    # y = sqrt(w) (z - z0): the constraints become Cs y >= ds with Cs = C diag(1/sqrt(w)),
    # ds = d - C z0, each row scaled to unit norm (the multipliers are rescaled at the end).
    Cs = floats[o:o + count * n].reshape((count, n))
    o += count * n
    ds = floats[o:o + count]
    o += count
    scale = floats[o:o + count]
    o += count
    for j in range(count):
        s = d[j]
        nn = 0.0
        for k in range(n):
            s -= C[j, k] * z0[k]
            Cs[j, k] = C[j, k] / sw[k]
            nn += Cs[j, k] * Cs[j, k]
        nn = math.sqrt(nn)
        scale[j] = nn
        if nn > 0.0:
            for k in range(n):
                Cs[j, k] /= nn
            ds[j] = s / nn
        else:
            ds[j] = s  # a constraint 0 >= s: met or infeasible, nothing to move
        u[j] = 0.0
    y = floats[o:o + n]
    ua = floats[o + n:o + 2 * n]  # multipliers of the active constraints
    r = floats[o + 2 * n:o + 3 * n]
    zdir = floats[o + 3 * n:o + 4 * n]
    Qw = floats[o + 4 * n:o + 4 * n + (n + 1) * n]
    Rw = floats[o + 4 * n + (n + 1) * n:]
    for k in range(n):
        y[k] = 0.0
        ua[k] = 0.0
    active = ints[:n]
    q = 0
    status = QP_MAX_ITERATIONS
    iterations = 0
    while iterations < max_iterations:
        # The most violated constraint (rows are unit normals: slack in y's units).
        p = -1
        worst = 0.0
        for j in range(count):
            s = -ds[j]
            for k in range(n):
                s += Cs[j, k] * y[k]
            tol = FEAS_TOL * (1.0 + abs(ds[j]))
            if s < -tol and s < worst:
                is_active = False
                for a in range(q):
                    if active[a] == j:
                        is_active = True
                if not is_active:
                    worst, p = s, j
        if p < 0:
            status = QP_OPTIMAL
            break
        if scale[p] == 0.0:
            status = QP_INFEASIBLE
            break
        u_p = 0.0
        added = False
        while iterations < max_iterations and not added:
            iterations += 1
            zz = _step_direction(Cs, n, active, q, p, zdir, r, Qw, Rw)
            if zz < 0.0:
                return QP_MAX_ITERATIONS, q  # dependent active normals: cannot happen in exact
            # The largest dual step that keeps the active multipliers >= 0.
            t1, k_drop = math.inf, -1
            for a in range(q):
                if r[a] > 0.0 and ua[a] / r[a] < t1:
                    t1, k_drop = ua[a] / r[a], a
            slack = -ds[p]
            for k in range(n):
                slack += Cs[p, k] * y[k]
            t2 = -slack / zz if zz > SPAN_TOL * SPAN_TOL else math.inf
            t = min(t1, t2)
            if t == math.inf:
                status = QP_INFEASIBLE
                for j in range(count):
                    u[j] = 0.0
                for k in range(n):
                    z[k] = z0[k] + y[k] / sw[k]
                return status, q
            if t2 < math.inf:
                for k in range(n):
                    y[k] += t * zdir[k]
            for a in range(q):
                ua[a] -= t * r[a]
            u_p += t
            if t == t2:
                active[q] = p
                ua[q] = u_p
                q += 1
                added = True
            else:
                # Drop the active constraint whose multiplier reached zero, keep the order.
                for a in range(k_drop, q - 1):
                    active[a] = active[a + 1]
                    ua[a] = ua[a + 1]
                q -= 1
    for k in range(n):
        z[k] = z0[k] + y[k] / sw[k]
    for a in range(q):
        j = active[a]
        u[j] = ua[a] / scale[j]
    return status, q
