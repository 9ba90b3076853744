"""Numba kernels of the ALE update's loops: surface curve, bilinear inversion, surface slides
(``ale.motion``, ``ale.surface.local_slides``), moved nodes and cell checks, the remap's hinted
point location and interpolation.

Each is the loop form of the NumPy code it replaces in ``ale.surface``, ``ale.motion`` and
``ale.remap``, with the same operations in the same order and the same iteration rule: the Newton
loops run over the whole batch until every member has converged (as the vectorized code did),
sums of arrays follow NumPy's pairwise order (``_pairwise_sum``) and the einsums' order. The
kernels that replaced the surface slides, the cell checks and the remap's location and
interpolation give the NumPy code's results bit for bit (``tests/test_ale_kernels.py``); the
curve kernels agree with it to round-off of the reordered arc-length quadrature. The arrays are
tiny (a few points on a chain of tens of segments), so the NumPy versions were dominated by
per-call overhead.
"""

from __future__ import annotations

import numpy as np

from ..jit import njit

# 8-point Gauss-Legendre on [0, 1] (as ale.surface)
_GX, _GW = np.polynomial.legendre.leggauss(8)
GAUSS_U = 0.5 * (_GX + 1.0)
GAUSS_W = 0.5 * _GW
CONVERGED = 1e-14  # Newton updates of a local parameter u in [0, 1] below this: round-off


@njit(cache=True, inline="always")
def _eval(points, bulge, seg, u):
    """Position and dx/du of segment ``seg`` at u: (x0, x1, dx0, dx1)."""
    p0, p1 = points[seg, 0], points[seg, 1]
    d0, d1 = points[seg + 1, 0] - p0, points[seg + 1, 1] - p1
    q0, q1 = bulge[seg, 0], bulge[seg, 1]
    w = u * (u - 1.0)
    c = 2.0 * u - 1.0
    return p0 + u * d0 + w * q0, p1 + u * d1 + w * q1, d0 + c * q0, d1 + c * q1


@njit(cache=True)
def _arc(points, bulge, seg, u, gauss_u, gauss_w):
    """Arc length from the start of segment ``seg`` to u (8-point Gauss)."""
    total = 0.0
    for g in range(gauss_u.size):
        _, _, dx0, dx1 = _eval(points, bulge, seg, u * gauss_u[g])
        total += np.sqrt(dx0 * dx0 + dx1 * dx1) * gauss_w[g]
    return u * total


@njit(cache=True)
def bulges(points, breaks):
    """``ale.surface._bulges`` (elementwise, in its operations' order): q_i of every segment."""
    n = points.shape[0]
    h = np.empty(n - 1)
    slope = np.empty((n - 1, 2))
    for i in range(n - 1):
        c0, c1 = points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1]
        h[i] = np.sqrt(c0 * c0 + c1 * c1)
        w = h[i] if h[i] > 0 else 1.0
        slope[i, 0], slope[i, 1] = c0 / w, c1 / w
    d2 = np.zeros((n, 2))
    tiny = np.finfo(np.float64).tiny
    for i in range(1, n - 1):
        span = h[i] + h[i - 1]
        if not (span >= tiny or np.isnan(span)):  # np.maximum(span, tiny), NaN kept
            span = tiny
        d2[i, 0] = (slope[i, 0] - slope[i - 1, 0]) / span
        d2[i, 1] = (slope[i, 1] - slope[i - 1, 1]) / span
    out = np.empty((n - 1, 2))
    for i in range(n - 1):
        left, right = 0.0 if breaks[i] else 1.0, 0.0 if breaks[i + 1] else 1.0
        count = max(int(left) + int(right), 1)
        factor = h[i] * h[i] / count
        for k in range(2):
            out[i, k] = factor * (d2[i, k] * left + d2[i + 1, k] * right)
    return out


@njit(cache=True)
def segment_speeds(points, bulge, gauss_u):
    """|dx/du| of every segment at the Gauss points u (n - 1, g): the integrand of the
    segment lengths (``SurfaceCurve._arc`` with u = 1 before its quadrature sum)."""
    out = np.empty((bulge.shape[0], gauss_u.size))
    for i in range(bulge.shape[0]):
        for g in range(gauss_u.size):
            _, _, dx0, dx1 = _eval(points, bulge, i, 1.0 * gauss_u[g])
            out[i, g] = np.sqrt(dx0 * dx0 + dx1 * dx1)
    return out


