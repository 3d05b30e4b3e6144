"""Quaternion and Euler helpers over whole arrays.

Glossary
--------
q, quat
    Unit quaternion stored scalar-last, ``(..., 4)`` as ``x, y, z, w``: the
    order of ``scipy.spatial.transform.Rotation`` and of glTF.
order
    Three upper-case axis letters such as ``"ZXY"``: the BVH channel order.
    BVH rotations are *intrinsic* in channel order, ``R = R_Z @ R_X @ R_Y``
    for ``ZXY``, which is scipy's upper-case (intrinsic) convention.
euler
    Angles in degrees, ``(..., 3)``, the i-th angle about ``order[i]``.

Every function broadcasts over leading axes and never mutates its input.
"""

from __future__ import annotations

import numpy as np

from .native import frame_halves, on_both_cores
from .native import kernels as _kernels  # the compiled loops, where built (core/native.py)

__all__ = [
    "quat_mul",
    "quat_inv",
    "quat_rotate",
    "quat_slerp",
    "quat_pow",
    "quat_between",
    "quat_normalize",
    "quat_angle",
    "quat_identity",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_from_joint_euler",
    "quat_to_euler",
    "euler_blocks",
    "quat_to_matrix",
    "quat_from_matrix",
    "quat_unroll",
    "unit_track",
    "cross",
    "vector_norm",
    "sum_last",
]


#: Elements (of the leading shape: joints' or points' frames) per block that keep a block's NumPy passes
#: in the CPU's cache: `_blockwise` here, `mocap_exaggerate.core.kinematics.cache_blocks` for frames.
CACHE_ELEMENTS = 1 << 14


def _blockwise(function):
    """Run an element-wise function of arrays block by block along their first axis, where the arrays are
    long: each of its NumPy passes then works on a block that stays in the CPU's cache instead of
    streaming whole clips through memory (about twice as fast on 10,000 frames of 95 joints, and no
    longer slower per frame on longer clips). Every element is computed as before: the same bits.

    An argument with the broadcast shape's first axis is cut; one that broadcasts along it is passed whole.
    """

    def run(*args):
        arrays = [np.asarray(a) for a in args]  # (the function sees what it always did: its own dtype rules)
        shape = np.broadcast_shapes(*(a.shape[:-1] for a in arrays))  # the leading shape (vectors last)
        if len(shape) < 1 or int(np.prod(shape)) <= 2 * CACHE_ELEMENTS:
            return function(*arrays)
        rows = max(CACHE_ELEMENTS // max(int(np.prod(shape[1:])), 1), 1)
        cut = [a.ndim == len(shape) + 1 and a.shape[0] == shape[0] for a in arrays]
        first = function(*(a[:rows] if c else a for a, c in zip(arrays, cut)))
        out = np.empty((shape[0],) + first.shape[1:], dtype=first.dtype)
        out[:rows] = first
        for start in range(rows, shape[0], rows):
            out[start : start + rows] = function(*(a[start : start + rows] if c else a for a, c in zip(arrays, cut)))
        return out

    run.__name__, run.__qualname__, run.__doc__ = function.__name__, function.__qualname__, function.__doc__
    run.__wrapped__ = function
    return run


def _parts(q: np.ndarray):
    q = np.asarray(q, dtype=np.float64)
    return q[..., 0], q[..., 1], q[..., 2], q[..., 3]


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions ``shape + (4,)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


@_blockwise
def _norm(v: np.ndarray) -> np.ndarray:
    total = v[..., 0] * v[..., 0]
    for i in range(1, v.shape[-1]):
        total = total + v[..., i] * v[..., i]
    return np.sqrt(total)


def vector_norm(v: np.ndarray, *, keepdims: bool = False) -> np.ndarray:
    """``np.linalg.norm(v, axis=-1)``, the same bits, at a third of its time on long arrays.

    Over a last axis of fewer than eight, NumPy's reduction adds the squares one after
    the other; here they are added so by element-wise passes (a reduction over three is
    mostly overhead), a block at a time in the cache. Longer axes go to NumPy.
    """
    v = np.asarray(v)
    if not 0 < v.shape[-1] < 8 or v.dtype != np.float64:
        return np.linalg.norm(v, axis=-1, keepdims=keepdims)
    out = _norm(v)
    return out[..., None] if keepdims else out


@_blockwise
def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (without ``np.cross``'s overhead)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = ay * bz - az * by
    out[..., 1] = az * bx - ax * bz
    out[..., 2] = ax * by - ay * bx
    return out


@_blockwise
def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), broadcasting."""
    ax, ay, az, aw = _parts(a)
    bx, by, bz, bw = _parts(b)
    out = np.empty(np.broadcast_shapes(np.shape(a), np.shape(b)))
    out[..., 0] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 1] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 2] = aw * bz + ax * by - ay * bx + az * bw
    out[..., 3] = aw * bw - ax * bx - ay * by - az * bz
    return out


def quat_inv(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (the conjugate)."""
    return np.asarray(q, dtype=np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])


