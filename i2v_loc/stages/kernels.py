"""Compiled (numba) kernels of the shared front end and of the hinged fit's nearest faces: one pass
over the points each, no Python loop per point or per voxel. Compiled once and cached on disk
(``cache=True``); ``warm_up()`` loads or compiles every specialisation the pipeline uses, so no
frame pays for compilation.

Arithmetic follows the numpy code these kernels replaced operation by operation (float32 where it
was float32, the same rounding order), so the outputs are the same points and decisions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

_JIT = {"cache": True, "nogil": True}
# helpers called per point or per voxel with arrays: inlined by numba itself, else every call counts
# each array's reference up and down (atomic operations: 40 ns a call instead of 1)
_INLINE = {**_JIT, "inline": "always"}

# voxel grouping: an occupancy bit per key when the key range is at most this times the points
# (plus a constant), else an open-addressing hash table
DENSE_KEYS_PER_POINT = 8
DENSE_KEYS_MIN = 1 << 16
EMPTY = np.int64(-1)
MIN_HOLD_ARM_M = 0.5  # the holding curvature's arm never shrinks below this (a kingpin far ahead, folded)


# ----------------------------------------------------------------------------- merge


@njit(**_JIT)
def sweep_to_yard(points, offsets, rot, trans, min_r2, max_r2, out_points, out_offsets, start):
    """Clean one sweep (finite, within the range limits) and write its points in the yard frame
    to ``out_points[start:]`` (their time offsets beside). Returns (points kept, non-finite points).

    The rotation is the fused multiply-add chain of the float32 matrix product it replaces
    (x r0 rounded, then y r1 and z r2 each added with one rounding: the hardware's float32 FMA, ``_fma``), so
    the points are bit-equal. Every point is written at the next free row, which is then kept or not
    (no branch around the writes; the rows written stay within the sweep's own)."""
    k = start
    n_bad = 0
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    for i in range(points.shape[0]):
        x, y, z, off = points[i, 0], points[i, 1], points[i, 2], offsets[i]
        xd, yd, zd = np.float64(x), np.float64(y), np.float64(z)
        r2 = xd * xd + yd * yd + zd * zd  # not finite exactly when a coordinate is not (squares add up)
        out_points[k, 0] = _fma(z, r02, _fma(y, r01, x * r00)) + trans[0]
        out_points[k, 1] = _fma(z, r12, _fma(y, r11, x * r10)) + trans[1]
        out_points[k, 2] = _fma(z, r22, _fma(y, r21, x * r20)) + trans[2]
        out_offsets[k] = off
        finite = np.isfinite(r2) and np.isfinite(off)
        k += finite and min_r2 <= r2 <= max_r2
        n_bad += not finite
    return k - start, n_bad


@njit(**_JIT)
def _cos_sin_small(angle):
    """cos and sin of an angle that is small in nearly every call (a box's turn while a sweep is
    captured: below 0.2 rad) by their Taylor series to within 1e-7 below 0.25 rad, where the library
    calls cost as much as the whole box test."""
    if abs(angle) > 0.25:
        return math.cos(angle), math.sin(angle)
    a2 = angle * angle
    return 1.0 - a2 * (0.5 - a2 * (1.0 / 24.0 - a2 / 720.0)), angle * (1.0 - a2 * (1.0 / 6.0 - a2 / 120.0))


@njit(**_JIT)
def interpolate(points, lag_s, boxes):
    """Move each point inside a box to the reference time (in place); the first box holding a
    point moves it. ``boxes`` rows: centre x, y, cos yaw, sin yaw, half length, half width,
    velocity x, y, yaw rate, age: the seconds from the box's pose to the reference time. With an
    age, a point is tested against the box where it stood when the point was captured (age - lag
    after the pose: a sweep's last points are up to 0.25 s younger than the last frame's pose);
    NaN: the box as it is."""
    for i in range(points.shape[0]):
        for b in range(boxes.shape[0]):
            cx, cy, c, s = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3]
            age = boxes[b, 9]
            if age == age:
                since = age - np.float64(lag_s[i])
                cx, cy = cx + boxes[b, 6] * since, cy + boxes[b, 7] * since
                cos_turn, sin_turn = _cos_sin_small(boxes[b, 8] * since)
                c, s = c * cos_turn - s * sin_turn, s * cos_turn + c * sin_turn
            dx = points[i, 0] - np.float32(cx)
            dy = points[i, 1] - np.float32(cy)
            along = np.float64(dx) * c + np.float64(dy) * s
            across = -np.float64(dx) * s + np.float64(dy) * c
            if abs(along) <= boxes[b, 4] and abs(across) <= boxes[b, 5]:
                vx, vy = np.float32(boxes[b, 6]), np.float32(boxes[b, 7])
                rate = boxes[b, 8]
                if rate != 0.0:
                    vx = vx + np.float32(rate) * -dy
                    vy = vy + np.float32(rate) * dx
                points[i, 0] += lag_s[i] * vx
                points[i, 1] += lag_s[i] * vy
                break


# ----------------------------------------------------------------------------- background


@njit(**_JIT)
def background_pass(
    points, shift, scale, upper, grid, free_bits, ready, keep_columns, learn, protect_columns, seen,
    in_region, foreground, learned, cells, columns,
):  # fmt: skip
    """Per point: its voxel of the padded grid (``grid``: voxels along x, y, z and the padding), in
    the region (inside the padding), foreground (the map before this frame: ``free_bits``, a bit per
    voxel, small enough to stay in cache); on a learning frame each region voxel outside the
    protected columns is listed once in ``learned`` (the sample). ``keep_columns`` /
    ``protect_columns`` are empty when no box is protected; ``seen`` is a bit per voxel, all clear
    between calls (an eighth of a byte array: it stays in cache); ``cells`` / ``columns``: scratch
    of at least the points' length. Returns the sample's size.

    Separate short loops (voxels; lookups; sample without a branch on the bit) run faster than one
    loop doing all: their loads overlap. The sample is counted in by ``count_sample``, on the next
    frame."""
    m = points.shape[0]
    _voxels(points, shift, scale, upper, grid, in_region, cells, columns)
    if ready:
        for i in range(m):
            foreground[i] = (free_bits[cells[i] >> 3] >> (cells[i] & 7)) & 1 != 0
        if keep_columns.shape[0] > 0:
            for i in range(m):
                if in_region[i] and not foreground[i]:
                    foreground[i] = keep_columns[columns[i]]
    else:
        foreground[:m] = in_region[:m]
    return _sample(cells, columns, in_region, protect_columns, seen, learned) if learn else 0


@njit(**_INLINE)
def _voxels(points, shift, scale, upper, grid, in_region, cells, columns):
    """Each point's voxel and (x, y) column of the padded grid, and whether it lies in the region
    (pad <= index < size - pad on every axis: one unsigned comparison per axis)."""
    ny, nz, pad = grid[1], grid[2], grid[3]
    wx, wy, wz = np.uint64(grid[0] - 2 * pad), np.uint64(ny - 2 * pad), np.uint64(nz - 2 * pad)
    s0, s1, s2 = shift[0], shift[1], shift[2]
    u0, u1, u2 = upper[0], upper[1], upper[2]
    for i in range(points.shape[0]):
        ix = np.int64(_clip_grid((points[i, 0] - s0) * scale, u0))
        iy = np.int64(_clip_grid((points[i, 1] - s1) * scale, u1))
        iz = np.int64(_clip_grid((points[i, 2] - s2) * scale, u2))
        columns[i] = ix * ny + iy
        cells[i] = columns[i] * nz + iz
        in_region[i] = (np.uint64(ix - pad) < wx) & (np.uint64(iy - pad) < wy) & (np.uint64(iz - pad) < wz)


@njit(**_INLINE)
def _sample(cells, columns, in_region, protect_columns, seen, learned):
    """The region's voxels outside the protected columns, each once, in ``learned``; returns how
    many. Every voxel is written at the next free slot, which is then kept or not (a branch on
    the seen bit would be mispredicted at every new voxel); ``seen`` is left clear."""
    use_protect = protect_columns.shape[0] > 0
    n = 0
    for i in range(in_region.shape[0]):  # the scratch may be longer
        cell = cells[i]
        byte, bit = cell >> 3, np.uint8(1) << np.uint8(cell & 7)
        old = seen[byte]
        new = in_region[i] & (not (use_protect and protect_columns[columns[i]])) & ((old & bit) == 0)
        learned[n] = cell
        seen[byte] = old | (bit if new else np.uint8(0))
        n += new
    for j in range(n):
        seen[learned[j] >> 3] = 0
    return n


@njit(**_JIT)
def _clip_grid(q, upper):
    """``q`` clipped to [0, upper] (the padded grid: outside points land in the padding)."""
    q = q if q > np.float32(0.0) else np.float32(0.0)
    return q if q < upper else upper


@njit(**_JIT)
def count_sample(cells, counts, evaluate, threshold, is_background, flips):
    """Count a sample (its voxels, each once) in. With ``evaluate`` (the window is full and the old
    sample already taken off the counts) a voxel that reaches ``threshold`` and is not background
    is listed in ``flips``: with fixed thresholds and every voxel decided, that is the only way a
    count going up changes a decision. Returns the number listed. (The counts first, then the
    decisions, in short loops whose cache misses overlap.)"""
    for c in cells:
        counts[c] += 1
    n_flips = 0
    if evaluate:
        for c in cells:
            if counts[c] == threshold and not is_background[c]:
                flips[n_flips] = c
                n_flips += 1
    return n_flips


@njit(**_JIT)
def forget_counts(cells, counts):
    """Take one sample (its voxels, each once) off the counts."""
    for c in cells:
        counts[c] -= 1


@njit(**_JIT)
def forgotten(cells, counts, is_background, threshold, forget, flips, n_flips):
    """List in ``flips`` (from ``n_flips`` on) the background voxels of a sample taken off the
    window whose final count is below both thresholds (fixed thresholds, every voxel decided: the
    only way a count going down changes a decision). Returns the new length of the list."""
    for c in cells:
        count = counts[c]
        if count < threshold and count <= forget and is_background[c]:
            flips[n_flips] = c
            n_flips += 1
    return n_flips


@njit(**_INLINE)
def _count_neighbourhood(c, offsets, dilated, free_bits, step):
    """Add ``step`` (+1 or -1) to the background count of the voxels around ``c``; a voxel whose
    count leaves or reaches 0 loses or gets its foreground bit."""
    for o in offsets:
        v = c + o
        if step > 0:
            if dilated[v] == 0:
                free_bits[v >> 3] &= ~(np.uint8(1) << np.uint8(v & 7))
            dilated[v] += 1
        else:
            dilated[v] -= 1
            if dilated[v] == 0:
                free_bits[v >> 3] |= np.uint8(1) << np.uint8(v & 7)


@njit(**_JIT)
def flip_cells(cells, is_background, dilated, free_bits, offsets):
    """Toggle the decision of these (distinct) voxels and the background count of their neighbourhood."""
    for c in cells:
        state = not is_background[c]
        is_background[c] = state
        _count_neighbourhood(c, offsets, dilated, free_bits, 1 if state else -1)


@njit(**_JIT)
def update_cells(cells, counts, is_background, dilated, free_bits, offsets, threshold, forget):
    """Re-decide these voxels (repeats allowed); a voxel that changes state updates the background
    count of its neighbourhood."""
    for c in cells:
        current = is_background[c]
        count = counts[c]
        state = count >= threshold or (current and count > forget)
        if state != current:
            is_background[c] = state
            _count_neighbourhood(c, offsets, dilated, free_bits, 1 if state else -1)


@njit(**_JIT)
def box_columns(boxes, margin, origin_x, origin_y, voxel, nx, ny, mask):
    """Mark the (x, y) columns of the padded grid whose centre lies in a box plus ``margin``.
    ``boxes`` rows: centre x, y, cos yaw, sin yaw, half length, half width."""
    for b in range(boxes.shape[0]):
        cx, cy, c, s, hl, hw = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3], boxes[b, 4], boxes[b, 5]
        reach = math.hypot(hl, hw) + margin
        lo_i = min(max(int(math.floor((cx - reach - origin_x) / voxel)) + 1, 0), nx - 1)
        lo_j = min(max(int(math.floor((cy - reach - origin_y) / voxel)) + 1, 0), ny - 1)
        hi_i = min(max(int(math.ceil((cx + reach - origin_x) / voxel)) + 1, 0), nx - 1)
        hi_j = min(max(int(math.ceil((cy + reach - origin_y) / voxel)) + 1, 0), ny - 1)
        for i in range(lo_i, hi_i + 1):
            dx = origin_x + (i - 0.5) * voxel - cx
            for j in range(lo_j, hi_j + 1):
                dy = origin_y + (j - 0.5) * voxel - cy
                if abs(dx * c + dy * s) <= hl + margin and abs(-dx * s + dy * c) <= hw + margin:
                    mask[i * ny + j] = True