@njit(cache=True)
def end_tangents(points, bulge, breaks):
    """``SurfaceCurve._tangents``: unit tangents at the start and end of every segment, the
    normalized mean of the two one-sided tangents at a smooth node."""
    m = bulge.shape[0]
    start, end = np.empty((m, 2)), np.empty((m, 2))
    for i in range(m):
        d0, d1 = points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1]
        s0, s1 = d0 - bulge[i, 0], d1 - bulge[i, 1]
        e0, e1 = d0 + bulge[i, 0], d1 + bulge[i, 1]
        ns, ne = np.sqrt(s0 * s0 + s1 * s1), np.sqrt(e0 * e0 + e1 * e1)
        start[i, 0], start[i, 1] = s0 / ns, s1 / ns
        end[i, 0], end[i, 1] = e0 / ne, e1 / ne
    for i in range(m - 1):  # node i + 1 joins segments i and i + 1
        if breaks[i + 1]:
            continue
        a0, a1 = end[i, 0] + start[i + 1, 0], end[i, 1] + start[i + 1, 1]
        na = np.sqrt(a0 * a0 + a1 * a1)
        a0, a1 = a0 / na, a1 / na
        end[i, 0], end[i, 1] = a0, a1
        start[i + 1, 0], start[i + 1, 1] = a0, a1
    return start, end


@njit(cache=True)
def segment_of(points, bulge, node_s, s, gauss_u, gauss_w):
    """Segment and local u of arc-length positions s (``SurfaceCurve._segment_of``)."""
    n_seg = bulge.shape[0]
    length = node_s[-1]
    p = s.size
    seg = np.empty(p, np.int64)
    u = np.empty(p)
    ds = np.empty(p)
    for i in range(p):
        si = min(max(s[i], 0.0), length)
        k = np.searchsorted(node_s, si, side="right") - 1
        k = min(max(k, 0), n_seg - 1)
        seg[i] = k
        ds[i] = si - node_s[k]
        seg_len = node_s[k + 1] - node_s[k]
        u[i] = ds[i] / seg_len if seg_len > 0 else 0.0
    for _ in range(6):  # Newton on arc(u) = ds, stopped when every step is round-off
        moving = False
        for i in range(p):
            _, _, dx0, dx1 = _eval(points, bulge, seg[i], u[i])
            speed = np.sqrt(dx0 * dx0 + dx1 * dx1)
            step = 0.0
            if speed > 0:
                step = (_arc(points, bulge, seg[i], u[i], gauss_u, gauss_w) - ds[i]) / speed
            u[i] = min(max(u[i] - step, 0.0), 1.0)
            if np.abs(step) > CONVERGED:
                moving = True
        if not moving:
            break
    return seg, u


@njit(cache=True)
def point_at(points, bulge, node_s, s, gauss_u, gauss_w):
    """Positions (p, 2) at arc-length parameters s (``SurfaceCurve.point_at``)."""
    seg, u = segment_of(points, bulge, node_s, s, gauss_u, gauss_w)
    out = np.empty((s.size, 2))
    for i in range(s.size):
        x0, x1, _, _ = _eval(points, bulge, seg[i], u[i])
        out[i, 0], out[i, 1] = x0, x1
    return out


@njit(cache=True)
def _nearest_segments(points, bulge, pts, keep):
    """Per point the ``keep`` segments with the closest of 9 samples each (stable order)."""
    n_seg = bulge.shape[0]
    p = pts.shape[0]
    out = np.empty((p, keep), np.int64)
    nearest = np.empty(n_seg)
    for i in range(p):
        for k in range(n_seg):
            best = np.inf
            for j in range(9):
                x0, x1, _, _ = _eval(points, bulge, k, j / 8.0)
                r0, r1 = x0 - pts[i, 0], x1 - pts[i, 1]
                best = min(best, np.sqrt(r0 * r0 + r1 * r1))
            nearest[k] = best
        taken = np.zeros(n_seg, np.bool_)
        for c in range(keep):  # repeated minimum, ties to the lower index: a stable argsort
            pick = -1
            for k in range(n_seg):
                if not taken[k] and (pick < 0 or nearest[k] < nearest[pick]):
                    pick = k
            taken[pick] = True
            out[i, c] = pick
    return out


@njit(cache=True, inline="always")
def _foot_residual(points, bulge, seg, u, t00, t01, t10, t11, p0, p1):
    """f(u) = (p - x(u)) . t(u) and df/du of ``SurfaceCurve.normal_foot``."""
    x0, x1, dx0, dx1 = _eval(points, bulge, seg, u)
    e0, e1 = t10 - t00, t11 - t01
    t0, t1 = t00 + u * e0, t01 + u * e1
    r0, r1 = p0 - x0, p1 - x1
    return r0 * t0 + r1 * t1, (r0 * e0 + r1 * e1) - (dx0 * t0 + dx1 * t1)