@_blockwise
def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)``, broadcasting.

    ``v + w t + u x t`` with ``t = 2 u x v`` (u, w: the vector and scalar parts).
    """
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = q[..., :3]
    t = 2.0 * cross(u, v)
    return v + q[..., 3:] * t + cross(u, t)


def quat_slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation from ``a`` (t = 0) to ``b`` (t = 1) along the shorter arc.

    a, b : (..., 4) unit quaternions; t : broadcasting with their leading shape
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = sum_last(a * b, keepdims=True)
    sign = np.where(dot < 0.0, -1.0, 1.0)
    dot = np.minimum(np.abs(dot), 1.0)
    angle = np.arccos(dot)
    sin = np.sin(angle)
    small = sin < 1e-9
    safe = np.where(small, 1.0, sin)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * angle) / safe)
    wb = sign * np.where(small, t, np.sin(t * angle) / safe)
    out = wa * a + wb * b
    norm = vector_norm(out, keepdims=True)
    return out / np.where(norm > 0.0, norm, 1.0)


def quat_pow(q: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """``q`` raised to ``t``: the same axis, ``t`` times the angle, for either sign of ``q``.

    Unlike `quat_slerp` from the identity, a quaternion with ``w < 0`` (a turn of
    more than half a revolution) is not replaced by the shorter turn the other
    way: interpolation stays continuous when a chain of rotations made
    hemisphere-continuous in time passes half a turn.

    >>> bool(np.allclose(quat_pow(np.array([0.0, 0.0, -1.0, 0.0]), 0.5), [0, 0, -np.sqrt(0.5), np.sqrt(0.5)]))
    True
    """
    q = np.asarray(q, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    vector = q[..., :3]
    size = vector_norm(vector, keepdims=True)
    half = np.arctan2(size, q[..., 3:])  # in [0, pi]: more than a half turn when w < 0
    half = np.where(size > 1e-12, half, 0.0)  # -1 is a whole turn about no axis in particular: none
    axis = vector / np.where(size > 1e-12, size, 1.0)
    return np.concatenate([axis * np.sin(t * half), np.cos(t * half)], axis=-1)


@_blockwise
def quat_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation carrying directions ``u`` onto ``v``, ``(..., 3) -> (..., 4)``.

    Identity where either vector is (nearly) zero; a half turn about some
    perpendicular axis where they are opposite.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    nu = vector_norm(u, keepdims=True)
    nv = vector_norm(v, keepdims=True)
    q = np.concatenate([cross(u, v), nu * nv + sum_last(u * v, keepdims=True)], axis=-1)
    norm = vector_norm(q, keepdims=True)
    tiny = 1e-12 * np.maximum(nu * nv, 1e-300)
    opposite = (norm <= tiny) & (nu * nv > 0)
    if np.any(opposite):
        # Any axis perpendicular to u: cross with the coordinate axis least aligned with it.
        helper = np.eye(3)[np.argmin(np.abs(u), axis=-1)]
        perpendicular = cross(u, helper)
        perpendicular /= np.maximum(vector_norm(perpendicular, keepdims=True), 1e-300)
        flipped = np.concatenate([perpendicular, np.zeros(u.shape[:-1] + (1,))], axis=-1)
        q = np.where(opposite, flipped, q)
        norm = np.where(opposite, 1.0, norm)
    degenerate = (nu * nv <= 1e-300) | (norm <= 0)
    return np.where(degenerate, quat_identity(q.shape[:-1]), q / np.where(norm > 0, norm, 1.0))


@_blockwise
def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Scale quaternions to unit length."""
    return q / vector_norm(q, keepdims=True)


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians of the rotation taking ``a`` to ``b``, in ``[0, pi]``."""
    # atan2 of the relative rotation keeps full precision for tiny angles,
    # where arccos of the dot product loses half the digits.
    rel = quat_mul(quat_inv(a), b)
    return 2.0 * np.arctan2(vector_norm(rel[..., :3]), np.abs(rel[..., 3]))


def quat_from_axis_angle(axis: str, angle: np.ndarray) -> np.ndarray:
    """Quaternions for rotations by ``angle`` radians about the named axis ``"X"|"Y"|"Z"``."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    q = np.zeros(half.shape + (4,))
    q[..., "XYZ".index(axis)] = np.sin(half)
    q[..., 3] = np.cos(half)
    return q


