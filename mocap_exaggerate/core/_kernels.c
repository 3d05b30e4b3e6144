/* Loops NumPy runs as many small passes, each here one pass over memory: forward kinematics (joint by
 * joint, as NumPy's), world-to-local, the rotation-minimising frames carried along each cut link and the
 * twist spread along it (stages/orient.py), the read's Euler angles to quaternions, the BVH writer's
 * choice of Euler solution and whole turns (core/rotations.py), and the springs' time loop.
 *
 * Every number is computed with the operations NumPy's code uses, in the same order (core/rotations.py:
 * quat_mul, quat_rotate, quat_between, quat_normalize, _norm): +, -, *, /, sqrt and rint, each rounded
 * once (built without fused multiply-add or vectorising: setup.py), so the results are NumPy's bit for
 * bit (a NaN's sign bit aside, which no output carries: the BVH writer refuses NaN) and an install
 * without a C compiler, which runs the NumPy code, writes the same bytes. The tests compare both.
 * Sine and cosine are the C library's (NumPy's where it has no vector loop of its own, as here).
 *
 * local_from_world(parents, world_rot, world_pos, local_rot, local_pos)
 *     parents (J,) int64 with parents[0] = -1 and parents[j] < j; world_rot (F, J, 4), world_pos (F, J, 3);
 *     local_rot (F, J, 4) may be world_rot itself (each frame's joints are done last to first, so a
 *     parent is read before it is written); local_pos (F, J, 3). All C-contiguous float64.
 * forward_kinematics(parents, rot, pos)
 *     rot (J, F, 4) and pos (J, F, 3): the local transforms, joint-major (a joint's frames contiguous, as
 *     core/kinematics.py lays them out), turned into world ones in place.
 * chain_frames(out, positions, heads, starts, cuts, direction)
 *     out (F, J, 4) float64, read at the heads and written at starts[l] + k for k < cuts[l];
 *     positions (F, J, 3); heads, starts, cuts (L,) int64; direction (L, 3) float64.
 * twist_frames(out, angle, starts, cuts, direction)
 *     out (F, J, 4) float64, each sub-joint starts[l] + k (0 < k < cuts[l]) turned about its link's rest
 *     direction by angle[f, l] k / cuts[l] (curve_frames' second pass); angle (F, L) float64.
 * quat_from_euler(euler, out, codes)
 *     euler (F, J, 3) degrees, out (F, J, 4); codes (J, 4) int64: the axes i, j, k of the joint's
 *     intrinsic order and its parity (+1 or -1), or i = -1 for a joint left as it is.
 * euler_continuity(first, previous, parity, turns, last, frames, width, started)
 *     euler_blocks' choice between each frame's two Euler solutions and its whole turns, for a block of
 *     frames: first (n, M, 3) float64 the first solutions, overwritten by the angles chosen; previous,
 *     turns and last (M, 3) float64 and parity (M,) int64 what the blocks before carried (read when
 *     started is 1), updated for the next. Only +, -, *, / and rint (NumPy's round), so NumPy's bits.
 * chain_add(pos, parents, links, frames, joints)
 *     pos (F, J, 3) float64 rebuilt in place down the hierarchy from links (F, J-1, 3): each joint its parent's
 *     position plus its link (correct._rebuild; one add each, NumPy's bits).
 * euler_entries(q, out, count, i, j, k, sign)
 *     the five entries of the rotation matrices of count unit quaternions q (count, 4) float64 that
 *     rotations._euler_from_quat reads, made as _matrix_entry makes them, into out (6, count): sign R[i, k],
 *     R[i, i], R[i, j], -sign R[j, k], R[k, k], -sign R[i, j] (sign +1 or -1: exact).
 * single_turns(was, now, turned, out, start, end, joint, frames, joints, count)
 *     orientation recovery's joints turned by a single link (stages/orient.py): for each k < count, out[f,
 *     joint[k]] = quat_normalize(quat_mul(quat_between(was[f, end[k]] - was[f, start[k]], now[f, end[k]] -
 *     now[f, start[k]]), turned[f, joint[k]])); was and now (F, J, 3), turned and out (F, J, 4) float64,
 *     start, end and joint (count,) int64 joints (joint without repeats, out not turned: as NumPy's expression,
 *     which reads every turned orientation before it writes one).
 * rigid_branches(world, positions, local_rot, local_pos, joints, parents, frames, count, placed)
 *     orientation recovery's rigid branches (stages/orient.py): for each listed joint j, in order, world[f, j] =
 *     quat_mul(world[f, p], local_rot[f, j]) and positions[f, j] = positions[f, p] + quat_rotate(world[f, p],
 *     local_pos[f, j]) with p = parents[k], the joint's parent (before it in the list or not rigid);
 *     world and local_rot (F, J, 4), positions and local_pos (F, J, 3) float64, joints and parents (placed,)
 *     int64 with parents[k] < joints[k].
 * unit_track(q, out, frames, joints, joint)
 *     joint's track of quaternions q (F, joints, 4) float64, into out (F, 4), as the GLB writes it: rotations.quat_unroll (each dot product summed
 *     left to right, as np.sum sums four) and divided by vector_norm's length; NumPy's bits.
 * springs(follow, out, link_a, link_b, frames, particles, links, frame_time, substeps, stiffness, link_stiffness,
 *         damping)
 *     the suspended particles' time loop (stages/springs.py, `_integrate_vectorised`): follow and out
 *     (F, P, 3) float64, link_a and link_b (L,) int64 particle indices. The NumPy loop's operations in its
 *     order (each end's link pulls summed as np.bincount sums them), so its bits: near the stiffness the
 *     step can only just carry and with no drag the follow-through is chaotic, and any other order of
 *     sums would part from it by centimetres within a few seconds.
 *
 * twist_frames and quat_from_euler call the C library's sin and cos, as NumPy does for float64 where it has no vector loop
 * of its own (on this machine: tests/test_rubber_frames.py and tests/test_bvh.py compare the two, bit
 * for bit where NumPy's sine is the C library's, else to the last bit).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#ifndef M_PI /* (MSVC defines it only when asked) */