@njit(cache=True)
def normal_foot(points, bulge, node_s, t_start, t_end, pts, gauss_u, gauss_w):
    """Arc-length parameters and positions of the normal feet (``SurfaceCurve.normal_foot``)."""
    p = pts.shape[0]
    keep = min(3, bulge.shape[0])
    seg = _nearest_segments(points, bulge, pts, keep)
    f0 = np.empty((p, keep))
    root = np.empty((p, keep), np.bool_)
    u = np.empty((p, keep))
    lo = np.zeros((p, keep))
    hi = np.ones((p, keep))
    for i in range(p):
        for c in range(keep):
            k = seg[i, c]
            a, _ = _foot_residual(points, bulge, k, 0.0, t_start[k, 0], t_start[k, 1],
                                  t_end[k, 0], t_end[k, 1], pts[i, 0], pts[i, 1])
            b, _ = _foot_residual(points, bulge, k, 1.0, t_start[k, 0], t_start[k, 1],
                                  t_end[k, 0], t_end[k, 1], pts[i, 0], pts[i, 1])
            f0[i, c] = a
            root[i, c] = (a >= 0.0) and (b <= 0.0)
            if root[i, c]:
                u[i, c] = a / ((a - b) if a > b else 1.0)
            else:
                u[i, c] = 0.0 if a < 0 else 1.0
    for _ in range(30):  # Newton on the bracketed cubic, bisection when it leaves the bracket
        moving = False
        for i in range(p):
            for c in range(keep):
                k = seg[i, c]
                uc = u[i, c]
                f, df = _foot_residual(points, bulge, k, uc, t_start[k, 0], t_start[k, 1],
                                       t_end[k, 0], t_end[k, 1], pts[i, 0], pts[i, 1])
                if f > 0.0:
                    lo[i, c] = uc
                else:
                    hi[i, c] = uc
                step = f / df if df < 0.0 else np.inf
                new = uc - step
                if not (new >= lo[i, c] and new <= hi[i, c]):
                    new = 0.5 * (lo[i, c] + hi[i, c])
                if not (root[i, c] and f != 0.0):
                    new = uc
                if np.abs(new - uc) > CONVERGED:
                    moving = True
                u[i, c] = new
        if not moving:
            break
    s = np.empty(p)
    foot = np.empty((p, 2))
    for i in range(p):
        best, best_d, none = 0, np.inf, True
        for c in range(keep):
            if root[i, c]:
                none = False
                x0, x1, _, _ = _eval(points, bulge, seg[i, c], u[i, c])
                r0, r1 = x0 - pts[i, 0], x1 - pts[i, 1]
                dist = np.sqrt(r0 * r0 + r1 * r1)
                if dist < best_d:
                    best, best_d = c, dist
        if none:  # beyond a break: the nearest candidate's nearer end
            best_d = np.inf
            for c in range(keep):
                x0, x1, _, _ = _eval(points, bulge, seg[i, c], 0.0 if f0[i, c] < 0 else 1.0)
                r0, r1 = x0 - pts[i, 0], x1 - pts[i, 1]
                dist = np.sqrt(r0 * r0 + r1 * r1)
                if dist < best_d:
                    best, best_d = c, dist
        k, uc = seg[i, best], u[i, best]
        s[i] = node_s[k] + _arc(points, bulge, k, uc, gauss_u, gauss_w)
        foot[i, 0], foot[i, 1], _, _ = _eval(points, bulge, k, uc)
    return s, foot


@njit(cache=True)
def inverse_bilinear(cell_xy, points, iterations):
    """Reference coordinates (m, 2) and residual distances (m,) of points in Q4 cells
    (``ale.remap.inverse_bilinear`` for (m, 4, 2) cells and (m, 2) points)."""
    m = points.shape[0]
    a = np.empty((m, 4, 2))  # a0 (minus the point), a1, a2, a3 of x = a0 + a1 xi + ...
    for e in range(m):
        for i in range(2):
            x0, x1, x2, x3 = cell_xy[e, 0, i], cell_xy[e, 1, i], cell_xy[e, 2, i], cell_xy[e, 3, i]
            a[e, 0, i] = 0.25 * (x0 + x1 + x2 + x3) - points[e, i]
            a[e, 1, i] = 0.25 * (-x0 + x1 + x2 - x3)
            a[e, 2, i] = 0.25 * (-x0 - x1 + x2 + x3)
            a[e, 3, i] = 0.25 * (x0 - x1 + x2 - x3)
    xi = np.zeros((m, 2))
    for _ in range(iterations):
        change = 0.0
        for e in range(m):
            x, y = xi[e, 0], xi[e, 1]
            xy = x * y
            r0 = a[e, 0, 0] + a[e, 1, 0] * x + a[e, 2, 0] * y + a[e, 3, 0] * xy
            r1 = a[e, 0, 1] + a[e, 1, 1] * x + a[e, 2, 1] * y + a[e, 3, 1] * xy
            g10, g11 = a[e, 1, 0] + a[e, 3, 0] * y, a[e, 1, 1] + a[e, 3, 1] * y
            g20, g21 = a[e, 2, 0] + a[e, 3, 0] * x, a[e, 2, 1] + a[e, 3, 1] * x
            det = g10 * g21 - g11 * g20
            if not np.abs(det) > 0:
                det = 1.0
            nx = min(max(x - (g21 * r0 - g20 * r1) / det, -4.0), 4.0)
            ny = min(max(y - (g10 * r1 - g11 * r0) / det, -4.0), 4.0)
            change = max(change, np.abs(nx - x), np.abs(ny - y))
            xi[e, 0], xi[e, 1] = nx, ny
        if change <= 1e-15:  # converged to round-off of O(1) reference coordinates
            break
    res = np.empty(m)
    for e in range(m):
        x, y = xi[e, 0], xi[e, 1]
        xy = x * y
        r0 = a[e, 0, 0] + a[e, 1, 0] * x + a[e, 2, 0] * y + a[e, 3, 0] * xy
        r1 = a[e, 0, 1] + a[e, 1, 1] * x + a[e, 2, 1] * y + a[e, 3, 1] * xy
        res[e] = np.sqrt(r0 * r0 + r1 * r1)
    return xi, res