# ----------------------------------------------------------------------------- region


@njit(**_JIT)
def box_mask(points, low, high, out):
    """Points inside the axis-aligned box [low, high] (bounds included)."""
    for i in range(points.shape[0]):
        inside = True
        for a in range(3):
            v = points[i, a]
            if v < low[a] or v > high[a]:
                inside = False
                break
        out[i] = inside


@njit(**_JIT)
def in_upright_box(points, box, out):
    """Points whose (x, y) lie in the upright box ``box`` (centre x, y, cos yaw, sin yaw, half
    length, half width; bounds included), in ``out``. Returns how many."""
    cx, cy, c, s, half_l, half_w = box[0], box[1], box[2], box[3], box[4], box[5]
    n = 0
    for i in range(points.shape[0]):
        inside = _in_box(points[i, 0] - cx, points[i, 1] - cy, c, s, half_l, half_w)
        out[i] = inside
        n += inside
    return n


@njit(**_JIT)
def in_first_box_only(points, first, second, out):
    """Points in the upright box ``first`` and not in ``second`` (``in_upright_box``'s boxes), in
    ``out``. Returns how many. (The boxes' figures in scalars: loaded from their arrays in the
    loop, they kept it from being vectorised, six times slower.)"""
    cx, cy, c, s, half_l, half_w = first[0], first[1], first[2], first[3], first[4], first[5]
    cx2, cy2, c2, s2, half_l2, half_w2 = second[0], second[1], second[2], second[3], second[4], second[5]
    n = 0
    for i in range(points.shape[0]):
        x, y = points[i, 0], points[i, 1]
        inside = _in_box(x - cx, y - cy, c, s, half_l, half_w) & ~_in_box(x - cx2, y - cy2, c2, s2, half_l2, half_w2)
        out[i] = inside
        n += inside
    return n


@njit(**_INLINE)
def _in_box(dx, dy, c, s, half_l, half_w):
    return (abs(c * dx + s * dy) <= half_l) & (abs(c * dy - s * dx) <= half_w)


@njit(**_JIT)
def cauchy_cost(residual, scale):
    """The mean Cauchy loss ``log1p((residual / scale) ** 2)`` (libm's log1p and a running sum: within
    a few units in the last place of numpy's vectorised one, at a tenth of its five calls' cost)."""
    total = 0.0
    for i in range(residual.shape[0]):
        r = residual[i] / scale
        total += math.log1p(r * r)
    return total / residual.shape[0]


@njit(**_JIT)
def to_frame(points, ox, oy, c, s):
    """(N, 2) coordinates of the points (x, y) in the frame at (``ox``, ``oy``) turned by the yaw
    whose cosine and sine are ``c``, ``s`` (float64, as numpy computes them)."""
    out = np.empty((points.shape[0], 2))
    for i in range(points.shape[0]):
        _frame_row(points, i, ox, oy, c, s, out, i)
    return out


@njit(**_JIT)
def owned_to_frame(points, owner, track, ox, oy, c, s):
    """The rows of the points whose ``owner`` is ``track`` and their coordinates in that frame (``to_frame``)."""
    rows = np.flatnonzero(owner == track)
    out = np.empty((rows.shape[0], 2))
    for k in range(rows.shape[0]):
        _frame_row(points, rows[k], ox, oy, c, s, out, k)
    return rows, out


@njit(**_INLINE)
def _frame_row(points, i, ox, oy, c, s, out, k):
    d0, d1 = np.float64(points[i, 0]) - ox, np.float64(points[i, 1]) - oy
    out[k, 0] = c * d0 + s * d1
    out[k, 1] = -s * d0 + c * d1


@njit(**_JIT)
def count_beside(q, up_to, edge):
    """How many of a trailer's points (``q``: its frame, xy) lie up to ``up_to`` along it and
    ``edge`` or more out from its axis."""
    n = 0
    for i in range(q.shape[0]):
        n += (q[i, 0] <= up_to) & (abs(q[i, 1]) >= edge)
    return n


@njit(**_JIT)
def strided_pick(mask, k_in, k_out):
    """Row indices of an even stride of ``k_in`` rows where ``mask`` holds, then of ``k_out`` rows
    where it does not (each as ``np.linspace(0, n - 1, k).astype(int)`` over its own rows)."""
    n_in = 0
    for i in range(mask.shape[0]):
        n_in += mask[i]
    counts = (n_in, mask.shape[0] - n_in)
    wanted = (k_in, k_out)
    out = np.empty(k_in + k_out, dtype=np.int64)
    seen = np.zeros(2, dtype=np.int64)  # rows of each part passed so far
    taken = np.zeros(2, dtype=np.int64)
    for i in range(mask.shape[0]):
        part = 0 if mask[i] else 1
        k, n = wanted[part], counts[part]
        j = taken[part]
        if j < k:
            target = (n - 1 if k > 1 else 0) if j == k - 1 else np.int64(j * ((n - 1) / (k - 1)))
            if seen[part] == target:
                out[(0 if part == 0 else k_in) + j] = i
                taken[part] = j + 1
        seen[part] += 1
    return out


@njit(**_JIT)
def above_plane(points, take, normal, offset, threshold, out_index):
    """Indices of the taken points more than ``threshold`` above the plane. Returns (kept, taken)."""
    k = 0
    taken = 0
    for i in range(points.shape[0]):
        if not take[i]:
            continue
        taken += 1
        h = points[i, 0] * normal[0] + points[i, 1] * normal[1] + points[i, 2] * normal[2] + offset
        if h > threshold:
            out_index[k] = i
            k += 1
    return k, taken


@njit(**_JIT)
def plane_scores(sample, normals, offsets, threshold):
    """Samples within ``threshold`` of each plane (coordinates as rows: the inner loop runs along
    contiguous memory and vectorises)."""
    x, y, z = np.ascontiguousarray(sample[:, 0]), np.ascontiguousarray(sample[:, 1]), np.ascontiguousarray(sample[:, 2])
    scores = np.zeros(normals.shape[0], dtype=np.int64)
    for h in range(normals.shape[0]):
        a, b, c, d = normals[h, 0], normals[h, 1], normals[h, 2], offsets[h]
        count = 0
        for i in range(x.shape[0]):
            count += abs(x[i] * a + y[i] * b + z[i] * c + d) < threshold
        scores[h] = count
    return scores


@njit(**_JIT)
def plane_hypotheses(a, b, c, min_cos):
    """Unit normals (pointing up) of the planes through the rows of a, b, c (N, 3) that are not
    degenerate (cross product norm above 1e-9) and tilted at most as far as ``min_cos`` allows
    (normal z >= it), with the rows they came from. numpy's arithmetic: the cross product, its
    norm summed x, y, z, the division, the sign of z + 1e-12."""
    n = a.shape[0]
    normals = np.empty((n, 3))
    rows = np.empty(n, dtype=np.int64)
    k = 0
    for i in range(n):
        u0, u1, u2 = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1], b[i, 2] - a[i, 2]
        v0, v1, v2 = c[i, 0] - a[i, 0], c[i, 1] - a[i, 1], c[i, 2] - a[i, 2]
        n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if not norm > 1e-9:
            continue
        up = np.sign(n2 / norm + 1e-12)
        n0, n1, n2 = n0 / norm * up, n1 / norm * up, n2 / norm * up
        if n2 >= min_cos:
            normals[k, 0], normals[k, 1], normals[k, 2] = n0, n1, n2
            rows[k] = i
            k += 1
    return normals[:k], rows[:k]


@njit(**_JIT)
def row_mean(rows):
    """Mean of the rows of a non-empty (N, k) float64 array, summed row after row as numpy's
    ``mean(axis=0)`` of a C-ordered array does (so the same bits), without its per-row overhead."""
    total = rows[0].copy()
    for i in range(1, rows.shape[0]):
        for a in range(rows.shape[1]):
            total[a] += rows[i, a]
    return total / np.float64(rows.shape[0])


# ----------------------------------------------------------------------------- voxel grouping


@intrinsic
def _popcount(typingctx, x):
    """Set bits of a uint64 (LLVM's ctpop: the hardware instruction where there is one)."""

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])

    return types.uint64(types.uint64), codegen


@njit(**_INLINE)
def _hash_slot(table_keys, key):
    """Open addressing, linear probing; the key mixed first (splitmix64's finaliser: grid keys are
    regular, and probing clusters on them otherwise)."""
    mask = table_keys.shape[0] - 1
    x = np.uint64(key)
    x = (x ^ (x >> np.uint64(33))) * np.uint64(0xFF51AFD7ED558CCD)
    x = (x ^ (x >> np.uint64(33))) * np.uint64(0xC4CEB9FE1A85EC53)
    x = x ^ (x >> np.uint64(33))
    slot = np.int64(x & np.uint64(mask))
    while table_keys[slot] != EMPTY and table_keys[slot] != key:
        slot = (slot + 1) & mask
    return slot