#define M_PI 3.14159265358979323846
#endif

/* ------------------------------------------------------------------ NumPy's arithmetic, one at a time */

static inline void quat_mul(const double *a, const double *b, double *out) {
    const double ax = a[0], ay = a[1], az = a[2], aw = a[3];
    const double bx = b[0], by = b[1], bz = b[2], bw = b[3];
    out[0] = aw * bx + ax * bw + ay * bz - az * by;
    out[1] = aw * by - ax * bz + ay * bw + az * bx;
    out[2] = aw * bz + ax * by - ay * bx + az * bw;
    out[3] = aw * bw - ax * bx - ay * by - az * bz;
}

static inline void cross(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* v + w t + u x t with t = 2 (u x v) */
static inline void quat_rotate(const double *q, const double *v, double *out) {
    double c[3], t[3], d[3];
    cross(q, v, c);
    t[0] = 2.0 * c[0];
    t[1] = 2.0 * c[1];
    t[2] = 2.0 * c[2];
    cross(q, t, d);
    out[0] = v[0] + q[3] * t[0] + d[0];
    out[1] = v[1] + q[3] * t[1] + d[1];
    out[2] = v[2] + q[3] * t[2] + d[2];
}

static inline double norm3(const double *v) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

static inline double norm4(const double *v) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]); }

/* The smallest turn carrying u onto v (quat_between): identity where either is zero, a half turn about
 * an axis perpendicular to u where they are opposite. */
static inline void quat_between(const double *u, const double *v, double *out) {
    const double nu = norm3(u), nv = norm3(v);
    const double both = nu * nv;
    double q[4];
    cross(u, v, q);
    q[3] = both + (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]);
    double norm = norm4(q);
    const double tiny = 1e-12 * (both > 1e-300 ? both : 1e-300);
    if (norm <= tiny && both > 0) {
        const double ax = fabs(u[0]), ay = fabs(u[1]), az = fabs(u[2]);
        int least = 0; /* np.argmin: the first of equal smallest */
        if (ay < ax) least = 1;
        if (az < (least == 0 ? ax : ay)) least = 2;
        double helper[3] = {0.0, 0.0, 0.0};
        helper[least] = 1.0;
        double perpendicular[3];
        cross(u, helper, perpendicular);
        double size = norm3(perpendicular);
        if (!(size >= 1e-300)) size = 1e-300; /* np.maximum(size, 1e-300) */
        q[0] = perpendicular[0] / size;
        q[1] = perpendicular[1] / size;
        q[2] = perpendicular[2] / size;
        q[3] = 0.0;
        norm = 1.0;
    }
    if (both <= 1e-300 || norm <= 0) {
        out[0] = out[1] = out[2] = 0.0;
        out[3] = 1.0;
        return;
    }
    out[0] = q[0] / norm;
    out[1] = q[1] / norm;
    out[2] = q[2] / norm;
    out[3] = q[3] / norm;
}

/* ------------------------------------------------------------------ buffers */

/* A C-contiguous buffer of `count` items of `format` ("d" or "q"); writable when asked. */
static int get_array(PyObject *object, Py_buffer *view, const char *format, Py_ssize_t count, int writable,
                     const char *name) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(object, view, flags) < 0) return -1;
    const Py_ssize_t size = format[0] == 'd' ? (Py_ssize_t)sizeof(double) : (Py_ssize_t)sizeof(int64_t);
    int same = view->format != NULL && (strcmp(view->format, format) == 0 ||
                                         (format[0] == 'q' && strcmp(view->format, "l") == 0 && sizeof(long) == 8));
    /* count * size must not wrap (Python builds with -fwrapv): a count past what memory holds is refused */
    if (!same || view->itemsize != size || count < 0 || count > PY_SSIZE_T_MAX / size || view->len != count * size) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "%s: a C-contiguous buffer of %zd %s", name, count,
                     format[0] == 'd' ? "float64" : "int64");
        return -1;
    }
    return 0;
}

/* The arrays of a call, in order (`writable[k]` 'w' for an output), each checked by get_array; how many were
 * got (all of them, or fewer with the error set). */
static int get_arrays(PyObject **objects, Py_buffer *views, const char *formats, const char *writable,
                      const Py_ssize_t *counts, const char **names, int n) {
    char format[2] = {0, 0};
    for (int k = 0; k < n; k++) {
        format[0] = formats[k];
        if (get_array(objects[k], &views[k], format, counts[k], writable[k] == 'w', names[k]) < 0) return k;
    }
    return n;
}

/* The end of a call: every array got let go; None, or NULL with the error set when it went bad. */
static PyObject *finish(Py_buffer *views, int got, int bad) {
    for (int k = 0; k < got; k++) PyBuffer_Release(&views[k]);
    if (bad) return NULL;
    Py_RETURN_NONE;
}

/* Frame and joint counts whose products with a transform's width cannot wrap; else a ValueError. */
static int counts_fit(Py_ssize_t frames, Py_ssize_t joints, const char *name) {
    if (frames < 0 || joints < 1 || joints > PY_SSIZE_T_MAX / 64 || frames > PY_SSIZE_T_MAX / 64 / joints) {
        PyErr_Format(PyExc_ValueError, "%s: bad frame or joint count", name);
        return 0;
    }
    return 1;
}

/* parents[0] = -1 and every other parent before its child; else a ValueError. */
static int parents_in_order(const int64_t *parents, Py_ssize_t joints, const char *name) {
    int bad = parents[0] != -1;
    for (Py_ssize_t j = 1; j < joints && !bad; j++) bad = parents[j] < 0 || parents[j] >= j;
    if (bad) PyErr_Format(PyExc_ValueError, "%s: parents must start at -1, each before its child", name);
    return !bad;
}

/* A private copy of n int64 items of a buffer got by get_array (the index arrays a loop reads with the GIL let
 * go are checked and read from it: another thread changing the caller's array cannot send the loop out of
 * bounds); NULL with MemoryError set. PyMem_Free it. */
