/* Fixed-point text for BVH motion lines: the one loop NumPy cannot make fast.
 *
 * format_fixed(values, rows, cols, decimals) -> bytes, where values is a C-contiguous
 * buffer of rows * cols native float64 (its format is checked). Each number is rounded as NumPy's np.rint(abs(v) * 10**decimals)
 * (round half to even; one IEEE multiply, so the same integer NumPy computes), written with
 * no minus sign on a zero, numbers separated by one space, rows by one LF, and a final LF.
 * Magnitudes of 1e9 or more are the caller's (io/bvh.py formats them in Python).
 *
 * Optional: io/bvh.py falls back to its NumPy formatter when this module was not built, and
 * the tests check that both write the same bytes.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

static const double TWO_52 = 4503599627370496.0;

static const char DIGIT_PAIRS[201] =
    "00010203040506070809"
    "10111213141516171819"
    "20212223242526272829"
    "30313233343536373839"
    "40414243444546474849"
    "50515253545556575859"
    "60616263646566676869"
    "70717273747576777879"
    "80818283848586878889"
    "90919293949596979899";

/* Writes the decimal digits of v (no leading zeros, at least one digit); returns the count. */
static int write_integer(char *out, uint64_t v) {
    char buffer[24];
    int n = 0;
    while (v >= 100) {
        unsigned pair = (unsigned)(v % 100);
        v /= 100;
        buffer[n++] = DIGIT_PAIRS[2 * pair + 1];
        buffer[n++] = DIGIT_PAIRS[2 * pair];
    }
    if (v >= 10) {
        buffer[n++] = DIGIT_PAIRS[2 * v + 1];
        buffer[n++] = DIGIT_PAIRS[2 * v];
    } else {
        buffer[n++] = (char)('0' + v);
    }
    for (int i = 0; i < n; i++) out[i] = buffer[n - 1 - i];
    return n;
}

static PyObject *format_fixed(PyObject *self, PyObject *args) {
    PyObject *values_object;
    Py_buffer view;
    Py_ssize_t rows, cols;
    int decimals;
    if (!PyArg_ParseTuple(args, "Onni", &values_object, &rows, &cols, &decimals)) return NULL;
    if (PyObject_GetBuffer(values_object, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    /* Per number at most: separator (or the row's LF), sign, 10 integer digits (a number below 1e9 may
     * round up to 1000000000), point, decimals. */
    const Py_ssize_t widest = 13 + decimals;
    if (view.format == NULL || strcmp(view.format, "d") != 0 || view.itemsize != (Py_ssize_t)sizeof(double) ||
        rows < 0 || cols < 1 || decimals < 0 || decimals > 9 || rows > (PY_SSIZE_T_MAX - 1) / cols / 24 ||
        view.len != rows * cols * (Py_ssize_t)sizeof(double)) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError,
                        "format_fixed: a C-contiguous buffer of rows * cols native float64, 0 <= decimals <= 9");
        return NULL;
    }
    Py_ssize_t most = rows * cols * widest + 1;
    PyObject *result = PyBytes_FromStringAndSize(NULL, most);
    if (result == NULL) {
        PyBuffer_Release(&view);
        return NULL;
    }
    char *out = PyBytes_AS_STRING(result);
    char *at = out;
    const double *values = (const double *)view.buf;
    uint64_t scale = 1;
    for (int i = 0; i < decimals; i++) scale *= 10;
    const double limit = 1e9 * (double)scale; /* magnitudes of 1e9 or more are the caller's */
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t r = 0; r < rows && !bad; r++) {
        for (Py_ssize_t c = 0; c < cols; c++) {
            double v = values[r * cols + c];
            double units = fabs(v) * (double)scale;
            if (!(units < limit)) { /* NaN, infinite or 1e9 or more: the caller's job */
                bad = 1;
                break;
            }
            /* Round half to even, as np.rint: below 2**52, adding and taking away 2**52 leaves the
             * nearest integer (the default rounding mode); from 2**52 on every double is one. */
            if (units < TWO_52) units = (units + TWO_52) - TWO_52;
            uint64_t whole_units = (uint64_t)units;
            if (c > 0) *at++ = ' ';
            if (v < 0 && whole_units > 0) *at++ = '-';
            at += write_integer(at, whole_units / scale);
            if (decimals > 0) {
                *at++ = '.';
                uint64_t frac = whole_units % scale;
                int i = decimals;
                while (i >= 2) {
                    unsigned pair = (unsigned)(frac % 100);
                    frac /= 100;
                    at[--i] = DIGIT_PAIRS[2 * pair + 1];
                    at[--i] = DIGIT_PAIRS[2 * pair];
                }
                if (i == 1) at[0] = (char)('0' + frac);
                at += decimals;
            }
        }
        *at++ = '\n';
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    if (bad) {
        Py_DECREF(result);
        PyErr_SetString(PyExc_ValueError, "format_fixed: a value is not finite, or is 1e9 or more");
        return NULL;
    }
    if (_PyBytes_Resize(&result, at - out) < 0) return NULL;
    return result;
}

static PyMethodDef methods[] = {
    {"format_fixed", format_fixed, METH_VARARGS,
     "format_fixed(values, rows, cols, decimals) -> bytes: fixed-point rows of float64 numbers."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_formatting", NULL, -1, methods};

PyMODINIT_FUNC PyInit__formatting(void) { return PyModule_Create(&module); }
