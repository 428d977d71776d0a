"""A rigorous lower bound of the kinetostatic margin along the look ahead's ray, from the
margin's own solution at the pose: where the bound stays above the level the look ahead
tests its samples against, no sample can fall below it, and the samples need not be taken
(kinetostatics.kinetostatic_tick). numpy and numba, no Drake.

The look ahead samples the margin at q(s) = p + s e, 0 < s <= S (e the unit velocity, S the
stopping distance; the orientation R, the wrench w and the floor held). At p the margin has
a maximiser T* with W(p) T* = -w. Any T with W(q) T = -w bounds the margin at q from below
(the margin is a maximum over those T), and T* + d does when W(q) d = -r,
r = (W(q) - W(p)) T*. With A = D W (the moment rows scaled by 1/rho, rho the attachments'
RMS radius: any right inverse will do, and the scaled one is ~5 times better conditioned on
paper_7cable), P = A(p)^T (A(p) A(p)^T)^-1 and F = A(q) - A(p), P (I + F P)^-1 is a right
inverse of A(q) where ||F P|| < 1, and with D r = s g + h (g = sum_i T*_i D W_i'(0), the
columns' derivative along e; h the rest):

    d = -s P g + eps,   ||eps|| <= ||P|| (||F|| s ||P g|| + ||h||) / (1 - ||F|| ||P||).

Each line (T_i - floor, ceiling - T_i) at T* + d is within ||eps|| of its value at
T* - s P g, linear in s; the minimum of linear functions (and the soft minimum, concave) is
concave in s, so over [0, S] it is at least its smaller end value. The norms: ||P||^2 =
||(A A^T)^-1|| <= ||C^-1||_F^2 with C the Cholesky factor; a cable's unit vector
u(s) = (a - B - s e) / |a - B - s e| moves by at most s / (L - s) (|u'| <= 1 / L(s), L(s) >=
L - s) and leaves its tangent by at most s^2 / (sqrt(3) (L - s)^2) (|u''| <= (2 / sqrt 3) /
L(s)^2); a column [u; R b x u] scaled by D moves by at most sqrt(1 + |R b|^2 / rho^2) times
u's move.

The margin the samples compute is the hard margin (the max-min, to round-off) or the soft
one (Newton's method from the hard maximiser, converged), both at least the value at any
feasible T of their own minimum; so the bound holds for them to round-off, which GUARD
covers. The bound also keeps the wrench matrix at q of full rank with room to spare
(sigma_min(A(q)) >= sigma_min(A(p)) - ||F||), so a sample's rank test cannot fail: the
elimination's last pivot is at least sigma_min(W) / sqrt(m - rows + 1) and the pivoted QR's
|R_rr| at least sigma_min(W), against RANK_TOL times the first pivot, at most the largest
column's norm.
"""

import math

import numba

from cdpm_drake.kernels.nullspace import RANK_TOL
from cdpm_drake.kernels.pose import cholesky, cholesky_solve, matrix_view

_jit = numba.njit(cache=True, error_model="numpy")

# The bound's allowance for round-off (relative to 1 + the largest tension, N): the samples'
# margins are exact to ~1e-9 relative (the elimination against the QR where tested), the QP
# form of several internal forces to ~1e-8.
GUARD = 1e-6
# ||F|| ||P|| at most this (the series (I + F P)^-1 then converges with room); and no sample
# within twice the stopping distance of a reel.
MAX_COUPLING = 0.5


def ray_work_size(m: int) -> int:
    """Floats of `ray_floor`'s work array for m cables."""
    return 6 * m + 36 + 6 + 6 + m