static int64_t *items_copy(const Py_buffer *view, Py_ssize_t n) {
    int64_t *copy = PyMem_Malloc((size_t)(n > 0 ? n : 1) * sizeof(int64_t));
    if (copy == NULL) {
        PyErr_NoMemory();
        return NULL;
    }
    if (n > 0) memcpy(copy, view->buf, (size_t)n * sizeof(int64_t));
    return copy;
}

/* A copy of the caller's parents (joints >= 1), checked by parents_in_order; NULL with the error set. The loops
 * read the copy with the GIL let go: another thread changing the caller's array then cannot send them out of
 * bounds. PyMem_Free it. */
static int64_t *parents_copy(const Py_buffer *view, Py_ssize_t joints, const char *name) {
    int64_t *copy = items_copy(view, joints);
    if (copy == NULL) return NULL;
    if (!parents_in_order(copy, joints, name)) {
        PyMem_Free(copy);
        return NULL;
    }
    return copy;
}

static PyObject *local_from_world(PyObject *self, PyObject *args) {
    PyObject *objects[5];
    Py_ssize_t frames, joints;
    if (!PyArg_ParseTuple(args, "OOOOOnn", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4], &frames,
                          &joints))
        return NULL;
    if (!counts_fit(frames, joints, "local_from_world")) return NULL;
    Py_buffer views[5];
    const Py_ssize_t counts[5] = {joints, frames * joints * 4, frames * joints * 3, frames * joints * 4,
                                  frames * joints * 3};
    const char *names[5] = {"parents", "world_rot", "world_pos", "local_rot", "local_pos"};
    int got = get_arrays(objects, views, "qdddd", "rrrww", counts, names, 5);
    int bad = got < 5;
    int64_t *parents = bad ? NULL : parents_copy(&views[0], joints, "local_from_world");
    if (!bad) bad = parents == NULL;
    if (!bad) {
        const double *world_rot = (const double *)views[1].buf;
        const double *world_pos = (const double *)views[2].buf;
        double *local_rot = (double *)views[3].buf;
        double *local_pos = (double *)views[4].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            const double *rot = world_rot + f * joints * 4;
            const double *pos = world_pos + f * joints * 3;
            double *lrot = local_rot + f * joints * 4;
            double *lpos = local_pos + f * joints * 3;
            for (Py_ssize_t j = joints - 1; j >= 1; j--) { /* last to first: a parent is read before written */
                const double *parent = rot + parents[j] * 4;
                const double inverse[4] = {parent[0] * -1.0, parent[1] * -1.0, parent[2] * -1.0, parent[3] * 1.0};
                const double *pp = pos + parents[j] * 3, *pj = pos + j * 3;
                const double offset[3] = {pj[0] - pp[0], pj[1] - pp[1], pj[2] - pp[2]};
                double turned[4];
                quat_mul(inverse, rot + j * 4, turned);
                quat_rotate(inverse, offset, lpos + j * 3);
                memcpy(lrot + j * 4, turned, sizeof(turned));
            }
            if (lrot != rot) memcpy(lrot, rot, 4 * sizeof(double));
            memcpy(lpos, pos, 3 * sizeof(double));
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(parents);
    return finish(views, got, bad);
}