@njit(cache=True)
def cell_min_sines(nodes, cells, which):
    """Smallest corner sine of the cells ``which`` (``ale.smoothing.cell_min_sines``)."""
    out = np.empty(which.size)
    for k in range(which.size):
        e = which[k]
        low = np.inf
        for c in range(4):
            i, j, h = cells[e, c], cells[e, (c + 1) % 4], cells[e, (c + 3) % 4]
            a0, a1 = nodes[j, 0] - nodes[i, 0], nodes[j, 1] - nodes[i, 1]
            b0, b1 = nodes[h, 0] - nodes[i, 0], nodes[h, 1] - nodes[i, 1]
            cross = a0 * b1 - a1 * b0
            scale = np.sqrt((a0 * a0 + a1 * a1) * (b0 * b0 + b1 * b1))
            low = min(low, cross / scale if scale > 0 else -1.0)
        out[k] = low
    return out


@njit(cache=True)
def any_min_sine_below(nodes, cells, which, tol):
    """``np.any(cell_min_sines(nodes, cells, which) <= tol)`` without the array (NaN: False)."""
    q = cell_min_sines(nodes, cells, which)
    for k in range(q.size):
        if q[k] <= tol:
            return True
    return False


@njit(cache=True)
def element_masses(X, cells, which, density, dn, shape):
    """Per cell of ``which`` its 4 lumped nodal masses (``ale.motion._element_masses``);
    ``dn`` (g, a, k) natural gradients and ``shape`` (g, a) shape values at the Gauss points,
    ``density`` per cell of ``which``."""
    out = np.zeros((which.size, 4))
    det = np.empty(4)
    for k in range(which.size):
        e = which[k]
        for g in range(4):
            j00 = j01 = j10 = j11 = 0.0  # J_ik = dx_i / dxi_k
            for a in range(4):
                n = cells[e, a]
                j00 += dn[g, a, 0] * X[n, 0]
                j01 += dn[g, a, 1] * X[n, 0]
                j10 += dn[g, a, 0] * X[n, 1]
                j11 += dn[g, a, 1] * X[n, 1]
            det[g] = (j00 * j11 - j01 * j10) * density[k]
        for a in range(4):
            total = 0.0
            for g in range(4):
                total += det[g] * shape[g, a]
            out[k, a] = total
    return out


@njit(cache=True)
def masses_after(X, cells, which, density, dn, shape, old_element_masses, masses):
    """``_TnState.masses_after``: the lumped masses ``masses`` with the element masses of the
    cells ``which`` (``old_element_masses`` per cell) replaced by those of X; ``density`` per
    cell. The changes are accumulated as ``np.bincount`` does (from zero, in cell order) and
    then added, so the result is the NumPy expression's bit for bit."""
    dens = np.empty(which.size)
    for k in range(which.size):
        dens[k] = density[which[k]]
    change = element_masses(X, cells, which, dens, dn, shape)
    add = np.zeros(masses.size)
    for k in range(which.size):
        e = which[k]
        for a in range(4):
            add[cells[e, a]] += change[k, a] - old_element_masses[e, a]
    out = np.empty(masses.size)
    for i in range(masses.size):
        out[i] = masses[i] + add[i]
    return out


# --- surface slides (ale.motion._surface_slides, ale.surface.local_slides) -------------------


@njit(cache=True)
def _block_sum(a, lo, n):
    """NumPy's pairwise sum of a block of at most 128 values (eight accumulators)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = a[lo + j]
    i = 8
    while i < n - (n % 8):
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pairwise_sum(a, lo, n):
    """Sum of a[lo:lo + n] in NumPy's order (``np.sum`` of a contiguous float64 array: blocks
    of at most 128 summed by ``_block_sum``, halves (multiples of 8) added above that), so the
    results agree bit for bit. The halving is unrolled with an explicit stack: a recursive
    function loaded from Numba's cache crashed."""
    if n <= 128:
        return _block_sum(a, lo, n)
    frame_lo = np.empty(64, np.int64)
    frame_n = np.empty(64, np.int64)
    frame_state = np.empty(64, np.int64)
    values = np.empty(64)
    depth, count = 1, 0
    frame_lo[0], frame_n[0], frame_state[0] = lo, n, 0
    while depth > 0:
        top = depth - 1
        start, size = frame_lo[top], frame_n[top]
        if size <= 128:
            values[count] = _block_sum(a, start, size)
            count += 1
            depth -= 1
            continue
        half = size // 2
        half -= half % 8
        if frame_state[top] < 2:  # push the left half, then the right one
            right = frame_state[top] == 1
            frame_state[top] += 1
            frame_lo[depth] = start + half if right else start
            frame_n[depth] = size - half if right else half
            frame_state[depth] = 0
            depth += 1
        else:
            values[count - 2] = values[count - 2] + values[count - 1]
            count -= 1
            depth -= 1
    return values[0]