@njit(**_JIT)
def voxel_ids(points, take, voxel, one):
    """Voxel id of each taken point (-1 for the others) and the voxel keys (raster order, origin at
    the taken points' minimum). Returns (ids, voxel_keys, dims, bits, word_rank, table_keys,
    table_ids): with a small key range an occupancy bit per key (``bits``, uint64 words) and the
    voxels before each word (``word_rank``), so the grouping touches a few kB, and the ids in key
    order; else an open-addressing hash table of key -> id (``bits`` empty) and the ids in order of
    first appearance (``rank_in_key_order`` renumbers them once the keys are sorted). See ``_lookup``.

    The grid is computed in the type of ``one``/``voxel`` (the points' own for float32 grids,
    float64 for ``one`` = 1.0); the offsets from the minimum are never negative, so the integer
    conversion is the floor."""
    n = points.shape[0]
    # bounds and grid steps in scalars: a minimum kept in an array is stored and loaded every point
    lo_x = lo_y = lo_z = one * np.float32(np.inf)
    hi_x = hi_y = hi_z = -lo_x
    n_taken = 0
    for i in range(n):
        if take[i]:
            n_taken += 1
            x, y, z = points[i, 0] * one, points[i, 1] * one, points[i, 2] * one
            lo_x, lo_y, lo_z = min(lo_x, x), min(lo_y, y), min(lo_z, z)
            hi_x, hi_y, hi_z = max(hi_x, x), max(hi_y, y), max(hi_z, z)
    dims = np.ones(3, dtype=np.int64)
    if n_taken:  # the index grows with the coordinate: the highest point's is the largest
        dims[0] = np.int64((hi_x - lo_x) / voxel) + 1
        dims[1] = np.int64((hi_y - lo_y) / voxel) + 1
        dims[2] = np.int64((hi_z - lo_z) / voxel) + 1
    ny, nz = dims[1], dims[2]
    keys = np.full(n, EMPTY, dtype=np.int64)
    n_keys = np.int64(0)
    for i in range(n):
        if take[i]:
            qx = np.int64((points[i, 0] * one - lo_x) / voxel)
            qy = np.int64((points[i, 1] * one - lo_y) / voxel)
            qz = np.int64((points[i, 2] * one - lo_z) / voxel)
            keys[i] = (qx * ny + qy) * nz + qz
            n_keys = max(n_keys, keys[i] + 1)
    ids = np.full(n, EMPTY, dtype=np.int64)
    no_table = np.empty(0, dtype=np.int64)
    if n_keys <= DENSE_KEYS_PER_POINT * n_taken + DENSE_KEYS_MIN:
        bits = np.zeros((n_keys + 63) >> 6, dtype=np.uint64)
        for i in range(n):
            if keys[i] >= 0:
                bits[keys[i] >> 6] |= np.uint64(1) << np.uint64(keys[i] & 63)
        word_rank = np.empty(bits.shape[0], dtype=np.int64)
        n_vox = 0
        for w in range(bits.shape[0]):
            word_rank[w] = n_vox
            n_vox += np.int64(_popcount(bits[w]))
        voxel_keys = np.empty(n_vox, dtype=np.int64)
        v = 0
        for w in range(bits.shape[0]):
            word = bits[w]
            while word:
                low = word & (~word + np.uint64(1))  # the lowest set bit
                voxel_keys[v] = w * 64 + np.int64(_popcount(low - np.uint64(1)))
                v += 1
                word ^= low
        for i in range(n):
            key = keys[i]
            if key >= 0:  # the voxels before its word and before it in its word
                word, bit = bits[key >> 6], np.uint64(1) << np.uint64(key & 63)
                ids[i] = word_rank[key >> 6] + np.int64(_popcount(word & (bit - np.uint64(1))))
        return ids, voxel_keys, dims, bits, word_rank, no_table, no_table
    size = 1
    while size < 2 * n_taken + 2:
        size *= 2
    table_keys = np.full(size, EMPTY, dtype=np.int64)
    table_ids = np.full(size, EMPTY, dtype=np.int64)
    first = np.empty(n_taken, dtype=np.int64)
    n_vox = 0
    for i in range(n):
        if keys[i] < 0:
            continue
        slot = _hash_slot(table_keys, keys[i])
        if table_keys[slot] == EMPTY:
            table_keys[slot] = keys[i]
            table_ids[slot] = n_vox
            first[n_vox] = keys[i]
            n_vox += 1
        ids[i] = table_ids[slot]
    no_bits = np.empty(0, dtype=np.uint64)
    return ids, first[:n_vox], dims, no_bits, no_table, table_keys, table_ids


@njit(**_JIT)
def rank_in_key_order(sorted_keys, ids, table_keys, table_ids):
    """Renumber the voxels of a hash-table grouping by their rank in ``sorted_keys`` (in place)."""
    rank = np.empty(sorted_keys.shape[0], dtype=np.int64)
    for r in range(sorted_keys.shape[0]):
        slot = _hash_slot(table_keys, sorted_keys[r])
        rank[table_ids[slot]] = r
        table_ids[slot] = r
    for i in range(ids.shape[0]):
        if ids[i] >= 0:
            ids[i] = rank[ids[i]]


@njit(**_JIT)
def voxel_sums(points, values, ids, n_vox):
    """Per voxel: the float64 sums of the points' coordinates and values (in point order) and the counts."""
    sums = np.zeros((n_vox, 3 + values.shape[1]))
    counts = np.zeros(n_vox, dtype=np.int64)
    for i in range(points.shape[0]):
        v = ids[i]
        if v < 0:
            continue
        counts[v] += 1
        for a in range(3):
            sums[v, a] += points[i, a]
        for a in range(values.shape[1]):
            sums[v, 3 + a] += values[i, a]
    return sums, counts


@njit(**_INLINE)
def _lookup(key, bits, word_rank, table_keys, table_ids):
    """Id of the voxel of ``key`` (a key of the grid) in a grouping of ``voxel_ids``, -1 if none."""
    if bits.shape[0] > 0:
        w = key >> 6
        if w >= bits.shape[0]:
            return EMPTY
        word, bit = bits[w], np.uint64(1) << np.uint64(key & 63)
        if not word & bit:
            return EMPTY
        return word_rank[w] + np.int64(_popcount(word & (bit - np.uint64(1))))
    slot = _hash_slot(table_keys, key)
    return table_ids[slot] if table_keys[slot] == key else EMPTY


@njit(**_INLINE)
def _root(parent, v):
    while parent[v] != v:
        parent[v] = parent[parent[v]]
        v = parent[v]
    return v


@njit(**_INLINE)
def _union(parent, a, b):
    """Joins the trees of a and b under the smaller root."""
    a, b = _root(parent, a), _root(parent, b)
    if a != b:
        parent[max(a, b)] = min(a, b)


@njit(**_JIT)
def _component_labels(parent):
    """Each element's component, numbered in the order of the components' first elements."""
    labels = np.full(len(parent), EMPTY, dtype=np.int64)
    n_comp = 0
    for v in range(len(parent)):
        r = _root(parent, v)
        if labels[r] < 0:
            labels[r] = n_comp
            n_comp += 1
        labels[v] = labels[r]
    return labels