static PyObject *forward_kinematics(PyObject *self, PyObject *args) {
    PyObject *objects[3];
    Py_ssize_t frames, joints;
    if (!PyArg_ParseTuple(args, "OOOnn", &objects[0], &objects[1], &objects[2], &frames, &joints)) return NULL;
    if (!counts_fit(frames, joints, "forward_kinematics")) return NULL;
    Py_buffer views[3];
    const Py_ssize_t counts[3] = {joints, joints * frames * 4, joints * frames * 3};
    const char *names[3] = {"parents", "rot", "pos"};
    int got = get_arrays(objects, views, "qdd", "rww", counts, names, 3);
    int bad = got < 3;
    int64_t *parents = bad ? NULL : parents_copy(&views[0], joints, "forward_kinematics");
    if (!bad) bad = parents == NULL;
    if (!bad) {
        double *rot = (double *)views[1].buf;
        double *pos = (double *)views[2].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t j = 1; j < joints; j++) { /* joint by joint, as NumPy's: a parent is done before its children */
            const double *parent_rot = rot + parents[j] * frames * 4, *parent_pos = pos + parents[j] * frames * 3;
            double *joint_rot = rot + j * frames * 4, *joint_pos = pos + j * frames * 3;
            for (Py_ssize_t f = 0; f < frames; f++) {
                double turned[3], product[4];
                quat_rotate(parent_rot + f * 4, joint_pos + f * 3, turned);
                joint_pos[f * 3] = parent_pos[f * 3] + turned[0];
                joint_pos[f * 3 + 1] = parent_pos[f * 3 + 1] + turned[1];
                joint_pos[f * 3 + 2] = parent_pos[f * 3 + 2] + turned[2];
                quat_mul(parent_rot + f * 4, joint_rot + f * 4, product);
                memcpy(joint_rot + f * 4, product, sizeof(product));
            }
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(parents);
    return finish(views, got, bad);
}

static PyObject *chain_frames(PyObject *self, PyObject *args) {
    PyObject *objects[6];
    Py_ssize_t frames, joints, links;
    if (!PyArg_ParseTuple(args, "OOOOOOnnn", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4],
                          &objects[5], &frames, &joints, &links))
        return NULL;
    if (frames < 0 || joints < 1 || links < 0 || joints > PY_SSIZE_T_MAX / 64 || links > PY_SSIZE_T_MAX / 64 ||
        frames > PY_SSIZE_T_MAX / 64 / joints) {
        PyErr_SetString(PyExc_ValueError, "chain_frames: bad frame, joint or link count");
        return NULL;
    }
    Py_buffer views[6];
    const Py_ssize_t counts[6] = {frames * joints * 4, frames * joints * 3, links, links, links, links * 3};
    const char *names[6] = {"out", "positions", "heads", "starts", "cuts", "direction"};
    int got = get_arrays(objects, views, "ddqqqd", "wrrrrr", counts, names, 6);
    int bad = got < 6;
    int64_t *heads = NULL, *starts = NULL, *cuts = NULL;
    if (!bad) {
        heads = items_copy(&views[2], links);
        starts = heads == NULL ? NULL : items_copy(&views[3], links);
        cuts = starts == NULL ? NULL : items_copy(&views[4], links);
        bad = cuts == NULL;
    }
    if (!bad) {
        for (Py_ssize_t l = 0; l < links && !bad; l++) /* every joint read or written inside the arrays */
            bad = heads[l] < 0 || heads[l] >= joints || starts[l] < 0 || starts[l] >= joints || cuts[l] < 0 ||
                  cuts[l] >= joints - starts[l]; /* (written so that no sum wraps) */
        if (bad) PyErr_SetString(PyExc_ValueError, "chain_frames: a link's joints are outside the skeleton");
    }
    if (!bad) {
        double *out = (double *)views[0].buf;
        const double *positions = (const double *)views[1].buf;
        const double *direction = (const double *)views[5].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            double *rot = out + f * joints * 4;
            const double *pos = positions + f * joints * 3;
            for (Py_ssize_t l = 0; l < links; l++) {
                double frame[4];
                memcpy(frame, rot + heads[l] * 4, sizeof(frame));
                for (int64_t k = 0; k < cuts[l]; k++) {
                    const int64_t j = starts[l] + k;
                    const double along[3] = {pos[(j + 1) * 3] - pos[j * 3], pos[(j + 1) * 3 + 1] - pos[j * 3 + 1],
                                             pos[(j + 1) * 3 + 2] - pos[j * 3 + 2]};
                    double pointing[3], turn[4], turned[4];
                    quat_rotate(frame, direction + l * 3, pointing);
                    quat_between(pointing, along, turn);
                    quat_mul(turn, frame, turned);
                    const double size = norm4(turned);
                    for (int i = 0; i < 4; i++) frame[i] = turned[i] / size;
                    memcpy(rot + j * 4, frame, sizeof(frame));
                }
            }
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(heads);
    PyMem_Free(starts);
    PyMem_Free(cuts);
    return finish(views, got, bad);
}

static PyObject *twist_frames(PyObject *self, PyObject *args) {
    PyObject *objects[5];
    Py_ssize_t frames, joints, links;
    if (!PyArg_ParseTuple(args, "OOOOOnnn", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4], &frames,
                          &joints, &links))
        return NULL;
    if (!counts_fit(frames, joints, "twist_frames")) return NULL;
    if (links < 0 || links > PY_SSIZE_T_MAX / 64 || (links && frames > PY_SSIZE_T_MAX / 64 / links)) {
        PyErr_SetString(PyExc_ValueError, "twist_frames: bad link count");
        return NULL;
    }
    Py_buffer views[5];
    const Py_ssize_t counts[5] = {frames * joints * 4, frames * links, links, links, links * 3};
    const char *names[5] = {"out", "angle", "starts", "cuts", "direction"};
    int got = get_arrays(objects, views, "ddqqd", "wrrrr", counts, names, 5);
    int bad = got < 5;
    int64_t *starts = NULL, *cuts = NULL;
    if (!bad) {
        starts = items_copy(&views[2], links);
        cuts = starts == NULL ? NULL : items_copy(&views[3], links);
        bad = cuts == NULL;
    }
    if (!bad) {
        for (Py_ssize_t l = 0; l < links && !bad; l++)
            bad = starts[l] < 0 || starts[l] >= joints || cuts[l] < 1 || cuts[l] > joints - starts[l];
        if (bad) PyErr_SetString(PyExc_ValueError, "twist_frames: a link's joints are outside the skeleton");
    }
    if (!bad) {
        double *out = (double *)views[0].buf;
        const double *angle = (const double *)views[1].buf, *direction = (const double *)views[4].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            double *rot = out + f * joints * 4;
            for (Py_ssize_t l = 0; l < links; l++) {
                const double *axis = direction + l * 3;
                const double turn = 0.5 * angle[f * links + l];
                for (int64_t k = 1; k < cuts[l]; k++) {
                    /* half = 0.5 angle (k / cuts): NumPy's order, each product rounded once */
                    const double half = turn * ((double)k / (double)cuts[l]);
                    const double s = sin(half);
                    const double twist[4] = {axis[0] * s, axis[1] * s, axis[2] * s, cos(half)};
                    double *q = rot + (starts[l] + k) * 4, turned[4];
                    quat_mul(q, twist, turned);
                    const double size = norm4(turned);
                    for (int i = 0; i < 4; i++) q[i] = turned[i] / size;
                }
            }
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(starts);
    PyMem_Free(cuts);
    return finish(views, got, bad);
}

static PyObject *quat_from_euler(PyObject *self, PyObject *args) {
    PyObject *objects[3];
    Py_ssize_t frames, joints;
    if (!PyArg_ParseTuple(args, "OOOnn", &objects[0], &objects[1], &objects[2], &frames, &joints)) return NULL;
    if (!counts_fit(frames, joints, "quat_from_euler")) return NULL;
    Py_buffer views[3];
    const Py_ssize_t counts[3] = {frames * joints * 3, frames * joints * 4, joints * 4};
    const char *names[3] = {"euler", "out", "codes"};
    int got = get_arrays(objects, views, "ddq", "rwr", counts, names, 3);
    int bad = got < 3;
    if (!bad) {
        const int64_t *codes = (const int64_t *)views[2].buf;
        for (Py_ssize_t j = 0; j < joints && !bad; j++) {
            const int64_t *c = codes + j * 4;
            if (c[0] == -1) continue;
            bad = c[0] < 0 || c[0] > 2 || c[1] < 0 || c[1] > 2 || c[2] < 0 || c[2] > 2 || c[0] == c[1] ||
                  c[1] == c[2] || c[0] == c[2] || (c[3] != 1 && c[3] != -1);
        }
        if (bad) PyErr_SetString(PyExc_ValueError, "quat_from_euler: a joint's order is not three different axes");
    }
    if (!bad) {
        const double *euler = (const double *)views[0].buf;
        double *out = (double *)views[1].buf;
        const int64_t *codes = (const int64_t *)views[2].buf;
        const double to_radians = M_PI / 180.0; /* np.deg2rad: x * (pi / 180) */
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            for (Py_ssize_t j = 0; j < joints; j++) {
                const int64_t *code = codes + j * 4;
                if (code[0] == -1) continue;
                const double *e = euler + (f * joints + j) * 3;
                double c[3], s[3];
                for (int a = 0; a < 3; a++) {
                    const double half = 0.5 * (e[a] * to_radians);
                    c[a] = cos(half);
                    s[a] = sin(half);
                }
                const double parity = (double)code[3];
                const double c1c2 = c[0] * c[1], s1s2 = s[0] * s[1], c1s2 = c[0] * s[1], s1c2 = s[0] * c[1];
                double *q = out + (f * joints + j) * 4;
                q[code[0]] = s1c2 * c[2] + parity * c1s2 * s[2];
                q[code[1]] = c1s2 * c[2] - parity * s1c2 * s[2];
                q[code[2]] = c1c2 * s[2] + parity * s1s2 * c[2];
                q[3] = c1c2 * c[2] - parity * s1s2 * s[2];
            }
        }
        Py_END_ALLOW_THREADS
    }
    return finish(views, got, bad);
}

