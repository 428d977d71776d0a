"""Self-calibration of a cable robot from its own encoder lengths (plain numpy, no Drake).

A robot with more cables than its platform has degrees of freedom measures its own misfit at
every pose: m encoder lengths against 3 (translation) or 6 (full pose) unknowns. Over a set of
poses those redundant lengths identify the reel exits a_i, the encoders' offsets c_i and, with
full pose, the attachment points b_i (self-calibration of over-constrained robots, as in
Miermeister and Pott's IPAnema work). The model of one encoder reading, cable i at pose k:

    e_ik = ||a_i - p_k - R_k b_i|| / (1 + T_ik / EA) + c_i

(the rigid length shortened by the cable's stretch where its tension T_ik is measured; without
tensions the stretch is taken as zero and what is constant of it goes into c_i).

The gauge is fixed explicitly: pose 0 is the homing pose, where a person placed the platform
(its position, and with full pose its orientation, are known), which fixes the base frame; with
full pose the attachment points' centroid and orientation keep the file's, which fixes the
platform frame (lengths alone cannot see a shift of every b_i that every pose undoes). A weak
Gaussian prior on each parameter (the accuracy the file claims) keeps the normal equations
regular; what the data identify is read off the data alone (the information without the prior):
a parameter whose standard deviation from the data exceeds `identified_std` is reported as not
identified.

Externally measured poses (a laser tracker, motion capture: positions in the base frame with
their standard deviations) are residuals too. A translating platform's lengths cannot see a
turn of every a_i - b_i about the homing pose; measured poses can: 2 or more, off one line
through the homing pose, fix the turn (the homing pose keeps the frame's position: held, it
also lets a single wrong measurement show instead of tilting the frame, which 3 poses alone
could not tell from a turn). The fit then holds no turn, and the exits' absolute standard
deviations come from the data.

Solved by Gauss-Newton with a Levenberg-Marquardt damping and Huber weights (a robust loss:
a reading `huber` sigmas off counts linearly), re-linearising each pose's rotation at its
current estimate so that the Jacobian is exact.
"""

import dataclasses

import numpy as np


class CalibrationError(ValueError):
    """The data cannot calibrate the robot; the message says why, with the numbers."""


@dataclasses.dataclass(frozen=True)
class CalibrationPrior:
    """How far the file may be from the truth (one standard deviation), m."""

    reels_std: float = 0.05
    attachments_std: float = 0.02
    offsets_std: float = 0.05


@dataclasses.dataclass
class CalibrationResult:
    """The fitted geometry and what the data say about it. Arrays are 0-based by cable."""

    reels: np.ndarray             # (m, 3) a_i, base frame, m
    attachments: np.ndarray       # (m, 3) b_i, platform frame, m
    offsets: np.ndarray           # (R, m) c_i per run: reading minus unstretched length, m
    reels_std: np.ndarray         # (m, 3) from the data alone (inf: not identified), m
    attachments_std: np.ndarray   # (m, 3); 0 where not fitted
    # The same in the frame the gauge holds (relative to the homing pose and the file's
    # orientation): how well the geometry is known relative to itself.
    reels_std_in_frame: np.ndarray
    attachments_std_in_frame: np.ndarray
    offsets_std: np.ndarray       # (R, m)
    positions: np.ndarray         # (K, 3) fitted poses
    rotations: np.ndarray         # (K, 3, 3)
    residual_before: np.ndarray   # (m,) RMS per cable with the file's geometry, m
    residual_after: np.ndarray    # (m,) RMS per cable after the fit, m
    singular_values: np.ndarray   # of the data's whitened Jacobian, gauge removed, descending
    unidentified: list            # names of parameters the data do not identify
    iterations: int
    fit_attachments: bool
    # What fixes the base frame: "homing" (the homing poses, and for a translating platform
    # the file's turn), "homing+measured" (the homing poses and the measured poses' turn).
    gauge: str = "homing"
    # Per measured pose: the fitted pose minus the measured position (M, 3), m.
    measured_residual: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros((0, 3)))



def parameter_names(m: int, fit_attachments: bool, runs: int = 1) -> list[str]:
    """The geometry parameters' names as a user reads them (cables 1..m, runs 1..R), in the
    fit's order: reel exits, attachment points (where fitted), encoder offsets."""
    names = [f"reel {i + 1} {axis}" for i in range(m) for axis in "xyz"]
    if fit_attachments:
        names += [f"attachment {i + 1} {axis}" for i in range(m) for axis in "xyz"]
    names += [f"encoder offset {i + 1}" + (f" (run {r + 1})" if runs > 1 else "")
              for r in range(runs) for i in range(m)]
    return names