def _axes(order: str) -> tuple[int, int, int, int]:
    """The axes ``i, j, k`` (0, 1, 2 for X, Y, Z) of a Tait-Bryan order such as ``"ZXY"``, and its parity:
    +1 when ``ijk`` is a cyclic permutation of ``XYZ``, else -1."""
    i, j, k = ("XYZ".index(a) for a in order.upper())
    return i, j, k, 1 if (j - i) % 3 == 1 else -1


def quat_from_euler(euler: np.ndarray, order: str) -> np.ndarray:
    """Quaternions from intrinsic Euler angles in degrees.

    euler : (..., 3) float64, the i-th angle about ``order[i]``

    The same rotation as ``Rotation.from_euler(order, euler, degrees=True)``
    and as ``q0 * q1 * q2`` of the three axis quaternions. For the six
    Tait-Bryan orders (three different axes, every BVH order) the product is
    written out: with half-angle cosines ``c`` and sines ``s`` and ``p`` the
    parity of the axis permutation (+1 when ``ijk`` is cyclic),
    ``q_i = s1 c2 c3 + p c1 s2 s3``, ``q_j = c1 s2 c3 - p s1 c2 s3``,
    ``q_k = c1 c2 s3 + p s1 s2 c3``, ``w = c1 c2 c3 - p s1 s2 s3``.
    """
    order = order.upper()
    radians = np.deg2rad(np.asarray(euler, dtype=np.float64))
    if len(set(order)) != 3:
        q = quat_from_axis_angle(order[0], radians[..., 0])
        q = quat_mul(q, quat_from_axis_angle(order[1], radians[..., 1]))
        return quat_mul(q, quat_from_axis_angle(order[2], radians[..., 2]))
    i, j, k, parity = _axes(order)
    half = 0.5 * radians
    c, s = np.cos(half), np.sin(half)
    c1, c2, c3 = c[..., 0], c[..., 1], c[..., 2]
    s1, s2, s3 = s[..., 0], s[..., 1], s[..., 2]
    c1c2, s1s2, c1s2, s1c2 = c1 * c2, s1 * s2, c1 * s2, s1 * c2
    out = np.empty(radians.shape[:-1] + (4,))
    out[..., i] = s1c2 * c3 + parity * c1s2 * s3
    out[..., j] = c1s2 * c3 - parity * s1c2 * s3
    out[..., k] = c1c2 * s3 + parity * s1s2 * c3
    out[..., 3] = c1c2 * c3 - parity * s1s2 * s3
    return out