/* np.round(x): half to even, as rint in the default rounding mode */
static inline double wrap_near(double angle, double reference) {
    return angle + 360.0 * rint((reference - angle) / 360.0);
}

static inline double distance3(const double *a, const double *reference) {
    return (fabs(wrap_near(a[0], reference[0]) - reference[0]) + fabs(wrap_near(a[1], reference[1]) - reference[1])) +
           fabs(wrap_near(a[2], reference[2]) - reference[2]);
}

static PyObject *euler_continuity(PyObject *self, PyObject *args) {
    PyObject *objects[5];
    Py_ssize_t frames, width;
    int started;
    if (!PyArg_ParseTuple(args, "OOOOOnnp", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4], &frames,
                          &width, &started))
        return NULL;
    if (!counts_fit(frames, width, "euler_continuity")) return NULL;
    Py_buffer views[5];
    const Py_ssize_t counts[5] = {frames * width * 3, width * 3, width, width * 3, width * 3};
    const char *names[5] = {"first", "previous", "parity", "turns", "last"};
    int got = get_arrays(objects, views, "ddqdd", "wwwww", counts, names, 5);
    int bad = got < 5;
    if (!bad && frames > 0) {
        double *angles = (double *)views[0].buf, *previous = (double *)views[1].buf;
        int64_t *parity = (int64_t *)views[2].buf;
        double *turns = (double *)views[3].buf, *last = (double *)views[4].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t m = 0; m < width; m++) {
            double before[3], chosen_before[3], turn[3];
            int64_t flips = parity[m];
            memcpy(before, previous + m * 3, sizeof(before));
            memcpy(chosen_before, last + m * 3, sizeof(chosen_before));
            memcpy(turn, turns + m * 3, sizeof(turn));
            for (Py_ssize_t t = 0; t < frames; t++) {
                double *angle = angles + (t * width + m) * 3;
                const double first[3] = {angle[0], angle[1], angle[2]};
                const double second[3] = {first[0] + 180.0, 180.0 - first[1], first[2] + 180.0};
                const int opening = t == 0 && !started; /* the clip's first frame: nothing before it */
                /* flip to the other solution where it is nearer the previous frame's first one */
                if (!opening && distance3(second, before) < distance3(first, before)) flips++;
                const double *chosen = flips % 2 == 1 ? second : first;
                for (int c = 0; c < 3; c++) {
                    if (!opening) turn[c] += rint((chosen[c] - chosen_before[c]) / 360.0);
                    chosen_before[c] = chosen[c];
                    before[c] = first[c];
                }
                for (int c = 0; c < 3; c++) angle[c] = chosen_before[c] - 360.0 * turn[c];
            }
            memcpy(previous + m * 3, before, sizeof(before));
            memcpy(last + m * 3, chosen_before, sizeof(chosen_before));
            memcpy(turns + m * 3, turn, sizeof(turn));
            parity[m] = flips;
        }
        Py_END_ALLOW_THREADS
    }
    return finish(views, got, bad);
}