@njit(cache=True)
def wanted_arc(points, bulge, node_s, t_start, t_end, breaks, pts, pos, snap, gauss_u,
               gauss_w):
    """``ale.motion._wanted_arc`` with the active nodes' tangents (``node_tangents(pos)``)."""
    s, foot = normal_foot(points, bulge, node_s, t_start, t_end, pts, gauss_u, gauss_w)
    n = node_s.size
    h_min = np.inf
    for i in range(n - 1):
        h_min = min(h_min, node_s[i + 1] - node_s[i])
    out = np.empty(s.size)
    for i in range(s.size):
        gap = np.inf
        for j in range(n):
            if breaks[j]:
                gap = min(gap, np.abs(s[i] - node_s[j]))
        k = pos[i]
        if k == n - 1:
            t0, t1 = t_end[max(k - 1, 0), 0], t_end[max(k - 1, 0), 1]
        else:
            t0, t1 = t_start[min(k, n - 2), 0], t_start[min(k, n - 2), 1]
        over = (pts[i, 0] - foot[i, 0]) * t0 + (pts[i, 1] - foot[i, 1]) * t1
        out[i] = s[i] + (over if gap <= snap * h_min else 0.0)
    return out


@njit(cache=True)
def _true_indices(mask):
    """Indices of the True entries of a boolean array (np.flatnonzero)."""
    count = 0
    for i in range(mask.size):
        count += mask[i]
    out = np.empty(count, np.int64)
    c = 0
    for i in range(mask.size):
        if mask[i]:
            out[c] = i
            c += 1
    return out


@njit(cache=True)
def anchor_targets(node_s, breaks, pos, wanted, slide_tolerance, ratio, snap):
    """Targets of the active nodes (``ale.motion._clamp_slides`` of the wanted arc lengths,
    slides below the tolerance dropped) and the anchors; (targets, clamped, mismatch, anchor
    indices, anchor slides, first pair of anchors out of order or -1)."""
    n, k = node_s.size, pos.size
    brk = _true_indices(breaks)
    n_brk = brk.size
    run_min = np.empty(max(n_brk - 1, 1))
    for r in range(n_brk - 1):
        low = node_s[brk[r] + 1] - node_s[brk[r]]
        for i in range(brk[r] + 1, brk[r + 1]):
            low = min(low, node_s[i + 1] - node_s[i])
        run_min[r] = low
    targets = np.empty(k)
    clamped = np.zeros(k, np.bool_)
    mismatch = 0.0
    for i in range(k):
        p = pos[i]
        near = min(node_s[max(p - 1, 0) + 1] - node_s[max(p - 1, 0)],
                   node_s[min(p, n - 2) + 1] - node_s[min(p, n - 2)])
        w = wanted[i]
        if np.abs(w - node_s[p]) <= slide_tolerance * near:
            w = node_s[p]
        j = np.searchsorted(brk, p)
        run = min(max(j - 1, 0), n_brk - 2)
        b0, b1 = brk[run], brk[run + 1]
        h = ratio * run_min[run]
        if brk[min(j, n_brk - 1)] == p:
            t = node_s[p]
        else:
            lo = min(node_s[b0] + (p - b0) * h, node_s[p])
            hi = max(node_s[b1] - (b1 - p) * h, node_s[p])
            t = min(max(w, lo), hi)
        targets[i] = t
        clamped[i] = np.abs(t - w) > snap * run_min[run]
        miss = np.abs(wanted[i] - t)
        if not (miss <= mismatch) and not np.isnan(mismatch):
            mismatch = miss
    anchor = breaks.copy()
    s = node_s.copy()
    slide = np.zeros(n)
    for i in range(k):
        anchor[pos[i]] = True
        s[pos[i]] = targets[i]
        slide[pos[i]] = targets[i] - node_s[pos[i]]
    idx = _true_indices(anchor)
    n_anchor = idx.size
    bad = -1
    for i in range(n_anchor - 1):
        if s[idx[i + 1]] - s[idx[i]] <= 0.0:
            bad = i
            break
    return targets, clamped, mismatch, idx, slide[idx], bad