def quat_from_joint_euler(euler: np.ndarray, orders: list[str], *, compiled: bool = True) -> np.ndarray:
    """Quaternions ``(F, J, 4)`` of each joint's Euler angles ``(F, J, 3)`` in degrees, joint ``j`` in
    ``orders[j]`` (`quat_from_euler` joint by joint).

    ``compiled``: the Tait-Bryan joints in one pass by ``core/_kernels.c`` where it was built (NumPy's
    arithmetic in its order, with the C library's sine and cosine: the same bits where NumPy's are the
    C library's, as on the machines we test; half the time).
    """
    euler = np.asarray(euler, dtype=np.float64)
    out = np.empty(euler.shape[:-1] + (4,))
    codes = np.full((len(orders), 4), -1, dtype=np.int64)
    for j, order in enumerate(orders):
        order = order.upper()
        if len(set(order)) == 3:
            codes[j] = _axes(order)
    kernel = (compiled and _kernels is not None and euler.ndim == 3 and euler.shape[1:] == (len(orders), 3)
              and len(orders) > 0)
    if kernel:
        euler = np.ascontiguousarray(euler)
        on_both_cores(lambda part: _kernels.quat_from_euler(euler[part], out[part], codes, part.stop - part.start,
                                                            len(orders)), frame_halves(len(euler)))
    by_order: dict[str, list[int]] = {}
    for j, order in enumerate(orders):
        if not kernel or codes[j, 0] < 0:
            by_order.setdefault(order.upper(), []).append(j)
    for order, members in by_order.items():
        out[:, members] = quat_from_euler(euler[:, members], order)
    return out