static PyObject *springs(PyObject *self, PyObject *args) {
    PyObject *objects[4];
    Py_ssize_t frames, count, links, substeps;
    double frame_time, stiffness, link_stiffness, damping;
    if (!PyArg_ParseTuple(args, "OOOOnnndnddd", &objects[0], &objects[1], &objects[2], &objects[3], &frames, &count,
                          &links, &frame_time, &substeps, &stiffness, &link_stiffness, &damping))
        return NULL;
    if (!counts_fit(frames, count, "springs")) return NULL;
    if (links < 0 || links > PY_SSIZE_T_MAX / 64 || substeps < 1 || substeps > 1000000 || !(frame_time > 0.0) ||
        !isfinite(frame_time) || !isfinite(stiffness) || !isfinite(link_stiffness) || !isfinite(damping)) {
        PyErr_SetString(PyExc_ValueError, "springs: bad link count, substeps or constants");
        return NULL;
    }
    Py_buffer views[4];
    const Py_ssize_t counts[4] = {frames * count * 3, frames * count * 3, links, links};
    const char *names[4] = {"follow", "out", "link_a", "link_b"};
    int got = get_arrays(objects, views, "ddqq", "rwrr", counts, names, 4);
    int bad = got < 4;
    int64_t *link_a = NULL, *link_b = NULL;
    if (!bad) {
        link_a = items_copy(&views[2], links);
        link_b = link_a == NULL ? NULL : items_copy(&views[3], links);
        bad = link_b == NULL;
    }
    if (!bad) {
        const int64_t *a = link_a, *b = link_b;
        for (Py_ssize_t l = 0; l < links && !bad; l++) bad = a[l] < 0 || a[l] >= count || b[l] < 0 || b[l] >= count;
        if (bad) PyErr_SetString(PyExc_ValueError, "springs: a link's particles are outside the set");
    }
    double *work = NULL;
    if (!bad && frames >= 2) {
        work = (double *)PyMem_RawMalloc(sizeof(double) * (size_t)(count * 15 + links));
        if (work == NULL) {
            PyErr_NoMemory();
            bad = 1;
        }
    }
    if (!bad && frames >= 2) {
        const double *follow = (const double *)views[0].buf;
        double *out = (double *)views[1].buf;
        double *x = work, *v = work + count * 3, *anchor = work + count * 6, *rest = work + count * 15;
        double *pulled_a = work + count * 9, *pulled_b = work + count * 12; /* the link forces on each end */
        const Py_ssize_t n = count * 3;
        Py_BEGIN_ALLOW_THREADS
        const double h = frame_time / (double)substeps;
        const double denominator = 1.0 + h * damping + h * h * stiffness;
        const double strength = h * link_stiffness / denominator, pull = h * stiffness / denominator;
        const double shrink = 1.0 / denominator;
        const double anchor_pull = h * stiffness, drag = h * damping / frame_time;
        memcpy(out, follow, sizeof(double) * (size_t)n);
        memcpy(x, follow, sizeof(double) * (size_t)n);
        for (Py_ssize_t i = 0; i < n; i++) v[i] = (follow[n + i] - follow[i]) / frame_time;
        for (Py_ssize_t f = 0; f + 1 < frames; f++) {
            const double *now = follow + f * n, *next = now + n;
            for (Py_ssize_t k = 1; k <= substeps; k++) {
                const double alpha = (double)k / (double)substeps;
                /* v' = (v + h (k (anchor - x) + c u + F)) / d, x' = x + h v' */
                for (Py_ssize_t i = 0; i < n; i++) {
                    const double step = next[i] - now[i];
                    anchor[i] = now[i] + alpha * step;
                    const double push = (anchor_pull * anchor[i] + drag * step) / denominator;
                    v[i] = v[i] * shrink + push - pull * x[i];
                }
                for (Py_ssize_t l = 0; l < links; l++) {
                    const double *pa = anchor + link_a[l] * 3, *pb = anchor + link_b[l] * 3;
                    const double r[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
                    rest[l] = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
                }
                /* Each end's pulls summed from zero in the links' order, then added to v, as np.bincount sums
                 * them for the NumPy loop: the same bits. */
                memset(pulled_a, 0, sizeof(double) * (size_t)n);
                memset(pulled_b, 0, sizeof(double) * (size_t)n);
                for (Py_ssize_t l = 0; l < links; l++) {
                    const double *xa = x + link_a[l] * 3, *xb = x + link_b[l] * 3;
                    const double e[3] = {xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]};
                    const double length = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
                    /* 1 - rest / length; a collapsed link (length 0) has e = 0 and pulls with nothing */
                    const double scale = 1.0 - rest[l] / (!(length < 1e-300) ? length : 1e-300); /* np.maximum */
                    for (int c = 0; c < 3; c++) {
                        const double pulled = strength * (scale * e[c]);
                        pulled_a[link_a[l] * 3 + c] += pulled;
                        pulled_b[link_b[l] * 3 + c] += pulled;
                    }
                }
                for (Py_ssize_t i = 0; i < n; i++) v[i] = v[i] + pulled_a[i] - pulled_b[i];
                for (Py_ssize_t i = 0; i < n; i++) x[i] = x[i] + h * v[i];
            }
            memcpy(out + (f + 1) * n, x, sizeof(double) * (size_t)n);
        }
        Py_END_ALLOW_THREADS
    } else if (!bad && frames == 1) {
        memcpy(views[1].buf, views[0].buf, sizeof(double) * (size_t)(count * 3));
    }
    PyMem_RawFree(work);
    PyMem_Free(link_a);
    PyMem_Free(link_b);
    return finish(views, got, bad);
}

/* Positions rebuilt down a hierarchy from their links: pos[f, j] = pos[f, parents[j]] + links[f, j - 1] for every
 * joint after the root, parents first (correct._rebuild's loop: one add per number, NumPy's bits). */