@_jit
def ray_floor(u, Rb, L, T, rows, e, reach, kappa, soft, floor, ceiling, work):
    """A lower bound (N) of the margin at every q = p + s e, 0 <= s <= reach, less GUARD
    (module docstring): u, Rb, L (m, 3), (m, 3), (m,) the cables posed at p (R b_i and the unit
    vectors, m); T (m,) the margin's maximiser at p (N), kappa its margin (N; the soft one
    where soft > 0: the temperature, N); rows 3 or 6; e (3,) a unit vector; reach (m);
    floor, ceiling (N); work: `ray_work_size(m)` floats. -inf where it cannot tell (the ray
    near a reel, a coupling too strong, a wrench matrix near rank loss)."""
    m = u.shape[0]
    big = 0.0
    for i in range(m):
        if not reach < 0.5 * L[i]:
            return -math.inf
        big = max(big, abs(T[i]))
    A = work[:rows * m]
    G = matrix_view(work, 6 * m, rows, rows)
    g = work[6 * m + 36:6 * m + 36 + rows]
    x = work[6 * m + 42:6 * m + 42 + rows]
    y = work[6 * m + 48:6 * m + 48 + m]
    inv = 1.0
    scale = 0.0  # sum_i (1 + |R b_i|^2): ||W||_F^2 at any pose, for the rank test
    rb2 = 0.0
    for i in range(m):
        s = Rb[i, 0] * Rb[i, 0] + Rb[i, 1] * Rb[i, 1] + Rb[i, 2] * Rb[i, 2]
        rb2 += s
        scale += 1.0 + s
    if rows == 6:
        if not rb2 > 0.0:
            return -math.inf
        inv = 1.0 / math.sqrt(rb2 / m)
    # A = D W(p) and g = sum_i T_i D W_i'(0), W_i' = [u_i'; R b_i x u_i'] with
    # u_i' = -(e - (e . u_i) u_i) / L_i.
    for r in range(rows):
        g[r] = 0.0
    for i in range(m):
        c = e[0] * u[i, 0] + e[1] * u[i, 1] + e[2] * u[i, 2]
        d0 = -(e[0] - c * u[i, 0]) / L[i]
        d1 = -(e[1] - c * u[i, 1]) / L[i]
        d2 = -(e[2] - c * u[i, 2]) / L[i]
        A[i], A[m + i], A[2 * m + i] = u[i, 0], u[i, 1], u[i, 2]
        g[0] += T[i] * d0
        g[1] += T[i] * d1
        g[2] += T[i] * d2
        if rows == 6:
            A[3 * m + i] = (Rb[i, 1] * u[i, 2] - Rb[i, 2] * u[i, 1]) * inv
            A[4 * m + i] = (Rb[i, 2] * u[i, 0] - Rb[i, 0] * u[i, 2]) * inv
            A[5 * m + i] = (Rb[i, 0] * u[i, 1] - Rb[i, 1] * u[i, 0]) * inv
            g[3] += T[i] * (Rb[i, 1] * d2 - Rb[i, 2] * d1) * inv
            g[4] += T[i] * (Rb[i, 2] * d0 - Rb[i, 0] * d2) * inv
            g[5] += T[i] * (Rb[i, 0] * d1 - Rb[i, 1] * d0) * inv
    for r in range(rows):
        for c in range(r + 1):
            s = 0.0
            for i in range(m):
                s += A[r * m + i] * A[c * m + i]
            G[r, c] = s
            G[c, r] = s
    if not cholesky(G):
        return -math.inf
    # ||P||^2 <= ||C^-1||_F^2, C^-1 by columns (forward substitution on the identity).
    inv_f = 0.0
    for j in range(rows):
        for i in range(j, rows):
            s = 1.0 if i == j else 0.0
            for k in range(j, i):
                s -= G[i, k] * x[k]
            x[i] = s / G[i, i]
            inv_f += x[i] * x[i]
    P = math.sqrt(inv_f) * (1.0 + 1e-9)
    # P g = A^T (C C^T)^-1 g: y = -P g, the tensions' first-order change per metre.
    cholesky_solve(G, g, x)
    Pg = 0.0
    for i in range(m):
        s = 0.0
        for r in range(rows):
            s += A[r * m + i] * x[r]
        y[i] = -s
        Pg += s * s
    Pg = math.sqrt(Pg)
    # ||F||_F and ||h|| at s = reach (both grow with s).
    F2, h = 0.0, 0.0
    for i in range(m):
        c2 = 1.0
        if rows == 6:
            c2 += (Rb[i, 0] * Rb[i, 0] + Rb[i, 1] * Rb[i, 1] + Rb[i, 2] * Rb[i, 2]) * inv * inv
        gap = L[i] - reach
        move = reach / gap
        F2 += c2 * move * move
        h += abs(T[i]) * math.sqrt(c2) * move * move / math.sqrt(3.0)
    Fn = math.sqrt(F2) * (1.0 + 1e-9)
    coupling = Fn * P
    if not coupling <= MAX_COUPLING:
        return -math.inf
    # sigma_min(W(q)) >= min(1, rho) (sigma_min(A(p)) - ||F||): far above the rank tests'.
    rho = 1.0 / inv
    if not min(1.0, rho) * (1.0 / P - Fn) > 1e3 * RANK_TOL * math.sqrt(m * scale):
        return -math.inf
    eps = P * (Fn * reach * Pg + h) / (1.0 - coupling)
    # The lines at T + reach y: their (soft) minimum; at s = 0 it is kappa.
    low = math.inf
    for i in range(m):
        t = T[i] + reach * y[i]
        low = min(low, t - floor, ceiling - t)
    end = low
    if soft > 0.0:
        total = 0.0
        for i in range(m):
            t = T[i] + reach * y[i]
            total += math.exp(-(t - floor - low) / soft) + math.exp(-(ceiling - t - low) / soft)
        end = low - soft * math.log(total)
    return min(kappa, end) - eps - GUARD * (1.0 + big)