def _matrix_entry(parts: tuple, row: int, col: int) -> np.ndarray:
    """Entry ``(row, col)`` of the rotation matrix of unit quaternions ``parts = (x, y, z, w)``:
    ``1 - 2 (a a + b b)`` on the diagonal (``a``, ``b`` the other two axes), ``2 (p q -+ r w)`` off it
    (``r`` the third axis; plus below the diagonal's cyclic order). One expression for `quat_to_matrix`
    and for the Euler angles read from five entries, so both give the same bits."""
    w = parts[3]
    if row == col:
        a, b = (parts[k] for k in range(3) if k != row)
        return 1.0 - 2.0 * (a * a + b * b)
    low, high = sorted((row, col))
    third = parts[3 - row - col]
    if (col - row) % 3 == 2:
        return 2.0 * (parts[low] * parts[high] + third * w)
    return 2.0 * (parts[low] * parts[high] - third * w)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` (they act on column vectors)."""
    parts = _parts(q)
    out = np.empty(np.shape(q)[:-1] + (3, 3))
    for row in range(3):
        for col in range(3):
            out[..., row, col] = _matrix_entry(parts, row, col)
    return out


def quat_from_matrix(matrix: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` of rotation matrices ``(..., 3, 3)`` (Shepperd's method).

    Each quaternion is taken from the largest of its four squared
    components, so no division is by a small number.
    """
    m = np.asarray(matrix, dtype=np.float64)
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    # 4 * component^2 for x, y, z, w
    squares = np.stack([1.0 + 2.0 * m[..., 0, 0] - trace, 1.0 + 2.0 * m[..., 1, 1] - trace,
                        1.0 + 2.0 * m[..., 2, 2] - trace, 1.0 + trace], axis=-1)
    pick = np.argmax(squares, axis=-1)
    out = np.empty(m.shape[:-2] + (4,))
    for k in range(4):
        chosen = pick == k
        if not np.any(chosen):
            continue
        big = np.sqrt(np.maximum(squares[chosen, k], 1e-300))
        part = np.empty((int(chosen.sum()), 4))
        part[:, k] = 0.5 * big
        sub = m[chosen]
        if k == 3:
            part[:, 0] = (sub[:, 2, 1] - sub[:, 1, 2]) / (2.0 * big)
            part[:, 1] = (sub[:, 0, 2] - sub[:, 2, 0]) / (2.0 * big)
            part[:, 2] = (sub[:, 1, 0] - sub[:, 0, 1]) / (2.0 * big)
        else:
            i, j, n = k, (k + 1) % 3, (k + 2) % 3
            part[:, j] = (sub[:, j, i] + sub[:, i, j]) / (2.0 * big)
            part[:, n] = (sub[:, n, i] + sub[:, i, n]) / (2.0 * big)
            part[:, 3] = (sub[:, n, j] - sub[:, j, n]) / (2.0 * big)
        out[chosen] = part
    return out / vector_norm(out, keepdims=True)


def _euler_from_quat(q: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Tait-Bryan angles in degrees for ``R = R_i(a) R_j(b) R_k(c)``, order ``"ijk"``, of unit quaternions.

    With ``R`` the quaternion's matrix: ``b = asin(s R[i, k])``, ``a = atan2(-s R[j, k], R[k, k])``,
    ``c = atan2(-s R[i, j], R[i, i])`` with ``s`` the parity of the axis permutation; ``b`` is taken
    by atan2 too, which keeps its digits near 90 degrees. At gimbal lock ``a`` and ``c`` are
    arbitrary: callers settle them. Only the five entries of ``R`` read are made, each by
    `_matrix_entry`, as `quat_to_matrix` makes them (the same bits as from the whole matrix, 40 % less work).
    """
    q = np.asarray(q)
    i, j, k, sign = _axes(order)
    if _kernels is not None and q.dtype == np.float64 and q.size:  # the entries in one compiled pass, the same bits
        q = np.ascontiguousarray(q)
        entries = np.empty((6,) + q.shape[:-1])
        _kernels.euler_entries(q, entries, q.size // 4, i, j, k, int(sign))
        s_ik, ii, ij, s_jk, kk, s_ij = entries
    else:
        parts = _parts(q)
        ii, ij = _matrix_entry(parts, i, i), _matrix_entry(parts, i, j)
        s_ik, s_jk, kk = sign * _matrix_entry(parts, i, k), -sign * _matrix_entry(parts, j, k), _matrix_entry(parts, k, k)
        s_ij = -sign * ij
    out = np.empty(q.shape[:-1] + (3,))
    np.degrees(np.arctan2(s_jk, kk), out=out[..., 0])
    np.degrees(np.arctan2(s_ik, np.hypot(ii, ij)), out=out[..., 1])
    np.degrees(np.arctan2(s_ij, ii), out=out[..., 2])
    return out


def quat_to_euler(
    q: np.ndarray, order: str, reference: np.ndarray | None = None
) -> np.ndarray:
    """Intrinsic Euler angles in degrees, choosing among equivalent solutions.

    A rotation has two Tait-Bryan solutions, ``(a, b, c)`` and
    ``(a + 180, 180 - b, c + 180)``, each defined up to whole turns. With a
    ``reference (..., 3)`` the solution and turns nearest to it are taken, so
    a clip written back keeps the angles it was read with. Without one the
    angles are made continuous along axis 0 (time), which is what animators
    expect of channel curves.

    q : (F, ..., 4) float64 unit quaternions
    """
    q = np.asarray(q, dtype=np.float64)
    if q.ndim < 2:  # one rotation, no time axis: a clip of one frame
        return quat_to_euler(q[None], order, None if reference is None else np.asarray(reference)[None])[0]
    if q.size == 0:
        return np.zeros(q.shape[:-1] + (3,))
    return next(euler_blocks(q, order, reference, block=len(q)))


def euler_blocks(q: np.ndarray, order: str, reference: np.ndarray | None = None, block: int = 1024,
                 columns: np.ndarray | None = None, *, compiled: bool = True):
    """`quat_to_euler` of ``q (F, ..., 4)`` as consecutive blocks of ``block`` frames, each ``(n, ..., 3)``.

    The same numbers as on the whole clip at once, bit for bit: what one frame's
    choice depends on is carried from block to block (the previous frame's
    solution, the parity of the flips so far, the whole turns added so far, the
    last angle that was not at gimbal lock; for a joint locked from the first
    frame, the first angle after that is not, looked for once). A writer converts
    a long clip with only a block of angles in memory. (Against the whole-clip
    conversion before blocks, an angle of exactly zero may keep a minus sign the
    old unwrapping took off; no writer shows it.)

    reference : broadcastable to ``q``'s own angles ``(F, ..., 3)``, every joint's even
        with ``columns`` (each block takes the columns' share)
    columns : for ``q (F, J, 4)``, the joints to convert (default all), taken from
        each block as it comes (no copy of the clip's rotations)
    compiled : without a reference, the choice of solution and whole turns made frame after frame
        by ``core/_kernels.c`` where it was built (the same bits: +, -, *, / and NumPy's rounding)
    """
    q = np.asarray(q, dtype=np.float64)
    frames = q.shape[0]
    order = order.upper()
    flat = q.reshape(frames, -1, 4)
    if reference is not None:
        reference = np.broadcast_to(np.asarray(reference, dtype=np.float64), q.shape[:-1] + (3,)).reshape(frames, -1, 3)
    if columns is None:
        lead, pick = q.shape[:-1], slice(None)
    else:
        if q.ndim != 3:
            raise ValueError(f"columns need quaternions (F, J, 4), got {q.shape}")
        pick = np.asarray(columns, dtype=np.int64)
        lead = (frames, len(pick))
        if np.array_equal(pick, np.arange(flat.shape[1])):
            pick = slice(None)  # every joint in order: each block a view, not a copy
    width = int(np.prod(lead[1:], dtype=np.int64))  # the M of the (n, M, 3) blocks
    source_columns = np.arange(flat.shape[1])[pick]
    previous = None  # the previous frame's first solution, (M, 3)
    parity = np.zeros(width, dtype=np.int64)  # flips so far
    turns_so_far = np.zeros((width, 3))  # whole turns taken away so far
    last_chosen = None  # the previous frame's pick before whole turns, (M, 3)
    last_third = np.full(width, np.nan)  # the third angle of the last frame not at gimbal lock
    ahead = _LookAhead(flat, order, source_columns, block)
    kernel = compiled and _kernels is not None and reference is None and width > 0
    if kernel:  # what the blocks carry, as the kernel keeps it (previous, parity, turns_so_far, last_chosen)
        carried = (np.zeros((width, 3)), parity, turns_so_far, np.zeros((width, 3)))
    for start in range(0, frames, block):
        part = slice(start, min(start + block, frames))
        qs = flat[part][:, pick]
        first = np.empty(qs.shape[:-1] + (3,))
        for sub in range(0, len(qs), 1024):  # 1,024 frames at a time: small temporaries on a whole clip
            first[sub : sub + 1024] = _euler_from_quat(qs[sub : sub + 1024], order)
        locked = np.abs(np.abs(first[..., 1]) - 90.0) < 1e-6
        if np.any(locked):
            # At gimbal lock only a combination of the outer angles is fixed. Take
            # the third angle from the reference, else from the previous unlocked
            # frame (else the next one), and solve the first angle for it.
            if reference is not None:
                third = reference[part][:, pick, 2]
            else:
                third = _fill_from_unlocked(first[..., 2], locked, last_third,
                                            lambda wanted, stop=part.stop: ahead.third(wanted, stop))
            first = np.where(locked[..., None], _solve_first_angle(qs, first[..., 1], third, order), first)
        if reference is None:
            unlocked = np.flatnonzero(~locked.all(axis=0))
            if len(unlocked):
                at = len(locked) - 1 - np.argmax(~locked[::-1, unlocked], axis=0)
                last_third[unlocked] = first[at, unlocked, 2]
        if kernel:
            first = np.ascontiguousarray(first).reshape(len(qs), width, 3)
            _kernels.euler_continuity(first, *carried, len(qs), width, start > 0)
            yield first.reshape(qs.shape[:1] + lead[1:] + (3,))
            continue
        second = first + np.array([180.0, 0.0, 180.0])
        second[..., 1] = 180.0 - first[..., 1]
        if reference is not None:
            ref = reference[part][:, pick]
            a = _wrap_near(first, ref)
            b = _wrap_near(second, ref)
            pick_b = np.sum(np.abs(b - ref), axis=-1) < np.sum(np.abs(a - ref), axis=-1)
            chosen = np.where(pick_b[..., None], b, a)
            # Where the reference itself describes this rotation, keep it exactly:
            # conversion near gimbal lock loses digits the reference still has.
            same = quat_angle(quat_from_euler(ref, order), qs) < 1e-9
            yield np.where(same[..., None], ref, chosen).reshape(qs.shape[:1] + lead[1:] + (3,))
            continue
        # Flip to the other solution where it is nearer the previous frame's pick.
        # The two solutions map onto each other by an involution that keeps
        # distances, so whether frame t flips does not depend on earlier picks:
        # the parity of the flips so far says which solution each frame uses.
        before = first[:-1] if previous is None else np.concatenate([previous[None], first[:-1]])
        now, other = (first[1:], second[1:]) if previous is None else (first, second)
        near_same = sum_last(np.abs(_wrap_near(now, before) - before))
        near_other = sum_last(np.abs(_wrap_near(other, before) - before))
        flips = np.cumsum(near_other < near_same, axis=0) + parity
        if previous is None:
            flips = np.concatenate([parity[None], flips])
        chosen = np.where((flips % 2 == 1)[..., None], second, first)
        previous, parity = first[-1].copy(), flips[-1].copy()
        # Whole turns: no step between neighbours over half a turn (np.unwrap with
        # period 360, a quarter of its time).
        step = np.diff(chosen, axis=0) if last_chosen is None else np.diff(chosen, axis=0, prepend=last_chosen[None])
        rounds = np.round(step / 360.0)
        last_chosen = chosen[-1].copy()
        if rounds.any():  # (chosen is np.where's own array: changed in place)
            turns = np.cumsum(rounds, axis=0) + turns_so_far
            turns_so_far = turns[-1].copy()
            chosen[len(chosen) - len(turns):] -= 360.0 * turns
        elif turns_so_far.any():  # no new turn in this block (never the first: it has none before it)
            chosen -= 360.0 * turns_so_far
        yield chosen.reshape(qs.shape[:1] + lead[1:] + (3,))


def sum_last(values: np.ndarray, *, keepdims: bool = False) -> np.ndarray:
    """``np.sum(values, axis=-1, keepdims=keepdims)``, the same bits: over a last axis of fewer than eight
    NumPy adds the values one after the other to 0.0, as this does by element-wise passes (a reduction over
    three or four is mostly overhead: half its time). Longer axes go to NumPy."""
    values = np.asarray(values)
    if values.ndim == 0 or not 1 < values.shape[-1] < 8 or values.dtype != np.float64:
        return np.sum(values, axis=-1, keepdims=keepdims)
    total = values[..., 0] + values[..., 1]
    for i in range(2, values.shape[-1]):
        total += values[..., i]
    total += 0.0  # (NumPy starts from +0.0: a sum of only -0.0 is +0.0; every other sum is as it was)
    return total[..., None] if keepdims else total


def _fill_from_unlocked(values: np.ndarray, locked: np.ndarray, before: np.ndarray, after) -> np.ndarray:
    """Replace locked entries along axis 0 by the last unlocked one before (else after, else 0).

    values, locked : (n, M), a block of frames; before : (M,) the last unlocked value
    of the frames before the block (NaN where none); after : called with the columns
    that need it, the first unlocked value after the block for each (0 where none).
    """
    frames = values.shape[0]
    index = np.where(~locked, np.arange(frames)[:, None], -1)
    last = np.maximum.accumulate(index, axis=0)
    nxt = np.flip(np.minimum.accumulate(np.flip(np.where(index < 0, frames, index), 0), axis=0), 0)
    filled = np.take_along_axis(values, np.clip(np.where(last >= 0, last, nxt), 0, frames - 1), axis=0)
    known = ~np.isnan(before)
    filled = np.where((last < 0) & known, before, filled)
    missing = (last < 0) & ~known & (nxt >= frames)
    if missing.any():
        wanted = np.flatnonzero(missing.any(axis=0))
        later = np.zeros(values.shape[1])
        later[wanted] = after(wanted)
        filled = np.where(missing, later, filled)
    return filled


class _LookAhead:
    """For `euler_blocks`: the third Euler angle of each column's first frame from a given one on that
    is not at gimbal lock (0 where none). Each column's is looked for once and kept until the blocks
    pass it: a joint locked for a whole clip costs one pass over it, not one per block."""

    def __init__(self, q: np.ndarray, order: str, columns: np.ndarray, block: int) -> None:
        self.q, self.order, self.columns, self.block = q, order, columns, block
        self.at = np.full(len(columns), -1, dtype=np.int64)  # where the found frame is (len(q): none)
        self.value = np.zeros(len(columns))

    def third(self, wanted: np.ndarray, start: int) -> np.ndarray:
        stale = wanted[self.at[wanted] < start]
        waiting = np.ones(len(stale), dtype=bool)
        self.at[stale], self.value[stale] = len(self.q), 0.0
        for begin in range(start, len(self.q), self.block):
            if not waiting.any():
                break
            angles = _euler_from_quat(self.q[begin : begin + self.block, self.columns[stale[waiting]]], self.order)
            free = np.abs(np.abs(angles[..., 1]) - 90.0) >= 1e-6
            hit = free.any(axis=0)
            row = np.argmax(free, axis=0)
            got = stale[waiting][hit]
            self.at[got] = begin + row[hit]
            self.value[got] = angles[row[hit], np.flatnonzero(hit), 2]
            waiting[np.flatnonzero(waiting)[hit]] = False
        return self.value[wanted]


def _solve_first_angle(q: np.ndarray, second: np.ndarray, third: np.ndarray, order: str) -> np.ndarray:
    """Euler triples ``(a, second, third)`` with ``a`` chosen so the triple gives ``q``."""
    order = order.upper()
    rest = quat_mul(
        quat_from_axis_angle(order[1], np.deg2rad(second)), quat_from_axis_angle(order[2], np.deg2rad(third))
    )
    first_q = quat_mul(q, quat_inv(rest))
    axis = "XYZ".index(order[0])
    a = np.degrees(2.0 * np.arctan2(first_q[..., axis], first_q[..., 3]))
    a = (a + 180.0) % 360.0 - 180.0
    return np.stack([a, second, third], axis=-1)


def _wrap_near(angles: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Add whole turns to ``angles`` to bring each nearest to ``reference``."""
    return angles + 360.0 * np.round((reference - angles) / 360.0)


def unit_track(q: np.ndarray, joint: int | None = None, *, compiled: bool = True) -> np.ndarray:
    """A track of quaternions ``(F, 4)`` as an animation keys it: `quat_unroll` along time (no sign flip
    between neighbours: a player interpolating them takes the short way) and each of unit length; one
    pass of ``core/_kernels.c`` where it was built, NumPy's bits. With ``joint``: that joint's track of
    ``q (F, J, 4)`` (read where it lies, not copied out first)."""
    q = np.asarray(q, dtype=np.float64)
    if joint is None:
        q = q[:, None]
        joint = 0
    if q.ndim != 3 or q.shape[2] != 4 or not 0 <= joint < q.shape[1]:
        raise ValueError(f"unit_track: a track (F, 4), or joint {joint} of (F, J, 4) rotations; got {q.shape}")
    if compiled and getattr(_kernels, "unit_track", None) is not None:
        out = np.empty((len(q), 4))
        _kernels.unit_track(np.ascontiguousarray(q), out, len(q), q.shape[1], int(joint))
        return out
    q = quat_unroll(q[:, joint], axis=0)
    return q / vector_norm(q, keepdims=True)


def quat_unroll(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip quaternion signs so neighbours along ``axis`` lie in one hemisphere."""
    q = np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.concatenate([np.zeros((1,) + dots.shape[1:], bool), np.cumsum(dots < 0, axis=0) % 2 == 1])
    q = np.where(flips[..., None], -q, q)
    return np.moveaxis(q, 0, axis)