static PyObject *chain_add(PyObject *self, PyObject *args) {
    PyObject *objects[3];
    Py_ssize_t frames, joints;
    if (!PyArg_ParseTuple(args, "OOOnn", &objects[0], &objects[1], &objects[2], &frames, &joints)) return NULL;
    if (!counts_fit(frames, joints, "chain_add")) return NULL;
    Py_buffer views[3];
    const Py_ssize_t counts[3] = {frames * joints * 3, joints, frames * (joints - 1) * 3};
    const char *names[3] = {"pos", "parents", "links"};
    int got = get_arrays(objects, views, "dqd", "wrr", counts, names, 3);
    int bad = got < 3;
    int64_t *parents = bad ? NULL : parents_copy(&views[1], joints, "chain_add");
    if (!bad) bad = parents == NULL;
    if (!bad) {
        double *pos = (double *)views[0].buf;
        const double *links = (const double *)views[2].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            double *at = pos + f * joints * 3;
            const double *link = links + f * (joints - 1) * 3;
            for (Py_ssize_t j = 1; j < joints; j++) {
                const double *parent = at + parents[j] * 3;
                at[j * 3] = parent[0] + link[(j - 1) * 3];
                at[j * 3 + 1] = parent[1] + link[(j - 1) * 3 + 1];
                at[j * 3 + 2] = parent[2] + link[(j - 1) * 3 + 2];
            }
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(parents);
    return finish(views, got, bad);
}

/* A track of quaternions (F, 4) as the GLB writes it: each sign flipped so neighbours lie in one hemisphere
 * (rotations.quat_unroll: the parity of the captured neighbours' negative dot products so far, each dot
 * summed left to right as NumPy's np.sum over four), then divided by its length (vector_norm's sums). */
static PyObject *unit_track(PyObject *self, PyObject *args) {
    PyObject *objects[2];
    Py_ssize_t frames, joints, joint;
    if (!PyArg_ParseTuple(args, "OOnnn", &objects[0], &objects[1], &frames, &joints, &joint)) return NULL;
    if (!counts_fit(frames, joints, "unit_track")) return NULL;
    if (joint < 0 || joint >= joints) {
        PyErr_SetString(PyExc_ValueError, "unit_track: the joint is not one of the joints");
        return NULL;
    }
    Py_buffer views[2];
    const Py_ssize_t counts[2] = {frames * joints * 4, frames * 4};
    const char *names[2] = {"q", "out"};
    int got = get_arrays(objects, views, "dd", "rw", counts, names, 2);
    int bad = got < 2;
    if (!bad) {
        const double *q = (const double *)views[0].buf + joint * 4;
        double *out = (double *)views[1].buf;
        Py_BEGIN_ALLOW_THREADS
        int flipped = 0;
        for (Py_ssize_t f = 0; f < frames; f++) {
            const double *now = q + f * joints * 4;
            if (f > 0) {
                const double *before = now - joints * 4;
                const double dot = ((now[0] * before[0] + now[1] * before[1]) + now[2] * before[2]) + now[3] * before[3];
                if (dot < 0) flipped = !flipped;
            }
            double turned[4];
            for (int k = 0; k < 4; k++) turned[k] = flipped ? -now[k] : now[k];
            const double length = sqrt(((turned[0] * turned[0] + turned[1] * turned[1]) + turned[2] * turned[2]) +
                                       turned[3] * turned[3]);
            for (int k = 0; k < 4; k++) out[f * 4 + k] = turned[k] / length;
        }
        Py_END_ALLOW_THREADS
    }
    return finish(views, got, bad);
}

/* Entry (row, col) of the rotation matrix of the unit quaternion p (x, y, z, w), as rotations._matrix_entry
 * makes it: 1 - 2 (a a + b b) on the diagonal (a, b the other two axes in order), 2 (p q -+ r w) off it. */
static double matrix_entry(const double *p, int row, int col) {
    if (row == col) {
        const int a = row == 0 ? 1 : 0, b = row == 2 ? 1 : 2;
        return 1.0 - 2.0 * (p[a] * p[a] + p[b] * p[b]);
    }
    const int low = row < col ? row : col, high = row < col ? col : row, third = 3 - row - col;
    if (((col - row) % 3 + 3) % 3 == 2) return 2.0 * (p[low] * p[high] + p[third] * p[3]);
    return 2.0 * (p[low] * p[high] - p[third] * p[3]);
}

/* What the Euler angles of intrinsic order (i, j, k) with parity sign are read from (rotations._euler_from_quat). */
static PyObject *euler_entries(PyObject *self, PyObject *args) {
    PyObject *objects[2];
    Py_ssize_t count, i, j, k, sign;
    if (!PyArg_ParseTuple(args, "OOnnnnn", &objects[0], &objects[1], &count, &i, &j, &k, &sign)) return NULL;
    if (count < 0 || count > PY_SSIZE_T_MAX / 64 || i < 0 || i > 2 || j < 0 || j > 2 || k < 0 || k > 2 || i == j ||
        j == k || i == k || (sign != 1 && sign != -1)) {
        PyErr_SetString(PyExc_ValueError, "euler_entries: bad count, axes or sign");
        return NULL;
    }
    Py_buffer views[2];
    const Py_ssize_t counts[2] = {count * 4, count * 6};
    const char *names[2] = {"q", "out"};
    int got = get_arrays(objects, views, "dd", "rw", counts, names, 2);
    int bad = got < 2;
    if (!bad) {
        const double *q = (const double *)views[0].buf;
        double *out = (double *)views[1].buf;
        const double s = (double)sign, minus = (double)(-sign);
        const int I = (int)i, J = (int)j, K = (int)k;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t n = 0; n < count; n++) {
            const double *p = q + n * 4;
            const double ij = matrix_entry(p, I, J);
            out[n] = s * matrix_entry(p, I, K);
            out[count + n] = matrix_entry(p, I, I);
            out[2 * count + n] = ij;
            out[3 * count + n] = minus * matrix_entry(p, J, K);
            out[4 * count + n] = matrix_entry(p, K, K);
            out[5 * count + n] = minus * ij;
        }
        Py_END_ALLOW_THREADS
    }
    return finish(views, got, bad);
}

/* Each joint turned by a single link: its captured orientation turned by the smallest turn carrying the link's
 * captured direction onto its new one, made unit (orient.recover_orientations' fit). */
static PyObject *single_turns(PyObject *self, PyObject *args) {
    PyObject *objects[7];
    Py_ssize_t frames, joints, count;
    if (!PyArg_ParseTuple(args, "OOOOOOOnnn", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4],
                          &objects[5], &objects[6], &frames, &joints, &count))
        return NULL;
    if (!counts_fit(frames, joints, "single_turns")) return NULL;
    if (count < 0 || count > joints) {
        PyErr_SetString(PyExc_ValueError, "single_turns: bad count");
        return NULL;
    }
    Py_buffer views[7];
    const Py_ssize_t counts[7] = {frames * joints * 3, frames * joints * 3, frames * joints * 4, frames * joints * 4,
                                  count, count, count};
    const char *names[7] = {"was", "now", "turned", "out", "start", "end", "joint"};
    int got = get_arrays(objects, views, "ddddqqq", "rrrwrrr", counts, names, 7);
    int bad = got < 7;
    int64_t *index[3] = {NULL, NULL, NULL};
    for (int n = 0; n < 3 && !bad; n++) {
        index[n] = items_copy(&views[4 + n], count);
        bad = index[n] == NULL;
        for (Py_ssize_t k = 0; k < count && !bad; k++) bad = index[n][k] < 0 || index[n][k] >= joints;
        if (bad && index[n] != NULL) PyErr_SetString(PyExc_ValueError, "single_turns: a joint out of range");
    }
    if (!bad) {
        const double *was = (const double *)views[0].buf, *now = (const double *)views[1].buf;
        const double *turned = (const double *)views[2].buf;
        double *out = (double *)views[3].buf;
        const int64_t *start = index[0], *end = index[1], *joint = index[2];
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            const double *w = was + f * joints * 3, *n = now + f * joints * 3, *t = turned + f * joints * 4;
            double *o = out + f * joints * 4;
            for (Py_ssize_t k = 0; k < count; k++) {
                const double *w0 = w + start[k] * 3, *w1 = w + end[k] * 3, *n0 = n + start[k] * 3, *n1 = n + end[k] * 3;
                const double u[3] = {w1[0] - w0[0], w1[1] - w0[1], w1[2] - w0[2]};
                const double v[3] = {n1[0] - n0[0], n1[1] - n0[1], n1[2] - n0[2]};
                double turn[4], q[4];
                quat_between(u, v, turn);
                quat_mul(turn, t + joint[k] * 4, q);
                const double size = norm4(q);
                double *r = o + joint[k] * 4;
                r[0] = q[0] / size;
                r[1] = q[1] / size;
                r[2] = q[2] / size;
                r[3] = q[3] / size;
            }
        }
        Py_END_ALLOW_THREADS
    }
    for (int n = 0; n < 3; n++) PyMem_Free(index[n]);
    return finish(views, got, bad);
}