def _skew(w):
    """(..., 3) -> (..., 3, 3) cross-product matrices: skew(w) @ v = w x v."""
    z = np.zeros(w.shape[:-1])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1),
                     np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def rotation_exp_batch(phi):
    """(K, 3) rotation vectors -> (K, 3, 3) rotations (Rodrigues)."""
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = _skew(phi)
    small = theta < 1e-12
    safe = np.where(small, 1.0, theta)
    A = np.where(small, 1.0, np.sin(safe) / safe)
    B = np.where(small, 0.5, (1 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + A * K + B * (K @ K)


def predicted(reels, attachments, offsets, positions, rotations, stretch):
    """e_ik (K, m), the model's encoder readings; `stretch` (K, m) is 1 / (1 + T / EA)."""
    w = np.einsum("kab,ib->kia", rotations, attachments)
    d = reels[None] - positions[:, None] - w
    return np.linalg.norm(d, axis=-1) * stretch + offsets[None]


# Measured poses closer than this to one line (m) cannot fix the turn about it.
MIN_OFF_LINE = 0.05


def _off_line(points) -> float:
    """How far the points reach off their best straight line, m (0 for fewer than 3)."""
    points = np.asarray(points, dtype=float)
    if len(points) < 3:
        return 0.0
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred)
    off = centred - np.outer(centred @ vt[0], vt[0])
    return float(np.max(np.linalg.norm(off, axis=1)))


def measured_gauge(measured_positions, homing_positions) -> str:
    """What the measured poses fix: "homing+measured" (off one line through the homing
    poses: the turn; the homing poses keep the position); CalibrationError saying what
    would stay held otherwise."""
    P = np.asarray(measured_positions, dtype=float).reshape(-1, 3)
    H = np.asarray(homing_positions, dtype=float).reshape(-1, 3)
    spread = _off_line(np.vstack([P, H]))
    if len(P) >= 2 and spread >= MIN_OFF_LINE:
        return "homing+measured"
    raise CalibrationError(
        f"{len(P)} measured pose(s) with the homing pose reach {spread * 1e3:.1f} mm off one "
        f"straight line (at least 2 poses and {MIN_OFF_LINE * 1e3:.0f} mm needed): the turn "
        "of the base frame about that line would still be held at the file's; measure at "
        "least 2 poses off one line through the homing pose")


def calibrate(reels, attachments, lengths, positions, rotations=None, *, tensions=None,
              EA=None, run=None, fit_attachments=False, encoder_std=1e-4,
              prior=CalibrationPrior(), identified_std=5e-4, huber=3.0,
              max_iterations=50, measured=None) -> CalibrationResult:
    """Fit the geometry to encoder readings at K poses.

    reels, attachments: (m, 3) the file's geometry (the start of the fit and the prior's
    mean), m. lengths: (K, m) encoder readings, m. positions: (K, 3) and rotations (K, 3, 3)
    (None: the platform translates only, at the identity) the poses' first guesses (the
    controller's estimate on the file's geometry).
    tensions: (K, m) measured tensions, N, with EA the cables' stiffness, N (None: no stretch).
    run: (K,) which run each pose comes from, 0..R-1 (None: one run). Each run was homed at
    its first pose, which is known and stays fixed (the gauge of the base frame), and has its
    own encoder offsets (its homing's).
    encoder_std: one reading's noise, m (the residuals are weighed by it).
    measured: None, or (index (M,) of the pose measured, position (M, 3) m base frame,
    std (M,) m): externally measured positions; they release the turn the lengths cannot see
    (measured_gauge; CalibrationError when too few or on one line).
    """
    a0 = np.array(reels, dtype=float)
    b0 = np.array(attachments, dtype=float)
    e = np.asarray(lengths, dtype=float)
    K, m = e.shape
    full = rotations is not None
    if fit_attachments and not full:
        raise CalibrationError("the attachment points are fitted only with the full pose (a "
                               "translating platform's b_i and its position trade off)")
    R = (np.broadcast_to(np.eye(3), (K, 3, 3)).copy() if not full
         else np.array(rotations, dtype=float))
    p = np.array(positions, dtype=float)
    if not np.all(np.isfinite(e)):
        bad = np.argwhere(~np.isfinite(e))[0]
        raise CalibrationError(f"encoder length of cable {bad[1] + 1} at pose {bad[0]} is "
                               f"{e[tuple(bad)]!r}, not a finite number")
    run = np.zeros(K, dtype=int) if run is None else np.asarray(run, dtype=int)
    runs = int(run.max()) + 1
    first = np.array([int(np.flatnonzero(run == r)[0]) for r in range(runs)])
    gauge = "homing"
    if measured is not None:
        m_idx = np.asarray(measured[0], dtype=int)
        m_pos = np.asarray(measured[1], dtype=float).reshape(-1, 3)
        m_std = np.asarray(measured[2], dtype=float)
        gauge = measured_gauge(m_pos, p[first])
    else:
        m_idx, m_pos, m_std = np.zeros(0, dtype=int), np.zeros((0, 3)), np.zeros(0)
    M = m_idx.size
    free = np.setdiff1d(np.arange(K), first)
    stretch = np.ones((K, m))
    if tensions is not None:
        T = np.asarray(tensions, dtype=float)
        if np.all(np.isfinite(T)):
            stretch = 1.0 / (1.0 + T / float(EA))
    dof = 6 if full else 3
    # The parameters: a (3m), b (3m, fitted only), c (m per run), then the free poses.
    at_b = 3 * m
    at_c = at_b + (3 * m if fit_attachments else 0)
    n_geo = at_c + runs * m
    n = n_geo + dof * free.size
    gauge_count = 6 if fit_attachments else (0 if full or gauge != "homing" else 3)
    if K * m + 3 * M < n - gauge_count:
        need = int(np.ceil((n_geo - gauge_count) / max(m - dof, 1))) + runs
        raise CalibrationError(f"{K} poses give {K * m} encoder readings for {n} unknowns "
                               f"({n_geo} geometry, {dof} per pose after each run's first): "
                               f"record at least {need} distinct poses")
    col_of_pose = np.full(K, -1)
    col_of_pose[free] = n_geo + dof * np.arange(free.size)
    a, b = a0.copy(), b0.copy()
    # c's start: what the readings at the poses' guesses say (its mean per run and cable).
    base = predicted(a, b, np.zeros(m), p, R, stretch)
    c = np.array([np.mean((e - base)[run == r], axis=0) for r in range(runs)])
    c_prior = c.copy()
    residual_before = np.sqrt(np.mean((e - base - c[run]) ** 2, axis=0))
    prior_std = np.concatenate([np.full(3 * m, prior.reels_std),
                                np.full(3 * m if fit_attachments else 0,
                                        prior.attachments_std),
                                np.full(runs * m, prior.offsets_std)])

    def geometry():
        return np.concatenate([a.ravel()] + ([b.ravel()] if fit_attachments else [])
                              + [c.ravel()])

    def geometry0():
        return np.concatenate([a0.ravel()] + ([b0.ravel()] if fit_attachments else [])
                              + [c_prior.ravel()])

    rows = np.arange(m)

    def jacobian():
        """Residuals r (K m,) in sigmas and their Jacobian (K m, n), pose rotations
        linearised at the present estimate (d R = exp(dphi) R)."""
        w = np.einsum("kab,ib->kia", R, b)
        d = a[None] - p[:, None] - w
        L = np.linalg.norm(d, axis=-1)
        u = d / L[..., None]
        r = ((L * stretch + c[run]) - e) / encoder_std
        s = (stretch / encoder_std)[..., None]
        J = np.zeros((K, m, n))
        for axis in range(3):
            J[:, rows, 3 * rows + axis] = u[..., axis] * s[..., 0]
        if fit_attachments:
            dLdb = -np.einsum("kab,kia->kib", R, u) * s
            for axis in range(3):
                J[:, rows, at_b + 3 * rows + axis] = dLdb[..., axis]
        J[np.arange(K)[:, None], rows[None], at_c + run[:, None] * m + rows[None]] = \
            1.0 / encoder_std
        dLdp = -u * s
        dLdphi = np.cross(u, w) * s
        for k in free:
            col = col_of_pose[k]
            J[k, :, col:col + 3] = dLdp[k]
            if full:
                J[k, :, col + 3:col + 6] = dLdphi[k]
        r, J = r.ravel(), J.reshape(K * m, n)
        if M:
            # The measured positions: p_k - measured, in their own sigmas.
            r_m = ((p[m_idx] - m_pos) / m_std[:, None]).ravel()
            J_m = np.zeros((M, 3, n))
            for j, k in enumerate(m_idx):
                col = col_of_pose[k]
                if col >= 0:
                    J_m[j, :, col:col + 3] = np.eye(3) / m_std[j]
            r, J = np.concatenate([r, r_m]), np.vstack([J, J_m.reshape(3 * M, n)])
        return r, J

    # The gauge rows' weight: far stiffer than any reading (in sigmas per metre).
    gauge_weight = 1e3 / encoder_std

    def gauge_rows():
        """The directions lengths cannot see, held at the file. Translating platform: its
        lengths depend on a_i - b_i and p_k alone, so turning all of them about the homing
        pose changes no length; the exits' correction is kept orthogonal to that turn (the
        smallest correction that fits). Full pose with the attachments fitted: their
        centroid and orientation stay the file's (the homing pose's orientation fixes the
        base frame's)."""
        if fit_attachments:
            G = np.zeros((6, n))
            centre = b0.mean(axis=0)
            for i in range(m):
                cols = slice(at_b + 3 * i, at_b + 3 * i + 3)
                G[:3, cols] = np.eye(3)
                G[3:, cols] = _skew(b0[i] - centre)
            return G * gauge_weight
        if full or gauge != "homing":
            return np.zeros((0, n))
        G = np.zeros((3, n))
        for i in range(m):
            G[:, 3 * i:3 * i + 3] = _skew(a0[i] - b0[i] - p[0])
        return G * gauge_weight

    def deviation():
        """The geometry's deviation from the file as a full parameter vector (poses 0)."""
        x = np.zeros(n)
        x[:3 * m] = (a - a0).ravel()
        if fit_attachments:
            x[at_b:at_b + 3 * m] = (b - b0).ravel()
        return x

    G = gauge_rows()

    def cost(r):
        a_r = np.abs(r)
        rho = np.where(a_r <= huber, 0.5 * r * r, huber * a_r - 0.5 * huber ** 2)
        x = (geometry() - geometry0()) / prior_std
        g = G @ deviation()
        return float(np.sum(rho) + 0.5 * np.sum(x * x) + 0.5 * np.sum(g * g))

    lam, it = 1e-3, 0
    r, J = jacobian()
    current = cost(r)
    for it in range(1, max_iterations + 1):
        weights = np.where(np.abs(r) <= huber, 1.0, huber / np.maximum(np.abs(r), 1e-300))
        H = J.T @ (J * weights[:, None]) + G.T @ G
        g = J.T @ (weights * r) + G.T @ (G @ deviation())
        H[:n_geo, :n_geo] += np.diag(1.0 / prior_std ** 2)
        g[:n_geo] += (geometry() - geometry0()) / prior_std ** 2
        accepted = False
        while lam <= 1e8:
            step = -np.linalg.solve(H + lam * np.diag(np.diag(H)), g)
            saved = (a.copy(), b.copy(), c.copy(), p.copy(), R.copy())
            a += step[:3 * m].reshape(m, 3)
            if fit_attachments:
                b += step[at_b:at_b + 3 * m].reshape(m, 3)
            c += step[at_c:n_geo].reshape(runs, m)
            poses = step[n_geo:].reshape(free.size, dof)
            p[free] += poses[:, :3]
            if full:
                R[free] = rotation_exp_batch(poses[:, 3:]) @ R[free]
            r_new, J_new = jacobian()
            new = cost(r_new)
            if new <= current:
                lam = max(lam / 3, 1e-9)
                accepted = True
                break
            a, b, c, p, R = saved
            lam *= 4
        if not accepted:
            break
        gain = current - new
        r, J, current = r_new, J_new, new
        if gain <= 1e-9 * max(current, 1.0) or np.max(np.abs(step)) < 1e-8:
            break

    def schur(H):
        return H[:n_geo, :n_geo] - H[:n_geo, n_geo:] @ np.linalg.solve(
            H[n_geo:, n_geo:] + 1e-12 * np.eye(n - n_geo), H[n_geo:, :n_geo])

    # What the data identify: the data's information, no prior, the gauge's directions left
    # out (they carry none).
    eig = np.linalg.eigvalsh(schur(J.T @ J))[::-1][:n_geo - G.shape[0]]
    chi2 = float(np.sum(r * r)) / max(K * m + 3 * M - n + G.shape[0], 1)
    scale = max(1.0, chi2)
    # The standard deviations: the data's information and the prior's (the prior alone
    # bounds the gauge's directions: there a parameter is as uncertain as the file says).
    H_post = J.T @ J
    H_post[:n_geo, :n_geo] += np.diag(1.0 / prior_std ** 2)
    std = np.sqrt(np.clip(np.diag(np.linalg.inv(schur(H_post))) * scale, 0.0, None))
    # ... and in the frame the gauge holds (the homing pose and the file's orientation): how
    # well the geometry is known relative to itself, what the cables' distances depend on.
    H_post += G.T @ G
    std_in_frame = np.sqrt(np.clip(np.diag(np.linalg.inv(schur(H_post))) * scale, 0.0, None))
    names = parameter_names(m, fit_attachments, runs)
    unidentified = [names[k] for k in range(n_geo) if not std[k] <= identified_std]
    resid = e - predicted(a, b, np.zeros(m), p, R, stretch) - c[run]
    result = CalibrationResult(
        reels=a, attachments=b, offsets=c, reels_std=std[:3 * m].reshape(m, 3),
        reels_std_in_frame=std_in_frame[:3 * m].reshape(m, 3),
        attachments_std_in_frame=(std_in_frame[at_b:at_b + 3 * m].reshape(m, 3)
                                  if fit_attachments else np.zeros((m, 3))),
        attachments_std=(std[at_b:at_b + 3 * m].reshape(m, 3) if fit_attachments
                         else np.zeros((m, 3))),
        offsets_std=std[at_c:n_geo].reshape(runs, m), positions=p, rotations=R,
        residual_before=residual_before,
        residual_after=np.sqrt(np.mean(resid ** 2, axis=0)),
        singular_values=np.sqrt(np.clip(eig, 0.0, None)) * encoder_std,
        unidentified=unidentified, iterations=it, fit_attachments=fit_attachments,
        gauge=gauge, measured_residual=p[m_idx] - m_pos)
    return result


def select_poses(times, positions, lengths, *, speeds=None, min_spacing=0.03,
                 max_speed=0.02, max_poses=120):
    """Indices of the log's ticks to calibrate on: tick 0 (the homing pose) first, then ticks
    where the platform moves slower than `max_speed` m/s (a quasi-static pose: the cables'
    dynamics do not bias the lengths) and at least `min_spacing` m from every pose taken,
    at most `max_poses`, spread over the run."""
    positions = np.asarray(positions, dtype=float)
    if speeds is None:
        dt = np.gradient(np.asarray(times, dtype=float))
        speeds = np.linalg.norm(np.gradient(positions, axis=0), axis=1) / np.maximum(dt, 1e-12)
    chosen = [0]
    for k in range(1, len(positions)):
        if speeds[k] > max_speed or not np.all(np.isfinite(lengths[k])):
            continue
        if np.min(np.linalg.norm(positions[chosen] - positions[k], axis=1)) >= min_spacing:
            chosen.append(k)
    if len(chosen) > max_poses:
        keep = np.linspace(0, len(chosen) - 1, max_poses).round().astype(int)
        chosen = [chosen[i] for i in keep]
    return np.array(chosen, dtype=int)


def calibration_tour(robot, start, *, poses: int = 16, floor: float = 8.0, grid: int = 7,
                     inset: float = 0.12):
    """Waypoints (poses + 1, 3) m for a calibration motion from `start`: `poses` points
    spread over the workspace box (inset by `inset` of its size on each side), each where the
    cables hold the level platform with every tension at least `floor` N (t*, statics.py),
    picked farthest-first (the spread identifies the geometry) and visited nearest-first (a
    short tour). RobotError-free: fewer points where fewer hold."""
    from cdpm_drake.robot.statics import holding_tension

    lo, hi = robot.workspace.lower, robot.workspace.upper
    axes = [np.linspace(l + inset * (h - l), h - inset * (h - l), grid) for l, h in zip(lo, hi)]
    candidates = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    held = candidates[holding_tension(robot, candidates) >= floor]
    chosen = [np.asarray(start, dtype=float)]
    for _ in range(min(poses, len(held))):
        d = np.min(np.linalg.norm(held[:, None] - np.array(chosen)[None], axis=2), axis=1)
        chosen.append(held[np.argmax(d)])
    points = np.array(chosen)
    order, left = [0], set(range(1, len(points)))
    while left:
        last = points[order[-1]]
        k = min(left, key=lambda j: (np.linalg.norm(points[j] - last), j))
        order.append(k)
        left.remove(k)
    return points[order]


def tour_schedule(points, *, speed: float = 0.25, shortest: float = 2.5, dwell: float = 2.0):
    """(waypoints, times) of a spring hand that moves the platform along `points` at about
    `speed` m/s (each leg at least `shortest` s) and holds it `dwell` s at each: every point
    twice, at its arrival and its departure."""
    waypoints, times = [points[0], points[0]], [0.0, 1.0]
    t = 1.0
    for a, b in zip(points[:-1], points[1:]):
        t += max(shortest, float(np.linalg.norm(b - a)) / speed)
        waypoints.append(b)
        times.append(round(t, 1))
        t += dwell
        waypoints.append(b)
        times.append(round(t, 1))
    return np.round(np.array(waypoints), 2), times