@njit(**_JIT)
def voxel_components(voxel_keys, dims, bits, word_rank, table_keys, table_ids):
    """26-connected components of the occupied voxels, numbered in the order of their first voxel
    in key (raster) order. The neighbour pairs are found first, then joined: lookups and unions in
    one loop ran ten times slower."""
    n_vox = voxel_keys.shape[0]
    pairs = np.empty((13 * n_vox, 2), dtype=np.int64)
    n_pairs = 0
    for v in range(n_vox):
        key = voxel_keys[v]
        i = key // (dims[1] * dims[2])
        j = (key // dims[2]) % dims[1]
        k = key % dims[2]
        for di in range(0, 2):
            for dj in range(-1, 2):
                for dk in range(-1, 2):
                    if di == 0 and (dj < 0 or (dj == 0 and dk <= 0)):
                        continue  # the other half of the neighbourhood looks back at this voxel
                    ni, nj, nk = i + di, j + dj, k + dk
                    if ni >= dims[0] or nj < 0 or nj >= dims[1] or nk < 0 or nk >= dims[2]:
                        continue
                    w = _lookup((ni * dims[1] + nj) * dims[2] + nk, bits, word_rank, table_keys, table_ids)
                    pairs[n_pairs, 0], pairs[n_pairs, 1] = v, w
                    n_pairs += w >= 0
    parent = np.arange(n_vox)
    for t in range(n_pairs):
        _union(parent, pairs[t, 0], pairs[t, 1])
    return _component_labels(parent)


@njit(**_JIT)
def radius_components(points, radius):
    """Connected components of the graph joining points at most ``radius`` apart (squared distances
    summed over the coordinates in order, as a k-d tree's pair query does), numbered in the order of
    their first point. Points are binned in cells of ``radius``: a pair can only join across
    neighbouring cells. ``points`` (N, 3) float64 (a 2-D cloud with a zero third column)."""
    n = points.shape[0]
    r2 = radius * radius
    lo = np.full(3, np.inf)
    for i in range(n):
        for a in range(3):
            lo[a] = min(lo[a], points[i, a])
    cell = np.empty((n, 3), dtype=np.int64)
    dims = np.ones(3, dtype=np.int64)
    for i in range(n):
        for a in range(3):
            c = np.int64((points[i, a] - lo[a]) / radius)
            cell[i, a] = c
            dims[a] = max(dims[a], c + 1)
    keys = np.empty(n, dtype=np.int64)
    for i in range(n):
        keys[i] = (cell[i, 0] * dims[1] + cell[i, 1]) * dims[2] + cell[i, 2]
    order = np.argsort(keys)
    sorted_keys = keys[order]
    parent = np.arange(n)
    for s in range(n):
        i = order[s]
        for di in range(-1, 2):
            for dj in range(-1, 2):
                for dk in range(-1, 2):
                    ci, cj, ck = cell[i, 0] + di, cell[i, 1] + dj, cell[i, 2] + dk
                    if ci < 0 or cj < 0 or ck < 0 or ci >= dims[0] or cj >= dims[1] or ck >= dims[2]:
                        continue
                    key = (ci * dims[1] + cj) * dims[2] + ck
                    t = np.searchsorted(sorted_keys, key)
                    while t < n and sorted_keys[t] == key:
                        j = order[t]
                        t += 1
                        if j <= i:
                            continue
                        d = 0.0
                        for a in range(3):
                            diff = points[i, a] - points[j, a]
                            d += diff * diff
                        if d <= r2:
                            _union(parent, i, j)
    return _component_labels(parent)


@njit(**_JIT)
def counting_order(labels, n_labels):
    """Stable order of the points by label (labels in 0..n_labels-1) and the count of each label."""
    counts = np.zeros(n_labels, dtype=np.int64)
    for v in labels:
        counts[v] += 1
    start = np.empty(n_labels, dtype=np.int64)
    total = 0
    for v in range(n_labels):
        start[v] = total
        total += counts[v]
    order = np.empty(labels.shape[0], dtype=np.int64)
    for i in range(labels.shape[0]):
        order[start[labels[i]]] = i
        start[labels[i]] += 1
    return order, counts


# ----------------------------------------------------------------------------- rectangles


@njit(**_INLINE)
def _cross(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


@njit(**_JIT)
def _outside_octagon(xy):
    """The points not strictly inside the polygon of the extreme points along x, y, x + y and x - y
    (Akl-Toussaint): those strictly inside are inside the hull, never its vertices."""
    n = xy.shape[0]
    # support directions counter-clockwise from straight down: the extremes are hull vertices in order
    dirs = np.array(
        [[0.0, -1.0], [1.0, -1.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [-1.0, 1.0], [-1.0, 0.0], [-1.0, -1.0]]
    )
    best = np.full(8, -np.inf)
    which = np.zeros(8, dtype=np.int64)
    for i in range(n):
        for d in range(8):
            v = dirs[d, 0] * xy[i, 0] + dirs[d, 1] * xy[i, 1]
            if v > best[d]:
                best[d], which[d] = v, i
    edges = np.empty((8, 2), dtype=np.int64)
    m = 0
    for d in range(8):
        a, b = which[d], which[(d + 1) % 8]
        if xy[a, 0] != xy[b, 0] or xy[a, 1] != xy[b, 1]:
            edges[m, 0], edges[m, 1] = a, b
            m += 1
    if m < 3:
        return xy
    keep = np.empty(n, dtype=np.bool_)
    for i in range(n):
        inside = True
        for e in range(m):
            if _cross(xy[edges[e, 0]], xy[edges[e, 1]], xy[i]) <= 0:
                inside = False
                break
        keep[i] = not inside
    return xy[keep]


@njit(**_JIT)
def _convex_hull(xy):
    """Vertices of the convex hull, counter-clockwise, without collinear points (monotone chain on
    the points the octagon filter leaves)."""
    xy = _outside_octagon(xy) if xy.shape[0] > 64 else xy
    n = xy.shape[0]
    pts = xy[np.argsort(xy[:, 0], kind="mergesort")]  # by x, then (below) by y among equal x
    i = 0
    while i < n:
        j = i
        while j + 1 < n and pts[j + 1, 0] == pts[i, 0]:
            j += 1
        if j > i:
            block = pts[i : j + 1]
            pts[i : j + 1] = block[np.argsort(block[:, 1], kind="mergesort")]
        i = j + 1
    hull = np.empty((2 * n + 1, 2))
    k = 0
    for i in range(n):
        while k >= 2 and _cross(hull[k - 2], hull[k - 1], pts[i]) <= 0:
            k -= 1
        hull[k] = pts[i]
        k += 1
    lower = k + 1
    for i in range(n - 2, -1, -1):
        while k >= lower and _cross(hull[k - 2], hull[k - 1], pts[i]) <= 0:
            k -= 1
        hull[k] = pts[i]
        k += 1
    return hull[: max(k - 1, 1)] if n > 0 else hull[:0]


@njit(**_JIT)
def min_area_rect(xy):
    """Rotating calipers over the hull edges' directions (modulo 90 deg): centre x, y, extent
    along the best direction, extent across it, the direction; NaN centre when the hull is flat."""
    hull = _convex_hull(xy)
    m = hull.shape[0]
    out = np.full(5, np.nan)
    if m < 3:
        return out
    angles = np.empty(m)
    for e in range(m):
        nxt = hull[(e + 1) % m]
        angles[e] = np.mod(np.arctan2(nxt[1] - hull[e, 1], nxt[0] - hull[e, 0]), np.pi / 2)
    angles = np.unique(angles)
    best_area = np.inf
    for a in angles:
        c, s = np.cos(a), np.sin(a)
        u_lo, u_hi, v_lo, v_hi = np.inf, -np.inf, np.inf, -np.inf
        for p in range(m):
            u = hull[p, 0] * c + hull[p, 1] * s
            v = -hull[p, 0] * s + hull[p, 1] * c
            u_lo, u_hi, v_lo, v_hi = min(u_lo, u), max(u_hi, u), min(v_lo, v), max(v_hi, v)
        du, dv = u_hi - u_lo, v_hi - v_lo
        if du * dv < best_area:
            best_area = du * dv
            cu, cv = (u_hi + u_lo) / 2, (v_hi + v_lo) / 2
            out[0] = cu * np.cos(a) - cv * np.sin(a)
            out[1] = cu * np.sin(a) + cv * np.cos(a)
            out[2], out[3], out[4] = du, dv, a
    return out


# ----------------------------------------------------------------------------- hinged fit


@intrinsic
def _fma(typingctx, a, b, c):
    """a * b + c with one rounding (LLVM's fma: the hardware instruction where there is one), in
    float32 when all three are float32, else in float64."""
    kind = types.float32 if a == b == c == types.float32 else types.float64

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return kind(kind, kind, kind), codegen


# the rows of a unit's face table: front, rear, left, right as (local normal x, y)
_FACE_NORMALS = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))


@njit(**_JIT)
def _face_table(geometry):
    """(4 per unit, 10) per face (front, rear, left, right) in yard coordinates: normal N (2),
    tangent T (2), plane offset, tangent offset, half extent along T, tangent coordinate of the face
    centre in the unit's frame, extra yaw lever (the kingpin moves with the tractor's yaw), unit.
    ``geometry``: tractor x, y, yaw, hitch, kingpin behind the axle, trailer slack, then per box
    front, length, width, floor, height."""
    n_units = (geometry.shape[0] - 6) // 5
    x, y, yaw1, kingpin = geometry[0], geometry[1], geometry[2], geometry[4]
    c1, s1 = math.cos(yaw1), math.sin(yaw1)
    table = np.empty((4 * n_units, 10))
    for u in range(n_units):
        ox, oy, yaw, slack = x, y, yaw1, 0.0
        if u == 1:
            ox, oy, yaw, slack = x - kingpin * c1, y - kingpin * s1, yaw1 + geometry[3], geometry[5]
        front, length, width = geometry[6 + 5 * u], geometry[7 + 5 * u], geometry[8 + 5 * u]
        c, s = math.cos(yaw), math.sin(yaw)
        half_w, half_l = width / 2, length / 2 + slack / 2
        mid_x = (front - length / 2) - slack / 2
        for f in range(4):
            nx, ny = _FACE_NORMALS[f]
            if f == 0:
                mx, my, half = front, 0.0, half_w
            elif f == 1:
                mx, my, half = front - length, 0.0, half_w
            else:
                mx, my, half = mid_x, half_w if f == 2 else -half_w, half_l
            big_nx, big_ny = c * nx - s * ny, s * nx + c * ny
            cx, cy = ox + c * mx - s * my, oy + s * mx + c * my
            row = table[4 * u + f]
            row[0], row[1], row[2], row[3] = big_nx, big_ny, -big_ny, big_nx
            row[4], row[5] = big_nx * cx + big_ny * cy, -big_ny * cx + big_nx * cy
            row[6], row[7] = half, -ny * mx + nx * my
            row[8] = kingpin * (-big_nx * s1 + big_ny * c1) if u == 1 else 0.0
            row[9] = u
    return table


@njit(**_JIT)
def claim_points(points, boxes, track_of_box, n_tracks, margin):
    """The track whose boxes are nearest each point (N, 2 or more columns; the planar distance, 0
    inside), if within ``margin``; -1 for none. ``boxes`` (K, 6): origin x, y and yaw of the box's
    unit frame, the box's rear and front along its x, its half width; ``track_of_box`` (K,) the
    track each belongs to. A tie goes to the lower track."""
    n = points.shape[0]
    owner = np.full(n, -1, dtype=np.int64)
    best = np.full(n, np.inf)
    squared = np.empty(n)
    for t in range(n_tracks):
        squared[:] = np.inf
        for k in range(boxes.shape[0]):
            if track_of_box[k] != t:
                continue
            ox, oy, c, s = boxes[k, 0], boxes[k, 1], math.cos(boxes[k, 2]), math.sin(boxes[k, 2])
            rear, front, half = boxes[k, 3], boxes[k, 4], boxes[k, 5]
            for i in range(n):
                d0, d1 = np.float64(points[i, 0]) - ox, np.float64(points[i, 1]) - oy
                qx, qy = c * d0 + s * d1, -s * d0 + c * d1
                dx = max(max(rear - qx, qx - front), 0.0)
                dy = max(abs(qy) - half, 0.0)
                squared[i] = min(squared[i], dx * dx + dy * dy)
        for i in range(n):
            d = math.sqrt(squared[i])
            if d <= margin and d < best[i]:
                owner[i], best[i] = t, d
    return owner


@njit(**_JIT)
def nearest_faces(xy, z_rel, geometry, top_band, n_params, chassis_gap):
    """Per point the nearest face of either unit box (``_face_table``'s rows; the first on a tie):
    signed distance to its plane (the residual), Jacobian row over the first ``n_params`` of
    (x, y, yaw, hitch), unit, distance to the face itself (beyond its ends too; inf above every
    roof) and face number (0 front, 1 rear, 2 left, 3 right). A point on a unit's roof or under its
    floor, inside its footprint (the trailer's reaching ``slack`` further back), is at distance 0
    from each of that unit's faces; picked so, it gets residual 0, a zero row and face -1. So does a
    point whose nearest face is an articulated vehicle's cab's rear face, more than ``chassis_gap``
    behind it, within its width and below half its height: the chassis, the coupling and the rear
    wheels stand there (inf: none is).

    Beyond a box's corner two faces are at the same distance: which one is picked is decided by the
    last bit, so the dot products are rounded like the (n, 2) x (2, faces) matrix products of the numpy
    code this replaced (OpenBLAS: y * b fused onto the rounded x * a), and the picks are the same."""
    table = _face_table(geometry)
    n_faces = table.shape[0]
    n_units = n_faces // 4
    slack = geometry[5]
    n = xy.shape[0]
    residual = np.zeros(n)
    jacobian = np.zeros((n, n_params))
    unit = np.empty(n, dtype=np.int64)
    distance = np.empty(n)
    face = np.empty(n, dtype=np.int64)
    perp = np.empty(n_faces)
    along = np.empty(n_faces)
    dist2 = np.empty(n_faces)
    roof = np.zeros(n_units, dtype=np.bool_)
    for i in range(n):
        px, py, z = xy[i, 0], xy[i, 1], z_rel[i]
        for f in range(n_faces):
            perp[f] = _fma(py, table[f, 1], px * table[f, 0]) - table[f, 4]
            along[f] = _fma(py, table[f, 3], px * table[f, 2]) - table[f, 5]
            excess = max(abs(along[f]) - table[f, 6], 0.0)
            dist2[f] = perp[f] * perp[f] + excess * excess
        for u in range(n_units):
            c = 4 * u
            outside = max(max(perp[c], perp[c + 1]), max(perp[c + 2], perp[c + 3]))
            if u == 1 and slack > 0:  # the roof reaches as far back as the sides may
                outside = max(max(perp[4], perp[6]), max(perp[7], perp[5] - slack))
            top, floor = geometry[9 + 5 * u] + geometry[10 + 5 * u], geometry[9 + 5 * u]
            flat = abs(z - top) <= top_band or z < floor - top_band
            roof[u] = flat and outside <= 0.0
            for f in range(c, c + 4):
                if roof[u]:
                    dist2[f] = 0.0
                if z > top + top_band:
                    dist2[f] = np.inf
        pick = 0
        for f in range(1, n_faces):
            if dist2[f] < dist2[pick]:
                pick = f
        u = np.int64(table[pick, 9])
        unit[i] = u
        distance[i] = math.sqrt(dist2[pick])
        chassis = (
            n_units == 2
            and pick == 1
            and perp[1] > chassis_gap
            and abs(along[1]) <= table[1, 6]
            and z < geometry[9] + geometry[10] / 2
        )
        if roof[u] or chassis:  # a roof, undercarriage or chassis point says nothing about the pose
            face[i] = -1
            continue
        face[i] = pick % 4
        residual[i] = perp[pick]
        lever = along[pick] + table[pick, 7]  # N_perp . (p - unit origin)
        jacobian[i, 0], jacobian[i, 1], jacobian[i, 2] = -table[pick, 0], -table[pick, 1], lever + table[pick, 8]
        if n_units == 2 and u == 1:
            jacobian[i, 3] = lever
    return residual, jacobian, unit, distance, face


@njit(**_JIT)
def fit_faces(xy, z_rel, geometry, top_band, n_pose, fits_length, fits_kingpin, fits_cab, v, chassis_gap):
    """``nearest_faces`` of the pose and fitted dimensions ``v`` (pose, then the trailer's length,
    then the kingpin's offset and the trailer's front, then the cab's length), with the dimensions'
    Jacobian columns: the rear face moves with the length; the trailer moves back along the
    tractor's axis with the kingpin's offset and forward along its own with its front; the cab's
    rear face moves back with its length. ``geometry`` is updated in place."""
    geometry[0], geometry[1], geometry[2] = v[0], v[1], v[2]
    geometry[3] = v[3] if n_pose == 4 else 0.0
    n_params = v.shape[0]
    if fits_length:
        geometry[12] = v[4]
    hinge_end = n_params - 1 if fits_cab else n_params
    if fits_kingpin:
        geometry[4], geometry[11] = v[hinge_end - 2], v[hinge_end - 1]
    if fits_cab:
        geometry[7] = v[n_params - 1]
    residual, pose_jacobian, unit, distance, face = nearest_faces(xy, z_rel, geometry, top_band, n_pose, chassis_gap)
    if n_params == n_pose:
        return residual, pose_jacobian, unit, distance, face
    n = xy.shape[0]
    jacobian = np.empty((n, n_params))
    jacobian[:, :n_pose] = pose_jacobian
    column = n_pose
    if fits_length:
        for i in range(n):
            jacobian[i, column] = -(1.0 if unit[i] == 1 and face[i] == 1 else 0.0)
        column += 1
    if fits_kingpin:
        for yaw, sign in ((v[2], -1.0), (v[2] + v[3], 1.0)):
            c, s = math.cos(yaw), math.sin(yaw)
            for i in range(n):
                along = pose_jacobian[i, 0] * c + pose_jacobian[i, 1] * s
                jacobian[i, column] = sign * along if unit[i] == 1 and face[i] >= 0 else 0.0
            column += 1
    if fits_cab:
        for i in range(n):
            jacobian[i, column] = -(1.0 if unit[i] == 0 and face[i] == 1 else 0.0)
    return residual, jacobian, unit, distance, face


@njit(**_JIT)
def irls(
    xy,
    z_rel,
    geometry,
    top_band,
    n_pose,
    fits_length,
    fits_kingpin,
    v0,
    prior_weights,
    scale,
    start_scale,
    iterations,
    ranges,
    chassis_gap,
):
    """Iteratively reweighted Gauss-Newton steps of the hinged fit from ``v0`` (Cauchy weights, the
    loss scale halved per step from ``start_scale`` down to ``scale``, a weak prior pulling towards
    ``v0``); stops once a step at the final scale moved the pose by less than 1 mm and 1e-4 rad.
    Returns the solution and the faces (residual, Jacobian, unit, distance, face) of its last step.
    ``ranges``: (trailer length low, high, kingpin low, high) the fitted dimensions are clipped to.

    The same arithmetic as the numpy loop it replaced: elementwise operations in its order, the
    normal equations by ``np.dot`` and ``np.linalg.solve`` (the BLAS / LAPACK calls numpy makes)."""
    prior_info = np.diag(prior_weights)
    v = v0.copy()
    n_params = v.shape[0]
    residual, jacobian, unit, distance, face = fit_faces(
        xy, z_rel, geometry, top_band, n_pose, fits_length, fits_kingpin, False, v, chassis_gap
    )
    for k in range(iterations):
        c = max(scale, start_scale * 0.5**k)
        if k > 0:
            residual, jacobian, unit, distance, face = fit_faces(
                xy, z_rel, geometry, top_band, n_pose, fits_length, fits_kingpin, False, v, chassis_gap
            )
        weighted = _cauchy_weighted(jacobian, residual, c)
        normal = np.dot(weighted.T, jacobian) + prior_info
        gradient = np.dot(weighted.T, residual) + prior_weights * (v - v0)
        step = np.linalg.solve(normal, -gradient)
        v = v + step
        if fits_length:
            v[4] = min(max(v[4], ranges[0]), ranges[1])
        if fits_kingpin:
            v[n_params - 2] = min(max(v[n_params - 2], ranges[2]), ranges[3])
        angular = abs(step[2]) if n_params == 3 else max(abs(step[2]), abs(step[3]))
        if c == scale and max(abs(step[0]), abs(step[1])) < 1e-3 and angular < 1e-4:
            break
    return v, residual, jacobian, unit, distance, face


@njit(**_JIT)
def joint_hinge_irls(
    xy,
    z_rel,
    starts,
    geometries,
    locals0,
    shared0,
    local_weights,
    shared_weights,
    scale,
    start_scale,
    iterations,
    ranges,
    chassis_gap,
    top_band,
):
    """Reweighted Gauss-Newton steps of the hinged model fitted to several frames at once: each
    frame ``f`` (its points ``starts[f]:starts[f + 1]``) has its own pose (``locals0[f]``: x, y,
    yaw, hitch), all share the kingpin's offset and the trailer's front, and the cab's length when
    ``shared0`` holds three (``ranges``' last two bound it as its third and fourth bound the
    kingpin's). Each
    frame's own parameters are eliminated from its normal equations (the Schur complement), the
    shared step solved from their sum, then each frame's step from it.
    Weak priors (``local_weights``, ``shared_weights``: the diagonal of their information) pull
    towards the start; the loss scale as ``irls``'s; stops once a step at the final scale moved
    the shared parameters by less than 1 mm (the frames' poses are a means: followed to 1 mm too,
    20 frames took all 10 steps, 2-3 ms, for the same hinge). Returns the shared parameters, the
    frames' own, the shared parameters' information (unweighted by the noise) and the residuals."""
    n_frames, n_local = locals0.shape
    n_shared = shared0.shape[0]
    n_params = n_local + n_shared
    local = locals0.copy()
    shared = shared0.copy()
    v = np.empty(n_params)
    residual = np.empty(xy.shape[0])
    information = np.zeros((n_shared, n_shared))
    h_ll_inv = np.empty((n_frames, n_local, n_local))
    h_ls = np.empty((n_frames, n_local, n_shared))
    g_l = np.empty((n_frames, n_local))
    for k in range(iterations):
        c = max(scale, start_scale * 0.5**k)
        information = np.diag(shared_weights)
        gradient = shared_weights * (shared - shared0)
        for f in range(n_frames):
            a, b = starts[f], starts[f + 1]
            v[:n_local] = local[f]
            v[n_local:] = shared
            r, jacobian, _, _, _ = fit_faces(
                xy[a:b], z_rel[a:b], geometries[f], top_band, 4, False, True, n_shared == 3, v, chassis_gap
            )
            residual[a:b] = r
            weighted = _cauchy_weighted(jacobian, r, c)
            normal = np.dot(weighted.T, jacobian)
            g = np.dot(weighted.T, r)
            for j in range(n_local):
                normal[j, j] += local_weights[j]
                g[j] += local_weights[j] * (local[f, j] - locals0[f, j])
            h_ll_inv[f] = np.linalg.inv(normal[:n_local, :n_local])
            h_ls[f] = normal[:n_local, n_local:]
            g_l[f] = g[:n_local]
            reduce = np.dot(h_ls[f].T, h_ll_inv[f])
            information += normal[n_local:, n_local:] - np.dot(reduce, h_ls[f])
            gradient += g[n_local:] - np.dot(reduce, g_l[f])
        step = np.linalg.solve(information, -gradient)
        shared = shared + step
        shared[0] = min(max(shared[0], ranges[2]), ranges[3])
        if n_shared == 3:
            shared[2] = min(max(shared[2], ranges[4]), ranges[5])
        moved = np.max(np.abs(step))
        for f in range(n_frames):
            local_step = -np.dot(h_ll_inv[f], g_l[f] + np.dot(h_ls[f], step))
            local[f] += local_step
        if c == scale and moved < 1e-3:
            break
    return shared, local, information - np.diag(shared_weights), residual


@njit(**_JIT)
def _cauchy_weighted(jacobian, residual, scale):
    """The Jacobian's rows times the Cauchy weights 1 / (1 + (r / scale)^2) of their residuals."""
    n, n_params = jacobian.shape
    weighted = np.empty((n, n_params))
    for i in range(n):
        q = residual[i] / scale
        w = 1.0 / (1.0 + q * q)
        for j in range(n_params):
            weighted[i, j] = jacobian[i, j] * w
    return weighted


@njit(**_JIT)
def fit_labels(unit, face, distance, residual, inlier_m, rear_face):
    """What a fit's points are: the unit whose face explains each (within ``inlier_m`` of the face
    itself, else -1), the face whose plane it lies on (within ``inlier_m`` of the plane, else -1),
    both int8, and how many explained points lie on the trailer's rear face (``rear_face``)."""
    n = unit.shape[0]
    units = np.empty(n, dtype=np.int8)
    faces = np.empty(n, dtype=np.int8)
    rear = 0
    for i in range(n):
        explained = distance[i] <= inlier_m
        units[i] = unit[i] if explained else -1
        faces[i] = face[i] if abs(residual[i]) <= inlier_m else -1
        rear += explained and unit[i] == 1 and face[i] == rear_face
    return units, faces, rear


@njit(**_JIT)
def face_median(q, column, unit, face, which_unit, which_face, along):
    """(how many, median) of ``q[:, column]`` over the points of a fit on one face of one unit
    (``unit``, ``face``: the fit's labels) whose ``q[:, 0]`` lies within ``along`` (low, high); the
    median is ``np.median``'s value (NaN for none)."""
    values = np.empty(q.shape[0])
    n = 0
    for i in range(q.shape[0]):
        if unit[i] == which_unit and face[i] == which_face and along[0] <= q[i, 0] <= along[1]:
            values[n] = q[i, column]
            n += 1
    return n, _median(values[:n]) if n else np.nan


@njit(**_JIT)
def rear_face(q, z_rel, unit, face, heights, front, half_width, inlier, beside, max_gap, end_band, middle_below, span):
    """The trailer body's hindmost points of a fit (``vehicle_dimensions._learn_trailer_length``): the
    points (``q``: the trailer's frame, ``z_rel``: height above the ground) within the body's
    ``heights`` (low, high), up to ``front`` and ``inlier`` outside its sides, hindmost last, cut
    at the first gap longer than ``max_gap`` or point level with a face that runs on past both sides
    (points of the other units ``beside`` (min, max) out past them, within ``end_band / 2``).
    Returns (how many in the body's band, the rows kept, hindmost first... last; whether the rear
    face is seen: points across its middle (within a quarter width of the axis, below
    ``middle_below``) within ``end_band`` of the hindmost and the face's points spanning ``span``;
    their median x)."""
    n = q.shape[0]
    band = np.empty(n, dtype=np.int64)
    left, right = np.empty(n), np.empty(n)
    n_band = n_left = n_right = 0
    for i in range(n):
        tall = heights[0] <= z_rel[i] <= heights[1] and q[i, 0] <= front
        side = abs(q[i, 1]) - half_width
        if tall and side <= inlier:
            band[n_band] = i
            n_band += 1
        if tall and unit[i] != 0 and beside[0] <= side <= beside[1]:
            if q[i, 1] > 0:
                left[n_left] = q[i, 0]
                n_left += 1
            elif q[i, 1] < 0:
                right[n_right] = q[i, 0]
                n_right += 1
    no_rows = np.empty(0, dtype=np.int64)
    if n_band < 5:
        return n_band, no_rows, False, np.nan
    x = np.empty(n_band)
    for k in range(n_band):
        x[k] = -q[band[k], 0]
    rows = band[:n_band][np.argsort(x, kind="mergesort")]
    keep = n_band
    walled = n_left > 0 and n_right > 0
    for k in range(n_band - 1):
        here, after = q[rows[k], 0], q[rows[k + 1], 0]
        if here - after > max_gap or (
            walled
            and _nearest(after, left[:n_left]) <= end_band / 2
            and _nearest(after, right[:n_right]) <= end_band / 2
        ):
            keep = k + 1
            break
    rows = rows[:keep]
    rear = q[rows[keep - 1], 0]
    lo, hi = np.inf, -np.inf
    middle = np.empty(keep)
    n_middle = 0
    for k in range(keep):
        r = rows[k]
        if q[r, 0] <= rear + end_band:
            lo, hi = min(lo, q[r, 1]), max(hi, q[r, 1])
            if abs(q[r, 1]) <= half_width / 2 and z_rel[r] < middle_below:
                middle[n_middle] = q[r, 0]
                n_middle += 1
    if n_middle < 2 or hi - lo < span:
        return n_band, rows, False, np.nan
    return n_band, rows, True, _median(middle[:n_middle])


@njit(**_JIT)
def _median(values):
    """``np.median`` of a non-empty array: the middle order statistic, or the mean of the two."""
    ordered = np.sort(values)
    half = ordered.shape[0] // 2
    return ordered[half] if ordered.shape[0] % 2 else (ordered[half - 1] + ordered[half]) / 2


@njit(**_INLINE)
def _nearest(x, marks):
    """The distance from ``x`` to the nearest of ``marks``."""
    best = np.inf
    for v in marks:
        best = min(best, abs(x - v))
    return best


@njit(**_JIT)
def fit_covariance(residual, jacobian, prior_information, scale, inlier_m, no_inlier_noise2, noise_floor2):
    """The hinged fit's covariance of all its parameters (the pose, then the fitted dimensions):
    Gauss-Newton with the Cauchy weights of the residuals and the noise of the inliers' residuals
    (their median square / 0.455, else ``no_inlier_noise2``; at least ``noise_floor2``), plus the
    weak prior (``prior_information``: its diagonal, 1 / sigma^2).
    numpy's order of operations; the inverse as numpy takes it (LAPACK gesv against the identity)."""
    n_params = jacobian.shape[1]
    weighted = _cauchy_weighted(jacobian, residual, scale)
    info = np.dot(weighted.T, jacobian) / inlier_noise2(residual, inlier_m, no_inlier_noise2, noise_floor2)
    for j in range(n_params):
        info[j, j] += prior_information[j]
    return np.linalg.solve(info, np.eye(n_params))


@njit(**_JIT)
def inlier_noise2(residual, inlier_m, no_inlier_noise2, noise_floor2):
    """The point noise of a fit: its inliers' (``inlier_m``) median square residual / 0.455, else
    ``no_inlier_noise2``; at least ``noise_floor2`` (the hinged fit's and the joint hinge fit's)."""
    n = residual.shape[0]
    squares = np.empty(n)
    n_in = 0
    for i in range(n):
        if abs(residual[i]) <= inlier_m:
            squares[n_in] = residual[i] * residual[i]
            n_in += 1
    sigma2 = no_inlier_noise2
    if n_in:
        sigma2 = _median(squares[:n_in]) / 0.455
    return max(sigma2, noise_floor2)


@njit(**_JIT)
def observed_directions(marginal, prior_sigmas, floor):
    """The pose directions a fit's points measured, as rows (k, n), and their noise (k, k): the
    marginal covariance in the weak prior's units, W = C / (sigma sigma^T), has the data's
    information inv(W) - I along its eigenvectors, 1 / w - 1; kept where that exceeds the prior's
    own (1, so w < 0.5); the floor added to the noise."""
    n = marginal.shape[0]
    whitened = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            whitened[i, j] = (marginal[i, j] + marginal[j, i]) / 2 / (prior_sigmas[i] * prior_sigmas[j])
    w, vectors = np.linalg.eigh(whitened)
    k = 0
    for i in range(n):
        k += w[i] < 0.5
    rows = np.empty((k, n))
    information = np.empty(k)
    r = 0
    for i in range(n):
        if w[i] < 0.5:
            information[r] = 1.0 / w[i] - 1.0
            for j in range(n):
                rows[r, j] = vectors[j, i] / prior_sigmas[j]
            r += 1
    noise = np.empty((k, k))
    for a in range(k):
        for b in range(k):
            total = 0.0
            for j in range(n):
                total += rows[a, j] * floor[j] * floor[j] * rows[b, j]
            noise[a, b] = total + (1.0 / information[a] if a == b else 0.0)
    return rows, noise


# ----------------------------------------------------------------------------- vehicle seeds


@njit(**_JIT)
def fullest_bin(projections, width):
    """(column, bin) of the fullest ``width``-wide bin of ``projections`` (n, k), one column at a
    time, bins counted from each column's lowest (floor(p / width) - its minimum); the first column,
    then the lowest bin, on ties: a Hough vote over k directions without an (n, k) array of bins
    and its histogram."""
    n, k = projections.shape
    best, best_column, best_bin = -1, 0, 0
    bins = np.empty(n, dtype=np.int64)
    for j in range(k):
        low, high = np.int64(0), np.int64(0)
        for i in range(n):
            b = np.int64(math.floor(projections[i, j] / width))
            bins[i] = b
            if i == 0 or b < low:
                low = b
            if i == 0 or b > high:
                high = b
        counts = np.zeros(high - low + 1, dtype=np.int64)
        for i in range(n):
            counts[bins[i] - low] += 1
        for b in range(high - low + 1):
            if counts[b] > best:
                best, best_column, best_bin = counts[b], j, b
    return best_column, best_bin


@njit(**_JIT)
def any_closer(a, b, distance):
    """Whether a point of ``b`` (M, 2) lies closer than ``distance`` to a point of ``a`` (N, 2)
    (squared distances summed x then y, strictly below distance squared: a k-d tree's query with
    that upper bound). ``a`` is binned in cells a little wider than ``distance``: a closer pair
    lies in the same or neighbouring cells."""
    if a.shape[0] == 0 or b.shape[0] == 0:
        return False
    limit = distance * distance
    cell_m = distance * (1.0 + 1e-9) if distance > 0 else 1.0
    lo_x, lo_y = a[:, 0].min(), a[:, 1].min()
    n = a.shape[0]
    cx = np.empty(n, dtype=np.int64)
    cy = np.empty(n, dtype=np.int64)
    for i in range(n):
        cx[i] = np.int64((a[i, 0] - lo_x) / cell_m)
        cy[i] = np.int64((a[i, 1] - lo_y) / cell_m)
    rows = cy.max() + 3  # a query's neighbour rows -1 .. rows - 2 never wrap into another column
    keys = (cx + 1) * rows + (cy + 1)
    order = np.argsort(keys)
    sorted_keys = keys[order]
    for j in range(b.shape[0]):
        qx, qy = b[j, 0], b[j, 1]
        fx, fy = math.floor((qx - lo_x) / cell_m), math.floor((qy - lo_y) / cell_m)
        if fx < -1 or fy < -1 or fx > cx.max() + 1 or fy > rows - 2:
            continue  # no cell of a beside it
        for di in range(-1, 2):
            for dj in range(-1, 2):
                ci, cj = np.int64(fx) + di + 1, np.int64(fy) + dj + 1
                if cj < 0 or cj >= rows:
                    continue
                key = ci * rows + cj
                t = np.searchsorted(sorted_keys, key)
                while t < n and sorted_keys[t] == key:
                    i = order[t]
                    t += 1
                    dx, dy = qx - a[i, 0], qy - a[i, 1]
                    if dx * dx + dy * dy < limit:
                        return True
    return False


@njit(**_JIT)
def _join_parts(xy, starts, distance):
    """Root part of each part (rows ``starts[k]:starts[k + 1]`` of ``xy``) after joining every two
    parts with a pair of points closer than ``distance`` (``any_closer``; tried only where their
    footprints come within it), chained: the smallest part index of its group."""
    n_parts = starts.shape[0] - 1
    low = np.empty((n_parts, 2))
    high = np.empty((n_parts, 2))
    for k in range(n_parts):
        part = xy[starts[k] : starts[k + 1]]
        for a in range(2):
            low[k, a], high[k, a] = part[:, a].min(), part[:, a].max()
    parent = np.arange(n_parts)
    for i in range(n_parts):
        for j in range(i + 1, n_parts):
            if (
                low[i, 0] - distance > high[j, 0]
                or low[j, 0] - distance > high[i, 0]
                or low[i, 1] - distance > high[j, 1]
                or low[j, 1] - distance > high[i, 1]
            ):
                continue  # footprints farther apart than the distance
            if _root(parent, i) != _root(parent, j) and any_closer(
                xy[starts[i] : starts[i + 1]], xy[starts[j] : starts[j + 1]], distance
            ):
                _union(parent, i, j)
    for k in range(n_parts):
        parent[k] = _root(parent, k)
    return parent


@njit(**_JIT)
def seed_groups(points, voxel, one, ground_z0, ground_dx, ground_dy, min_height, min_points, join_m, min_diagonal):
    """The start's clusters in one call: 26-connected components of ``voxel`` voxels (``grid_labels``)
    of at least ``min_points`` points whose highest point stands ``min_height`` above the ground
    under their centre (the plane z0 + dx x + dy y), largest first (ties: in raster order); those
    with points closer than ``join_m`` joined (``_join_parts``); kept when their footprint's diagonal
    reaches ``min_diagonal``. Returns the point indices of the clusters one after the other (each:
    its components in that order, each component's points in point order) and their bounds."""
    n = points.shape[0]
    ids, voxel_keys, dims, bits, word_rank, table_keys, table_ids = voxel_ids(points, np.ones(n, np.bool_), voxel, one)
    if bits.shape[0] == 0:
        voxel_keys = np.sort(voxel_keys)
        rank_in_key_order(voxel_keys, ids, table_keys, table_ids)
    labels = voxel_components(voxel_keys, dims, bits, word_rank, table_keys, table_ids)[ids]
    n_labels = labels.max() + 1 if n else 0
    counts, sums, top = _label_extents(points, labels, n_labels)
    order, _ = counting_order(labels, n_labels)
    first = np.zeros(n_labels + 1, dtype=np.int64)
    first[1:] = np.cumsum(counts)
    parts = np.empty(n_labels, dtype=np.int64)
    n_parts = 0
    for g in np.argsort(-counts, kind="mergesort"):
        centre_x, centre_y = sums[g, 0] / counts[g], sums[g, 1] / counts[g]
        height = top[g] - (ground_z0 + ground_dx * centre_x + ground_dy * centre_y)
        parts[n_parts] = g
        n_parts += counts[g] >= min_points and height >= min_height
    starts = np.zeros(n_parts + 1, dtype=np.int64)
    for k in range(n_parts):
        starts[k + 1] = starts[k] + counts[parts[k]]
    rows = np.empty(starts[n_parts], dtype=np.int64)
    for k in range(n_parts):
        rows[starts[k] : starts[k + 1]] = order[first[parts[k]] : first[parts[k] + 1]]
    xy = np.empty((rows.shape[0], 2))
    for r in range(rows.shape[0]):
        xy[r, 0], xy[r, 1] = points[rows[r], 0], points[rows[r], 1]
    roots = _join_parts(xy, starts, join_m)
    out = np.empty(rows.shape[0], dtype=np.int64)
    bounds = [0]
    for root in range(n_parts):
        if roots[root] != root:
            continue  # a group is listed at its first part (its root)
        begin = bounds[-1]
        end = begin
        for k in range(root, n_parts):
            if roots[k] == root:
                out[end : end + counts[parts[k]]] = rows[starts[k] : starts[k + 1]]
                end += counts[parts[k]]
        if _footprint_diagonal(points, out[begin:end]) >= min_diagonal:
            bounds.append(end)
        # else the next group overwrites its rows
    return out[: bounds[-1]], np.array(bounds, dtype=np.int64)


@njit(**_INLINE)
def _footprint_diagonal(points, rows):
    """The diagonal of the xy bounding box of the points ``rows`` (in the points' precision, as
    numpy's ``ptp`` of them)."""
    lo_x = hi_x = points[rows[0], 0]
    lo_y = hi_y = points[rows[0], 1]
    for r in rows:
        lo_x, hi_x = min(lo_x, points[r, 0]), max(hi_x, points[r, 0])
        lo_y, hi_y = min(lo_y, points[r, 1]), max(hi_y, points[r, 1])
    return math.hypot(hi_x - lo_x, hi_y - lo_y)


@njit(**_JIT)
def _label_extents(points, labels, n_labels):
    """Per label: point count, sums of x and of y (in point order, as np.bincount sums) and the
    highest z."""
    counts = np.zeros(n_labels, dtype=np.int64)
    sums = np.zeros((n_labels, 2))
    top = np.full(n_labels, -np.inf)
    for i in range(points.shape[0]):
        k = labels[i]
        counts[k] += 1
        sums[k, 0] += points[i, 0]
        sums[k, 1] += points[i, 1]
        top[k] = max(top[k], points[i, 2])
    return counts, sums, top


# ----------------------------------------------------------------------------- visibility


@njit(**_JIT)
def rays_through_box(points, origins, bounds, rotation, box, beyond_m):
    """How many rays (each sweep's origin to each of its returns, rows ``bounds[k]:bounds[k + 1]``;
    yard frame, turned by ``rotation`` into the box's frame) cross the upright box and end at least
    ``beyond_m`` past where they leave it, and how many end in it. ``box``: centre x, y, cos and
    sin of its yaw, half length, half width, bottom z, top z. The segment is clipped against the
    box's three slabs. Sweeps with a NaN origin are left out. Also returns the largest x along the
    box's length (its frame, centre 0) at which a counted ray is inside it (-inf for none)."""
    cx, cy, c, s, half_l, half_w, z_low, z_high = box[0], box[1], box[2], box[3], box[4], box[5], box[6], box[7]
    count = ended = 0
    front = -np.inf
    for k in range(origins.shape[0]):
        if not (np.isfinite(origins[k, 0]) and np.isfinite(origins[k, 1]) and np.isfinite(origins[k, 2])):
            continue  # a sweep whose sensor position is not known tells nothing
        ox, oy, oz = _box_frame(origins[k, 0], origins[k, 1], origins[k, 2], rotation, cx, cy, c, s)
        for i in range(bounds[k], bounds[k + 1]):
            px, py, pz = _box_frame(points[i, 0], points[i, 1], points[i, 2], rotation, cx, cy, c, s)
            dx, dy, dz = px - ox, py - oy, pz - oz
            enter, leave = _slab(0.0, 1.0, ox, dx, -half_l, half_l)
            enter, leave = _slab(enter, leave, oy, dy, -half_w, half_w)
            enter, leave = _slab(enter, leave, oz, dz, z_low, z_high)
            crossed = enter < leave and (1.0 - leave) * math.sqrt(dx * dx + dy * dy + dz * dz) >= beyond_m
            count += crossed
            if crossed:
                front = max(front, ox + max(enter * dx, leave * dx))
            ended += abs(px) <= half_l and abs(py) <= half_w and z_low <= pz <= z_high
    return count, ended, front


@njit(**_JIT)
def rays_before_side(points, origins, bounds, rotation, box, along, height, cone_cos, before_m):
    """Per place on a box's side and sweep: how many of the sweep's returns lie within the cone
    (cosine ``cone_cos``) about the ray from its sensor to the place, and how many of those ended
    ``before_m`` or more before it, not within ``before_m`` of the box (its own). The places:
    ``along`` its length (its frame, centre 0) at ``height`` (level frame), on the side facing
    that sweep's sensor. ``box``: centre x, y, cos and sin of its yaw, half length, half width
    (heights not asked); yard-frame rays turned by ``rotation`` into the level frame. Sweeps with
    a NaN origin count nothing."""
    cx, cy, c, s, half_l, half_w = box[0], box[1], box[2], box[3], box[4], box[5]
    n = along.shape[0]
    in_cone = np.zeros((n, origins.shape[0]), dtype=np.int64)
    before = np.zeros((n, origins.shape[0]), dtype=np.int64)
    for k in range(origins.shape[0]):
        if not (np.isfinite(origins[k, 0]) and np.isfinite(origins[k, 1]) and np.isfinite(origins[k, 2])):
            continue
        ox, oy, oz = _box_frame(origins[k, 0], origins[k, 1], origins[k, 2], rotation, cx, cy, c, s)
        side = half_w if oy >= 0.0 else -half_w
        ux, uy, uz, reach = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        for j in range(n):
            dx, dy, dz = along[j] - ox, side - oy, height - oz
            reach[j] = math.sqrt(dx * dx + dy * dy + dz * dz)
            ux[j], uy[j], uz[j] = dx / reach[j], dy / reach[j], dz / reach[j]
        for i in range(bounds[k], bounds[k + 1]):
            px, py, pz = _box_frame(points[i, 0], points[i, 1], points[i, 2], rotation, cx, cy, c, s)
            dx, dy, dz = px - ox, py - oy, pz - oz
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            if r == 0.0:
                continue
            outside = abs(px) > half_l + before_m or abs(py) > half_w + before_m
            for j in range(n):
                if (dx * ux[j] + dy * uy[j] + dz * uz[j]) >= cone_cos * r:
                    in_cone[j, k] += 1
                    before[j, k] += outside and r <= reach[j] - before_m
    return in_cone, before


@njit(**_JIT)
def plane_crossings(points, origins, bounds, rotation, lag, plane, motion, beyond_m):
    """Where rays (each sweep's origin to each of its returns, rows ``bounds[k]:bounds[k + 1]``; yard
    frame, turned by ``rotation`` into the level frame) cross an upright plane and end at least
    ``beyond_m`` behind it: (n, 2) along the plane from its point, and height. ``plane``: point x,
    y, direction x, y (unit), half length, top z; crossings farther along or higher are left out.
    ``motion``: centre x, y, velocity x, y and yaw rate of a unit each ray is carried with by its
    ``lag`` (first order; zeros: as captured). Sweeps with a NaN origin are left out."""
    px, py, dx, dy, half_length, top = plane[0], plane[1], plane[2], plane[3], plane[4], plane[5]
    nx, ny = -dy, dx
    out = np.empty((points.shape[0], 2))
    n = 0
    for k in range(origins.shape[0]):
        if not (np.isfinite(origins[k, 0]) and np.isfinite(origins[k, 1]) and np.isfinite(origins[k, 2])):
            continue
        ox, oy, oz = _box_frame(origins[k, 0], origins[k, 1], origins[k, 2], rotation, 0.0, 0.0, 1.0, 0.0)
        for i in range(bounds[k], bounds[k + 1]):
            ex, ey, ez = _box_frame(points[i, 0], points[i, 1], points[i, 2], rotation, 0.0, 0.0, 1.0, 0.0)
            sx, sy = _carried(ox, oy, motion, lag[i])
            ex, ey = _carried(ex, ey, motion, lag[i])
            before = (sx - px) * nx + (sy - py) * ny
            after = (ex - px) * nx + (ey - py) * ny
            if before * after >= 0.0 or abs(after) < beyond_m:
                continue
            t = before / (before - after)
            along = (sx + t * (ex - sx) - px) * dx + (sy + t * (ey - sy) - py) * dy
            z = oz + t * (ez - oz)
            if abs(along) <= half_length and z <= top:
                out[n, 0], out[n, 1] = along, z
                n += 1
    return out[:n]


@njit(**_INLINE)
def _carried(x, y, motion, lag):
    """A level-frame place carried with a unit's motion (centre x, y, velocity x, y, yaw rate) by ``lag``."""
    vx = motion[2] - motion[4] * (y - motion[1])
    vy = motion[3] + motion[4] * (x - motion[0])
    return x + vx * lag, y + vy * lag


@njit(**_INLINE)
def _box_frame(x, y, z, rotation, cx, cy, c, s):
    """A yard point turned into the level frame, then into the box's frame (its centre, its yaw)."""
    lx = rotation[0, 0] * x + rotation[0, 1] * y + rotation[0, 2] * z - cx
    ly = rotation[1, 0] * x + rotation[1, 1] * y + rotation[1, 2] * z - cy
    lz = rotation[2, 0] * x + rotation[2, 1] * y + rotation[2, 2] * z
    return c * lx + s * ly, -s * lx + c * ly, lz


@njit(**_INLINE)
def _slab(enter, leave, start, step, low, high):
    """The segment's parameter interval [enter, leave] narrowed to the slab low <= start + t step <= high
    (empty: enter >= leave)."""
    if step == 0.0:
        return (enter, leave) if low <= start <= high else (1.0, 0.0)
    a, b = (low - start) / step, (high - start) / step
    return max(enter, min(a, b)), min(leave, max(a, b))


# ----------------------------------------------------------------------------- kinematic filter


@njit(**_JIT)
def wrap_angles(values):
    """(a + pi) mod 2 pi - pi of each value (numpy's floored remainder, the same bits)."""
    out = np.empty_like(values)
    for i in range(values.shape[0]):
        out[i] = (values[i] + np.pi) % (2 * np.pi) - np.pi
    return out


@njit(**_JIT)
def _kinematics(s, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m):
    """d/dt of states (k, 6) [x, y, yaw, v, curvature, hitch] (kinematic_filter's model). The
    reference point (x, y) lies ``axle_m`` ahead of the rear axle that does not slip sideways (speed
    v, curvature): it moves sideways at the yaw rate times ``axle_m``, and the kingpin lies
    ``kingpin_m - axle_m`` behind that axle (with ``axle_m`` 0, the arithmetic of the plain model)."""
    d = np.zeros_like(s)
    kingpin = kingpin_m - axle_m
    for i in range(s.shape[0]):
        v, kappa, yaw, hitch = s[i, 3], s[i, 4], s[i, 2], s[i, 5]
        slip = v * kappa * axle_m
        d[i, 0] = v * math.cos(yaw) - slip * math.sin(yaw)
        d[i, 1] = v * math.sin(yaw) + slip * math.cos(yaw)
        d[i, 2] = v * kappa
        if articulated:
            d[i, 5] = hitch_rate(v, kappa, hitch, kingpin, trailer_axle_m)
            # reversing (unstable), a driver steers the hitch still: over ``hold_m`` travelled
            d[i, 4] = (holding_curvature(hitch, kingpin, trailer_axle_m) - kappa) * max(-v, 0.0) / hold_m
    return d


@njit(**_JIT)
def holding_curvature(hitch, kingpin_m, trailer_axle_m):
    """The path curvature at which the hitch angle holds still (``hitch_rate`` = 0 at any speed)."""
    return -math.sin(hitch) / max(trailer_axle_m + kingpin_m * math.cos(hitch), MIN_HOLD_ARM_M)


@njit(**_JIT)
def hitch_rate(v, curvature, hitch, kingpin_m, trailer_axle_m):
    """γ' of the one-trailer kinematics (kinematic_filter's model): −(v sin γ + M ω cos γ) / L2 − ω, ω = v κ."""
    omega = v * curvature
    return -(v * math.sin(hitch) + kingpin_m * omega * math.cos(hitch)) / trailer_axle_m - omega


@njit(**_JIT)
def propagate_states(states, step_s, steps, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m):
    """States (k, 6) after ``steps`` midpoint steps of ``step_s``, yaw and hitch wrapped: the
    arithmetic of the numpy code it replaced (s + h d(s + 0.5 h d(s)), products in its order)."""
    s = states.copy()
    half = 0.5 * step_s
    for _ in range(steps):
        mid = s + half * _kinematics(s, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m)
        s = s + step_s * _kinematics(mid, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m)
    s[:, 2] = wrap_angles(s[:, 2])
    s[:, 5] = wrap_angles(s[:, 5])
    return s


@njit(**_JIT)
def angle_residuals(a, b, angle_columns):
    """a - b (rows of a minus the row b, (1, n)), the angle columns wrapped."""
    d = a - b
    for c in angle_columns:
        d[:, c] = wrap_angles(d[:, c])
    return d


@njit(**_JIT)
def angle_mean(sigmas, weights, angle_columns):
    """The weighted mean of the rows of ``sigmas``; angle columns averaged on the circle."""
    mean = np.dot(weights, sigmas)
    for c in angle_columns:
        mean[c] = math.atan2(np.dot(weights, np.sin(sigmas[:, c])), np.dot(weights, np.cos(sigmas[:, c])))
    return mean


# ----------------------------------------------------------------------------- unscented filter


@njit(**_JIT)
def upper_factor(p):
    """U with U^T U = p (Cholesky); a covariance that lost definiteness to rounding is factored
    through its eigen-decomposition with the eigenvalues clipped at 1e-12."""
    n = p.shape[0]
    low = np.zeros_like(p)
    for j in range(n):
        d = p[j, j]
        for k in range(j):
            d -= low[j, k] * low[j, k]
        if not d > 0.0:
            w, v = np.linalg.eigh((p + p.T) / 2)
            return np.ascontiguousarray((v * np.sqrt(np.maximum(w, 1e-12))).T)
        low[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            e = p[i, j]
            for k in range(j):
                e -= low[i, k] * low[j, k]
            low[i, j] = e / low[j, j]
    return np.ascontiguousarray(low.T)


@njit(**_JIT)
def _sigma_points(x, p, spread):
    """Merwe's scaled sigma points: x, x + each row of U, x - each row (U^T U = spread p)."""
    u = upper_factor(spread * p)
    n = x.shape[0]
    sigmas = np.empty((2 * n + 1, n))
    sigmas[0] = x
    for i in range(n):
        sigmas[1 + i] = x + u[i]
        sigmas[1 + n + i] = x - u[i]
    return sigmas


@njit(**_JIT)
def _weighted_cross(a, b, wc):
    """sum_i wc_i a_i^T b_i over the rows of a and b."""
    return np.dot(np.ascontiguousarray(a.T * wc), b)


@njit(**_JIT)
def ukf_predict(x, p, wm, wc, spread, q, step_s, steps, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m, angles):
    """One unscented prediction over the one-trailer kinematics (``steps`` midpoint steps of
    ``step_s``): the state, its covariance and the sigma points drawn around them for the update."""
    sigmas = propagate_states(
        _sigma_points(x, p, spread), step_s, steps, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m
    )
    mean = angle_mean(sigmas, wm, angles)
    d = angle_residuals(sigmas, mean.reshape(1, -1), angles)
    cov = _weighted_cross(d, d, wc) + q
    return mean, cov, _sigma_points(mean, cov, spread)


@njit(**_JIT)
def ukf_update(x, p, sigmas_f, wm, wc, measured, z, r, rows, x_angles, z_angles):
    """Fuse ``z`` (noise ``r``) of the state's ``measured`` columns, only the directions ``rows``
    (k, m) of it (r is k x k). Returns the state, its covariance and the innovation's Mahalanobis
    distance."""
    sigmas_h = np.ascontiguousarray(sigmas_f[:, measured])
    zp = angle_mean(sigmas_h, wm, z_angles)
    dz = angle_residuals(sigmas_h, zp.reshape(1, -1), z_angles)
    dx = angle_residuals(sigmas_f, x.reshape(1, -1), x_angles)
    s = np.dot(np.dot(rows, _weighted_cross(dz, dz, wc)), np.ascontiguousarray(rows.T)) + r
    pxz = np.dot(_weighted_cross(dx, dz, wc), np.ascontiguousarray(rows.T))
    y = np.dot(rows, angle_residuals(z.reshape(1, -1), zp.reshape(1, -1), z_angles)[0])
    si = np.linalg.inv(s)
    k = np.dot(pxz, si)
    return x + np.dot(k, y), p - np.dot(k, np.dot(s, np.ascontiguousarray(k.T))), math.sqrt(np.dot(np.dot(y, si), y))


# ----------------------------------------------------------------------------- warm-up

_WARM = False


def warm_up() -> None:
    """Load (or compile, the first time on this machine) every kernel specialisation the pipeline
    calls, on tiny arrays, so that no frame pays for it."""
    global _WARM
    if _WARM:
        return
    p32 = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.5], [0.2, 0.1, 0.0]], dtype=np.float32)
    p64 = p32.astype(np.float64)
    offsets = np.zeros(3, dtype=np.float32)
    out_p, out_o = np.empty((3, 3), dtype=np.float32), np.empty(3, dtype=np.float32)
    sweep_to_yard(p32, offsets, np.eye(3, dtype=np.float32), np.zeros(3, dtype=np.float32), 0.0, 1e4, out_p, out_o, 0)
    interpolate(p32.copy(), offsets, np.zeros((1, 10)))
    take = np.ones(3, dtype=np.bool_)
    cells = np.zeros(64, dtype=np.uint16)
    flags = np.zeros(64, dtype=np.bool_)
    background_pass(
        p32,
        np.zeros(3, dtype=np.float32),
        np.float32(1.0),
        np.full(3, 3.5, dtype=np.float32),
        np.array([4, 4, 4, 1], dtype=np.int64),
        np.zeros(8, dtype=np.uint8),
        True,
        np.zeros(16, dtype=np.bool_),
        True,
        np.zeros(16, dtype=np.bool_),
        np.zeros(8, dtype=np.uint8),
        np.empty(3, dtype=np.bool_),
        np.empty(3, dtype=np.bool_),
        np.empty(3, dtype=np.int32),
        np.empty(3, dtype=np.int32),
        np.empty(3, dtype=np.int32),
    )
    count_sample(np.zeros(2, dtype=np.int32), np.zeros(64, dtype=np.uint8), True, 1, flags, np.empty(2, dtype=np.int32))
    one_cell = np.array([5], dtype=np.int32)
    forget_counts(one_cell, np.ones(64, np.uint8))
    forgotten(one_cell, np.zeros(64, np.uint8), flags, 1, 0, np.empty(1, dtype=np.int32), 0)
    bits = np.zeros(8, dtype=np.uint8)
    flip_cells(one_cell, flags, cells, bits, np.array([0]))
    flip_cells(one_cell, flags, cells, bits, np.array([0]))
    update_cells(one_cell, np.zeros(64, np.uint8), flags, cells, bits, np.array([0]), 1, 0)
    box_columns(np.zeros((1, 6)), 0.1, 0.0, 0.0, 0.2, 4, 4, np.zeros(16, dtype=np.bool_))
    box_mask(p32, np.zeros(3, dtype=np.float32), np.ones(3, dtype=np.float32), np.empty(3, dtype=np.bool_))
    strided_pick(np.array([True, False, True]), 1, 1)
    for p in (p32, p64):  # level points are float32 on level ground, float64 rotated
        in_upright_box(p, np.array([0.0, 0.0, 1.0, 0.0, 1.0, 1.0]), np.empty(3, dtype=np.bool_))
        to_frame(p, 0.0, 0.0, 1.0, 0.0)
        in_first_box_only(p, np.array([0.0, 0.0, 1.0, 0.0, 1.0, 1.0]), np.zeros(6), np.empty(3, dtype=np.bool_))
        owned_to_frame(p, np.zeros(3, dtype=np.int64), 0, 0.0, 0.0, 1.0, 0.0)
    count_beside(np.zeros((2, 2)), 1.0, 1.0)
    above_plane(p32, take, np.array([0.0, 0.0, 1.0]), 0.0, 0.1, np.empty(3, dtype=np.int64))
    plane_scores(p64, np.array([[0.0, 0.0, 1.0]]), np.zeros(1), 0.1)
    row_mean(p64)
    plane_hypotheses(p64, p64, p64, 0.9)
    far = p32 * np.float32(1e6)  # a key range too wide for the bits: the hash table
    for points, voxel, one in ((p32, np.float32(0.5), np.float32(1.0)), (p64, 0.5, 1.0), (p32, 0.5, 1.0)):
        for cloud in (points, far.astype(points.dtype)):
            ids, vkeys, dims, bits, word_rank, tk, ti = voxel_ids(cloud, take, voxel, one)
            if len(bits) == 0:
                vkeys = np.sort(vkeys)
                rank_in_key_order(vkeys, ids, tk, ti)
            voxel_sums(cloud, np.zeros((3, 0)), ids, len(vkeys))
            voxel_components(vkeys, dims, bits, word_rank, tk, ti)
    counting_order(np.array([1, 0, 1], dtype=np.int64), 2)
    radius_components(p64, 0.5)
    min_area_rect(np.ascontiguousarray(p64[:, :2]))
    for points in (p32, p64):  # level ground keeps float32; a slope float64
        claim_points(points, np.zeros((2, 6)), np.array([0, 0]), 1, 0.5)
    for n_boxes in (1, 2):
        geometry = np.r_[np.zeros(5), 1.0, np.tile([2.0, 4.0, 2.0, 0.5, 3.0], n_boxes)]
        nearest_faces(
            np.ascontiguousarray(p64[:, :2]), np.ascontiguousarray(p64[:, 2]), geometry, 0.25, 2 + n_boxes, 0.1
        )
    xy, z = np.ascontiguousarray(p64[:, :2]), np.ascontiguousarray(p64[:, 2])
    v0 = np.array([0.0, 0.0, 0.1, 0.2, 9.0, 0.3, 1.0])
    geometry = np.r_[np.zeros(5), 0.0, np.tile([2.0, 4.0, 2.0, 0.5, 3.0], 2)]
    ranges = np.array([2.0, 16.5, -1.5, 1.5])
    _, residual, jacobian, _, _, _ = irls(
        xy, z, geometry, 0.25, 4, True, True, v0, np.ones(7), 0.1, 0.2, 2, ranges, 0.1
    )
    cauchy_cost(residual, 0.1)
    inlier_noise2(residual, 0.1, 0.01, 0.0004)  # the joint hinge fit's, called on its own
    fit_covariance(residual, jacobian, np.ones(7), 0.1, 0.3, 0.01, 0.0004)
    joint_hinge_irls(
        xy, z, np.array([0, 3]), geometry[None].copy(), v0[None, :4].copy(), v0[5:].copy(), np.ones(4), np.ones(2),
        0.1, 0.2, 2, ranges, 0.1, 0.25,
    )  # fmt: skip
    face_median(p64, 1, np.zeros(3, dtype=np.int8), np.zeros(3, dtype=np.int8), 0, 0, (-1.0, 1.0))
    labels = np.zeros(3, dtype=np.int8)
    rear_face(
        p64[:, :2].copy(), p64[:, 2].copy(), labels, labels, (0.0, 1.0), 1.0, 1.0, 0.1, (0.3, 0.8), 1.0, 0.4, 1.0, 1.0
    )
    fit_labels(np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64), residual[:3], residual[:3], 0.1, 1)
    observed_directions(np.eye(4), np.ones(4), np.ones(4))
    fit_faces(xy, z, geometry, 0.25, 4, True, True, False, v0, 0.1)  # the tests call it on its own
    any_closer(xy, xy, 0.5)  # the tests call it on its own
    fullest_bin(np.ones((3, 2)), 0.1)
    rays_through_box(p32, p64[:1], np.array([0, 3]), np.eye(3), np.array([0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]), 0.3)
    plane = np.array([0.0, 0.0, 1.0, 0.0, 1.0, 1.0])
    plane_crossings(p32, p64[:1], np.array([0, 3]), np.eye(3), np.zeros(3), plane, np.zeros(5), 0.3)
    for points, one in ((p32, np.float32(1.0)), (p64, 1.0)):  # level ground keeps float32; a slope float64
        seed_groups(points, one * 0.5, one, 0.0, 0.0, 0.0, 0.0, 1, 0.5, 0.0)
    wrap_angles(np.zeros(2))
    hitch_rate(1.0, 0.1, 0.2, -0.3, 7.0)
    holding_curvature(0.2, -0.3, 7.0)
    states = np.zeros((13, 6))
    for articulated in (True, False):
        propagate_states(states, 0.1, 1, -0.3, 7.0, articulated, 1.0, 0.0)
    for columns in (np.array([2, 5]), np.array([2, 3]), np.array([2])):
        angle_residuals(states, states[:1], columns)
        angle_mean(states, np.ones(13), columns)
    weights, x_angles = np.ones(13), np.array([2, 5])
    for articulated, measured, z_angles in (
        (True, np.array([0, 1, 2, 5]), np.array([2, 3])),
        (False, np.arange(3), np.array([2])),
    ):
        x, p, sigmas = ukf_predict(
            np.zeros(6), np.eye(6), weights, weights, 6.0, np.eye(6), 0.1, 1, -0.3, 7.0, articulated, 1.0, 0.0, x_angles
        )
        for rows in (np.eye(len(measured)), np.eye(len(measured))[:1]):  # all directions, one
            noise = np.eye(len(rows))
            ukf_update(
                x, p, sigmas, weights, weights, measured, np.zeros(len(measured)), noise, rows, x_angles, z_angles
            )
    upper_factor(-np.eye(6))
    _WARM = True