@njit(cache=True)
def _buffer(cur, target, slide, lo, hi, reverse, out):
    """``ale.surface._buffer`` on cur (reversed if ``reverse``): fills out[:m] with the length
    changes of the m leading segments and returns m, or -1 if the whole run cannot absorb it."""
    n = cur.size
    change = -slide
    total = 0.0
    m = -1
    for i in range(n):
        j = n - 1 - i if reverse else i
        room = cur[j] - lo * target[j] if change < 0.0 else hi * target[j] - cur[j]
        out[i] = max(room, 0.0)
        total += out[i]
        if total >= np.abs(change):
            m = i + 1
            break
    if m < 0:
        return -1
    for i in range(m):
        out[i] = change * out[i] / total
    return m


@njit(cache=True)
def local_slides(s, ref, idx, slide, lo, hi):
    """``ale.surface.local_slides`` (validated inputs, band [lo, hi]); (slides, resets)."""
    out = np.zeros(s.size)
    for k in range(idx.size):
        out[idx[k]] = slide[k]
    resets = 0
    for k in range(idx.size - 1):
        a, b, sa, sb = idx[k], idx[k + 1], slide[k], slide[k + 1]
        if b - a < 2 or (sa == 0.0 and sb == 0.0):
            continue
        cur = np.empty(b - a)
        for i in range(b - a):
            cur[i] = s[a + i + 1] - s[a + i]
        rseg = ref[a:b]
        scale = _pairwise_sum(cur, 0, cur.size) / _pairwise_sum(rseg, 0, rseg.size)
        target = rseg * scale
        head, tail = np.empty(b - a), np.empty(b - a)
        m_head = _buffer(cur, target, sa, lo, hi, False, head) if sa != 0.0 else 0
        m_tail = _buffer(cur, target, -sb, lo, hi, True, tail) if sb != 0.0 else 0
        if m_head >= 0 and m_tail >= 0 and m_head + m_tail <= b - a:
            acc = 0.0
            for i in range(m_head - 1):
                acc += head[i]
                out[a + 1 + i] = sa + acc
            acc = 0.0
            for i in range(m_tail - 1):
                acc += tail[i]
                out[b - 1 - i] = sb - acc
            continue
        change = sb - sa  # of the run's length
        slack = np.empty(b - a)
        for i in range(b - a):
            room = cur[i] - lo * target[i] if change < 0.0 else hi * target[i] - cur[i]
            slack[i] = max(room, 0.0)
        total = _pairwise_sum(slack, 0, slack.size)
        if change == 0.0:
            out[a + 1:b] = sa
        elif total >= np.abs(change):
            acc = 0.0
            for i in range(b - a - 1):
                acc += slack[i]
                out[a + 1 + i] = sa + change * acc / total
        else:
            resets += 1
            cum = np.empty(b - a + 1)
            cum[0] = 0.0
            for i in range(b - a):
                cum[i + 1] = cum[i] + rseg[i]
            span = (s[b] - s[a]) + change
            for i in range(1, b - a):
                out[a + i] = sa + cum[i] / cum[b - a] * span - (s[a + i] - s[a])
    return out, resets


@njit(cache=True)
def slid_positions(x, chain_nodes, breaks, points, bulge, node_s, slides, snap_length,
                   gauss_u, gauss_w):
    """Node positions with the chain nodes slid along the curve (``ale.motion._move_surface``):
    a move below ``snap_length`` keeps the old position exactly."""
    n = slides.size
    count = 0
    for i in range(n):
        count += slides[i] != 0.0 and not breaks[i]
    which = np.empty(count, np.int64)
    s = np.empty(count)
    c = 0
    for i in range(n):
        if slides[i] != 0.0 and not breaks[i]:
            which[c] = i
            s[c] = node_s[i] + slides[i]
            c += 1
    out = x.copy()
    if count == 0:
        return out
    new = point_at(points, bulge, node_s, s, gauss_u, gauss_w)
    for c in range(count):
        i = which[c]
        r0, r1 = new[c, 0] - points[i, 0], new[c, 1] - points[i, 1]
        if np.sqrt(r0 * r0 + r1 * r1) > snap_length:
            out[chain_nodes[i], 0], out[chain_nodes[i], 1] = new[c, 0], new[c, 1]
    return out


# --- remap (ale.remap.Remapper: hinted point location, interpolation) ------------------------

_CORNER_XI = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


