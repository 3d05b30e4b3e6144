/* Quaternion loops NumPy runs as many small passes: forward kinematics (joint by joint, as NumPy's),
 * world-to-local and the rotation-minimising frames carried along each cut link (stages/orient.py),
 * frame by frame, in one pass over memory.
 *
 * Every number is computed with the operations NumPy's code uses, in the same order (core/rotations.py:
 * quat_mul, quat_rotate, quat_between, quat_normalize, _norm): +, -, *, / and sqrt only, each rounded
 * once (built without fused multiply-add or vectorising: setup.py), so the results are NumPy's bit for
 * bit (a NaN's sign bit aside, which no output carries: the BVH writer refuses NaN) and an install
 * without a C compiler, which runs the NumPy code, writes the same bytes. The tests compare both.
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
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

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
    const int64_t *parents = bad ? NULL : (const int64_t *)views[0].buf;
    if (!bad) bad = !parents_in_order(parents, joints, "local_from_world");
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
    const int64_t *parents = bad ? NULL : (const int64_t *)views[0].buf;
    if (!bad) bad = !parents_in_order(parents, joints, "forward_kinematics");
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
    if (!bad) {
        const int64_t *heads = (const int64_t *)views[2].buf, *starts = (const int64_t *)views[3].buf;
        const int64_t *cuts = (const int64_t *)views[4].buf;
        for (Py_ssize_t l = 0; l < links && !bad; l++) /* every joint read or written inside the arrays */
            bad = heads[l] < 0 || heads[l] >= joints || starts[l] < 0 || starts[l] >= joints || cuts[l] < 0 ||
                  cuts[l] >= joints - starts[l]; /* (written so that no sum wraps) */
        if (bad) PyErr_SetString(PyExc_ValueError, "chain_frames: a link's joints are outside the skeleton");
    }
    if (!bad) {
        double *out = (double *)views[0].buf;
        const double *positions = (const double *)views[1].buf;
        const int64_t *heads = (const int64_t *)views[2].buf, *starts = (const int64_t *)views[3].buf;
        const int64_t *cuts = (const int64_t *)views[4].buf;
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
    return finish(views, got, bad);
}

static PyMethodDef methods[] = {
    {"local_from_world", local_from_world, METH_VARARGS,
     "local_from_world(parents, world_rot, world_pos, local_rot, local_pos, frames, joints): world to local."},
    {"forward_kinematics", forward_kinematics, METH_VARARGS,
     "forward_kinematics(parents, rot, pos, frames, joints): joint-major local to world, in place."},
    {"chain_frames", chain_frames, METH_VARARGS,
     "chain_frames(out, positions, heads, starts, cuts, direction, frames, joints, links): frames along links."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernels", NULL, -1, methods};

PyMODINIT_FUNC PyInit__kernels(void) { return PyModule_Create(&module); }