/* Rigid branches placed under their recovered parents by their captured local transforms, joint after joint
 * in the skeleton's order (orient.recover_orientations). */
static PyObject *rigid_branches(PyObject *self, PyObject *args) {
    PyObject *objects[6];
    Py_ssize_t frames, joints, placed;
    if (!PyArg_ParseTuple(args, "OOOOOOnnn", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4],
                          &objects[5], &frames, &joints, &placed))
        return NULL;
    if (!counts_fit(frames, joints, "rigid_branches")) return NULL;
    if (placed < 0 || placed > joints) {
        PyErr_SetString(PyExc_ValueError, "rigid_branches: bad count");
        return NULL;
    }
    Py_buffer views[6];
    const Py_ssize_t counts[6] = {frames * joints * 4, frames * joints * 3, frames * joints * 4, frames * joints * 3,
                                  placed, placed};
    const char *names[6] = {"world", "positions", "local_rot", "local_pos", "joints", "parents"};
    int got = get_arrays(objects, views, "ddddqq", "wwrrrr", counts, names, 6);
    int bad = got < 6;
    int64_t *joint = bad ? NULL : items_copy(&views[4], placed);
    int64_t *parent = bad || joint == NULL ? NULL : items_copy(&views[5], placed);
    if (!bad) bad = joint == NULL || parent == NULL;
    for (Py_ssize_t k = 0; k < placed && !bad; k++) {
        bad = joint[k] < 1 || joint[k] >= joints || parent[k] < 0 || parent[k] >= joint[k];
        if (bad) PyErr_SetString(PyExc_ValueError, "rigid_branches: a joint out of range or after its parent");
    }
    if (!bad) {
        double *world = (double *)views[0].buf, *positions = (double *)views[1].buf;
        const double *local_rot = (const double *)views[2].buf, *local_pos = (const double *)views[3].buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t f = 0; f < frames; f++) {
            double *rot = world + f * joints * 4, *pos = positions + f * joints * 3;
            const double *lrot = local_rot + f * joints * 4, *lpos = local_pos + f * joints * 3;
            for (Py_ssize_t k = 0; k < placed; k++) {
                const int64_t j = joint[k], p = parent[k];
                double turned[3];
                quat_rotate(rot + p * 4, lpos + j * 3, turned);
                quat_mul(rot + p * 4, lrot + j * 4, rot + j * 4);
                pos[j * 3] = pos[p * 3] + turned[0];
                pos[j * 3 + 1] = pos[p * 3 + 1] + turned[1];
                pos[j * 3 + 2] = pos[p * 3 + 2] + turned[2];
            }
        }
        Py_END_ALLOW_THREADS
    }
    PyMem_Free(joint);
    PyMem_Free(parent);
    return finish(views, got, bad);
}

static PyMethodDef methods[] = {
    {"local_from_world", local_from_world, METH_VARARGS,
     "local_from_world(parents, world_rot, world_pos, local_rot, local_pos, frames, joints): world to local."},
    {"forward_kinematics", forward_kinematics, METH_VARARGS,
     "forward_kinematics(parents, rot, pos, frames, joints): joint-major local to world, in place."},
    {"chain_frames", chain_frames, METH_VARARGS,
     "chain_frames(out, positions, heads, starts, cuts, direction, frames, joints, links): frames along links."},
    {"twist_frames", twist_frames, METH_VARARGS,
     "twist_frames(out, angle, starts, cuts, direction, frames, joints, links): twist spread along links."},
    {"quat_from_euler", quat_from_euler, METH_VARARGS,
     "quat_from_euler(euler, out, codes, frames, joints): intrinsic Euler angles in degrees to quaternions."},
    {"euler_continuity", euler_continuity, METH_VARARGS,
     "euler_continuity(first, previous, parity, turns, last, frames, width, started): Euler angles made continuous."},
    {"chain_add", chain_add, METH_VARARGS,
     "chain_add(pos, parents, links, frames, joints): positions rebuilt down the hierarchy from their links."},
    {"euler_entries", euler_entries, METH_VARARGS,
     "euler_entries(q, out, count, i, j, k, sign): the matrix entries Euler angles are read from."},
    {"single_turns", single_turns, METH_VARARGS,
     "single_turns(was, now, turned, out, start, end, joint, frames, joints, count): joints turned by one link."},
    {"rigid_branches", rigid_branches, METH_VARARGS,
     "rigid_branches(world, positions, local_rot, local_pos, joints, parents, frames, joints, count): rigid "
     "branches placed under their parents."},
    {"unit_track", unit_track, METH_VARARGS,
     "unit_track(q, out, frames, joints, joint): a joint's quaternion track unrolled into one hemisphere and of "
     "unit length."},
    {"springs", springs, METH_VARARGS,
     "springs(follow, out, link_a, link_b, frames, particles, links, frame_time, substeps, stiffness, "
     "link_stiffness, damping): the suspended particles' time loop."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels", NULL, -1, methods};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