@njit(cache=True)
def _nearest_on_cell_boundary(cell_xy, e, p0, p1):
    """Closest point of cell e's straight edges to (p0, p1) (``ale.remap._nearest_on_boundary``
    for one cell and point); (distance, xi0, xi1, local edge)."""
    best_dist, best_t, edge = np.inf, 0.0, 0
    for k in range(4):
        a0, a1 = cell_xy[e, k, 0], cell_xy[e, k, 1]
        d0, d1 = cell_xy[e, (k + 1) % 4, 0] - a0, cell_xy[e, (k + 1) % 4, 1] - a1
        t = (p0 - a0) * d0 + (p1 - a1) * d1
        t = min(max(t / max(d0 * d0 + d1 * d1, 1e-300), 0.0), 1.0)
        r0, r1 = a0 + t * d0 - p0, a1 + t * d1 - p1
        dist = np.sqrt(r0 * r0 + r1 * r1)
        if k == 0 or dist < best_dist:  # argmin: the first minimum
            best_dist, best_t, edge = dist, t, k
    s0, s1 = _CORNER_XI[edge, 0], _CORNER_XI[edge, 1]
    e0, e1 = _CORNER_XI[(edge + 1) % 4, 0], _CORNER_XI[(edge + 1) % 4, 1]
    return best_dist, s0 + best_t * (e0 - s0), s1 + best_t * (e1 - s1), edge


@njit(cache=True)
def locate_in_hints(cell_xy, cell_size, outer_edge, pts, hint, outside_tol, inside_tol,
                    iterations):
    """``Remapper._try_hints``: (cell or -1, xi, clamped) of points found in their hint cell or
    just outside one of its mesh-boundary edges (clamped onto it). The hinted points are
    inverted as one batch, as in the NumPy code (the Newton loop stops for the whole batch)."""
    n = pts.shape[0]
    cell = np.full(n, -1, np.int64)
    xi = np.zeros((n, 2))
    clamped = np.zeros(n, np.bool_)
    which = _true_indices(hint >= 0)
    count = which.size
    batch_xy = np.empty((count, 4, 2))
    batch_pts = np.empty((count, 2))
    for c in range(count):
        batch_xy[c] = cell_xy[hint[which[c]]]
        batch_pts[c] = pts[which[c]]
    found, res = inverse_bilinear(batch_xy, batch_pts, iterations)
    for c in range(count):
        i, h = which[c], hint[which[c]]
        if (max(np.abs(found[c, 0]), np.abs(found[c, 1])) <= 1.0 + inside_tol
                and res[c] <= 1e-9 * cell_size[h]):
            cell[i], xi[i, 0], xi[i, 1] = h, found[c, 0], found[c, 1]
            continue
        p0, p1 = pts[i, 0], pts[i, 1]
        dist, x0, x1, edge = _nearest_on_cell_boundary(cell_xy, h, p0, p1)
        a0, a1 = cell_xy[h, edge, 0], cell_xy[h, edge, 1]
        b0, b1 = cell_xy[h, (edge + 1) % 4, 0], cell_xy[h, (edge + 1) % 4, 1]
        outward = (b0 - a0) * (p1 - a1) - (b1 - a1) * (p0 - a0) < 0.0  # right of a -> b
        if outer_edge[h, edge] and outward and dist <= outside_tol * cell_size[h]:
            cell[i], xi[i, 0], xi[i, 1], clamped[i] = h, x0, x1, True
    return cell, xi, clamped


@njit(cache=True)
def interpolate(nodes, cells, fields, cell, xi, pts, gradients, quadratic):
    """``Remapper.remap``'s interpolant at located points: Q4 values (4.18) and, if
    ``quadratic``, the gradient-enhanced terms with ``gradients`` (p, 4, k, 2) of the cells'
    nodes. Summed in the order of the NumPy einsums it replaces (per point over the corners;
    the two gradient terms over the corners of per-corner sums over the two coordinates)."""
    p, k = pts.shape[0], fields.shape[1]
    out = np.zeros((p, k))
    shape = np.empty(4)
    for q in range(p):
        e = cell[q]
        for a in range(4):
            shape[a] = 0.25 * (1.0 + xi[q, 0] * _CORNER_XI[a, 0]) * (
                1.0 + xi[q, 1] * _CORNER_XI[a, 1])
        for j in range(k):
            total = 0.0
            for a in range(4):
                total += shape[a] * fields[cells[e, a], j]
            out[q, j] = total
        if not quadratic:
            continue
        off0, off1 = 0.0, 0.0  # p - x(xi): a clamped point lies off its cell
        for a in range(4):
            off0 += shape[a] * nodes[cells[e, a], 0]
            off1 += shape[a] * nodes[cells[e, a], 1]
        off0, off1 = pts[q, 0] - off0, pts[q, 1] - off1
        for j in range(k):
            near = 0.0
            for a in range(4):
                n = cells[e, a]
                g0, g1 = gradients[q, a, j, 0], gradients[q, a, j, 1]
                near += shape[a] * g0 * (pts[q, 0] - nodes[n, 0]) + shape[a] * g1 * (
                    pts[q, 1] - nodes[n, 1])
            out[q, j] = out[q, j] + 0.5 * near
        for j in range(k):
            far = 0.0
            for a in range(4):
                g0, g1 = gradients[q, a, j, 0], gradients[q, a, j, 1]
                far += shape[a] * g0 * off0 + shape[a] * g1 * off1
            out[q, j] = out[q, j] + 0.5 * far
    return out


@njit(cache=True)
def interpolate_at_nodes(nodes, cells, fields, cell, xi, pts, gradients, quadratic, cell_size,
                         same_node):
    """``interpolate``, except that a point within ``same_node`` times its cell's size of a
    corner of its cell takes that node's values exactly (``Remapper.remap``: unmoved nodes keep
    their fields). In a conforming mesh a point on an old node is located in a cell with that
    node as a corner (inside, or clamped onto its boundary), so the corners are the only
    candidates: this replaces a k-d tree query over all nodes, with the same distance
    (sqrt(d0^2 + d1^2)) and the same test."""
    out = interpolate(nodes, cells, fields, cell, xi, pts, gradients, quadratic)
    for q in range(pts.shape[0]):
        e = cell[q]
        best, near = np.inf, -1
        for a in range(4):
            n = cells[e, a]
            d0, d1 = pts[q, 0] - nodes[n, 0], pts[q, 1] - nodes[n, 1]
            dist = np.sqrt(d0 * d0 + d1 * d1)
            if dist < best:
                best, near = dist, n
        if best <= same_node * cell_size[e]:
            for j in range(fields.shape[1]):
                out[q, j] = fields[near, j]
    return out


# --- contact nodes of an ALE body (ntncontact.mesh_motion) ------------------------------------


@njit(cache=True)
def body_pairs(pairs, lo, hi):
    """(own node, partner) of the pairs (m, 2) with a node in [lo, hi): first the pairs whose
    body-2 node (column 1) is there, then those whose body-1 node is, each in pair order."""
    m = pairs.shape[0]
    count = 0
    for side in (1, 0):
        for r in range(m):
            count += lo <= pairs[r, side] < hi
    own = np.empty(count, np.int64)
    partner = np.empty(count, np.int64)
    c = 0
    for side in (1, 0):
        for r in range(m):
            if lo <= pairs[r, side] < hi:
                own[c], partner[c] = pairs[r, side], pairs[r, 1 - side]
                c += 1
    return own, partner


@njit(cache=True)
def first_occurrences(values):
    """Indices (ascending) of the first occurrence of each value: ``np.sort(np.unique(values,
    return_index=True)[1])``."""
    order = np.argsort(values, kind="mergesort")  # stable: equal values in index order
    keep = np.zeros(values.size, np.bool_)
    for k in range(values.size):
        if k == 0 or values[order[k]] != values[order[k - 1]]:
            keep[order[k]] = True
    return _true_indices(keep)


# --- moved nodes and cells (ale.motion) ------------------------------------------------------


@njit(cache=True)
def changed_cells(x_new, x_old, cells):
    """Nodes whose position changed (mask) and the cells with such a node (indices)."""
    n, m = x_new.shape[0], cells.shape[0]
    moved = np.zeros(n, np.bool_)
    for i in range(n):
        moved[i] = x_new[i, 0] != x_old[i, 0] or x_new[i, 1] != x_old[i, 1]
    touched = np.zeros(m, np.bool_)
    count = 0
    for e in range(m):
        touched[e] = moved[cells[e, 0]] or moved[cells[e, 1]] or moved[cells[e, 2]] or moved[
            cells[e, 3]]
        count += touched[e]
    which = np.empty(count, np.int64)
    c = 0
    for e in range(m):
        if touched[e]:
            which[c] = e
            c += 1
    return moved, which


@njit(cache=True)
def acceptable(x_new, x_old, cells, min_quality, reference_quality, tn_quality):
    """``ale.motion._acceptable``: every cell with a moved node keeps ``min_quality`` of its
    original smallest corner sine or does not get worse than at t_n."""
    _, which = changed_cells(x_new, x_old, cells)
    return acceptable_cells(x_new, cells, which, min_quality, reference_quality, tn_quality)


@njit(cache=True)
def acceptable_cells(x_new, cells, which, min_quality, reference_quality, tn_quality):
    """``acceptable`` with the changed cells ``which`` already known."""
    q = cell_min_sines(x_new, cells, which)
    for k in range(which.size):
        e = which[k]
        a, b = min_quality * reference_quality[e], tn_quality[e]
        if np.isnan(a) or np.isnan(b):  # np.minimum propagates NaN: q >= NaN fails
            return False
        if not q[k] >= min(a, b):
            return False
    return True


@njit(cache=True)
def hint_cells(node_cell, chain_nodes, owner, node_s, slides, moved):
    """``ale.motion._hints``: per moved node (in node order) a likely old cell: for a slid
    chain node the cell owning the segment it landed on, otherwise one around its position."""
    hint = node_cell.copy()
    for i in range(slides.size):
        if slides[i] != 0.0:
            seg = np.searchsorted(node_s, node_s[i] + slides[i], side="right") - 1
            hint[chain_nodes[i]] = owner[min(max(seg, 0), owner.size - 1)]
    return hint[_true_indices(moved)]
