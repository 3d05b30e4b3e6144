/* Fixed-point text for BVH motion lines, and the motion lines read back: the loops NumPy cannot make fast.
 *
 * format_fixed(values, rows, cols, decimals) -> bytes, where values is a C-contiguous
 * buffer of rows * cols native float64 (its format is checked). Each number is rounded as NumPy's np.rint(abs(v) * 10**decimals)
 * (round half to even; one IEEE multiply, so the same integer NumPy computes), written with
 * no minus sign on a zero, numbers separated by one space, rows by one LF, and a final LF.
 * Magnitudes of 1e9 or more are the caller's (io/bvh.py formats them in Python).
 *
 * format_columns(first, second, picks, rows, first_width, second_width, decimals) -> bytes: the same text of
 * rows whose columns are picked from two C-contiguous float64 tables (rows * first_width and rows *
 * second_width): picks[c] >= 0 is first[r, picks[c]], else second[r, -1 - picks[c]] (the BVH's positions and
 * Euler angles, formatted with no table of channels made between them).
 *
 * parse_motion(block, out, channels, declared, largest) -> the number of lines with values, or -1.
 * block is bytes (the text after 'Frame Time:'), out a writable buffer of declared * channels float64.
 * Lines end at LF; values are separated by any of TAB LF VT FF CR SPACE. When the first `declared` lines
 * with values each hold `channels` numbers written as BVH exporters write them ([+-] digits [. digits]
 * [e [+-] digits]) of magnitude at most `largest`, their values fill out and the count of every line with
 * values is returned; else -1, and io/bvh.py reads the block with NumPy, which finds and names the fault.
 * A number of at most 19 significant digits whose power of ten is within 22 is one IEEE product or
 * quotient of two exact doubles (Clinger's fast path), so correctly rounded; any other goes to Python's
 * own correctly rounded PyOS_string_to_double. So every value is the double nearest the text, as NumPy's
 * strtod makes it (the tests compare both on every clip).
 *
 * Optional: io/bvh.py falls back to its NumPy code when this module was not built, and the tests check
 * that both give the same bytes and values.
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

/* One number: its separator (none before a row's first), sign, digits. 0 when it is not finite or is 1e9
 * or more (the caller's job). */
static inline int write_value(char **at_pointer, double v, int first, uint64_t scale, int decimals, double limit) {
    char *at = *at_pointer;
    double units = fabs(v) * (double)scale;
    if (!(units < limit)) return 0; /* NaN, infinite or 1e9 or more */
    /* Round half to even, as np.rint: below 2**52, adding and taking away 2**52 leaves the
     * nearest integer (the default rounding mode); from 2**52 on every double is one. */
    if (units < TWO_52) units = (units + TWO_52) - TWO_52;
    uint64_t whole_units = (uint64_t)units;
    if (!first) *at++ = ' ';
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
    *at_pointer = at;
    return 1;
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
            if (!write_value(&at, values[r * cols + c], c == 0, scale, decimals, limit)) {
                bad = 1;
                break;
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

/* A C-contiguous buffer of exactly `count` native items of `format` ("d" float64 or "q" int64). */
static int get_items(PyObject *object, Py_buffer *view, const char *format, Py_ssize_t count, const char *name) {
    if (PyObject_GetBuffer(object, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return 0;
    const Py_ssize_t size = format[0] == 'd' ? (Py_ssize_t)sizeof(double) : (Py_ssize_t)sizeof(int64_t);
    int same = view->format != NULL && (strcmp(view->format, format) == 0 ||
                                         (format[0] == 'q' && strcmp(view->format, "l") == 0 && sizeof(long) == 8));
    if (!same || view->itemsize != size || count < 0 || count > PY_SSIZE_T_MAX / size || view->len != count * size) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "format_columns: %s must be C-contiguous native %s, %zd of them", name,
                     format[0] == 'd' ? "float64" : "int64", count);
        return 0;
    }
    return 1;
}

/* format_columns(first, second, picks, rows, first_width, second_width, decimals): format_fixed's bytes of
 * the rows whose column c is first[r, picks[c]] where picks[c] >= 0, else second[r, -1 - picks[c]]: the
 * BVH's channels taken from the positions and the Euler angles as they are, with no table made of them. */
static PyObject *format_columns(PyObject *self, PyObject *args) {
    PyObject *objects[3];
    Py_ssize_t rows, widths[2];
    int decimals;
    if (!PyArg_ParseTuple(args, "OOOnnni", &objects[0], &objects[1], &objects[2], &rows, &widths[0], &widths[1],
                          &decimals))
        return NULL;
    if (rows < 0 || widths[0] < 0 || widths[1] < 0 || decimals < 0 || decimals > 9 ||
        (widths[0] > 0 && rows > PY_SSIZE_T_MAX / 8 / widths[0]) ||
        (widths[1] > 0 && rows > PY_SSIZE_T_MAX / 8 / widths[1])) {
        PyErr_SetString(PyExc_ValueError, "format_columns: counts out of range, or not 0 <= decimals <= 9");
        return NULL;
    }
    Py_buffer views[3];
    if (!get_items(objects[2], &views[2], "q", PyObject_Length(objects[2]), "picks")) return NULL;
    const Py_ssize_t cols = views[2].len / (Py_ssize_t)sizeof(int64_t);
    if (!get_items(objects[0], &views[0], "d", rows * widths[0], "first")) {
        PyBuffer_Release(&views[2]);
        return NULL;
    }
    if (!get_items(objects[1], &views[1], "d", rows * widths[1], "second")) {
        PyBuffer_Release(&views[0]);
        PyBuffer_Release(&views[2]);
        return NULL;
    }
    /* The picks are copied before they are checked: the loop reads them with the GIL let go, when another
     * thread could change the caller's array. */
    int64_t *picks = cols >= 1 ? PyMem_Malloc((size_t)cols * sizeof(int64_t)) : NULL;
    if (cols >= 1 && picks == NULL) {
        for (int i = 0; i < 3; i++) PyBuffer_Release(&views[i]);
        return PyErr_NoMemory();
    }
    if (picks != NULL) memcpy(picks, views[2].buf, (size_t)cols * sizeof(int64_t));
    int fits = cols >= 1 && rows <= (PY_SSIZE_T_MAX - 1) / cols / 24;
    for (Py_ssize_t c = 0; c < cols && fits; c++)
        fits = picks[c] >= 0 ? picks[c] < widths[0] : -1 - picks[c] < widths[1];
    PyObject *result = NULL;
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "format_columns: a pick outside its table, or no columns");
    } else {
        const Py_ssize_t widest = 13 + decimals; /* (as format_fixed's) */
        result = PyBytes_FromStringAndSize(NULL, rows * cols * widest + 1);
    }
    if (result != NULL) {
        char *out = PyBytes_AS_STRING(result);
        char *at = out;
        const double *first = (const double *)views[0].buf, *second = (const double *)views[1].buf;
        uint64_t scale = 1;
        for (int i = 0; i < decimals; i++) scale *= 10;
        const double limit = 1e9 * (double)scale;
        int bad = 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t r = 0; r < rows && !bad; r++) {
            const double *a = first + r * widths[0], *b = second + r * widths[1];
            for (Py_ssize_t c = 0; c < cols; c++) {
                const double v = picks[c] >= 0 ? a[picks[c]] : b[-1 - picks[c]];
                if (!write_value(&at, v, c == 0, scale, decimals, limit)) {
                    bad = 1;
                    break;
                }
            }
            *at++ = '\n';
        }
        Py_END_ALLOW_THREADS
        if (bad) {
            Py_CLEAR(result);
            PyErr_SetString(PyExc_ValueError, "format_columns: a value is not finite, or is 1e9 or more");
        } else if (_PyBytes_Resize(&result, at - out) < 0) {
            result = NULL;
        }
    }
    PyMem_Free(picks);
    for (int i = 0; i < 3; i++) PyBuffer_Release(&views[i]);
    return result;
}

static const double POWERS_OF_TEN[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                         1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static inline int is_space(unsigned char c) { return c == ' ' || (c >= 9 && c <= 13); }

/* The number in [at, end) (a whole token), or 0 when it is not written as BVH exporters write numbers. */
static int parse_number(const char *at, const char *end, double *value) {
    const char *p = at;
    int negative = 0;
    if (end - at > 4096) return 0; /* (no number is written so; its digit counts stay far from overflow) */
    if (p < end && (*p == '+' || *p == '-')) negative = *p++ == '-';
    uint64_t mantissa = 0;
    int significant = 0, dropped = 0, scale = 0, any = 0;
    while (p < end && *p >= '0' && *p <= '9') { /* whole part */
        any = 1;
        if (mantissa == 0 && *p == '0') {
            p++;
            continue;
        }
        if (significant < 19) {
            mantissa = mantissa * 10 + (uint64_t)(*p - '0');
            significant++;
        } else {
            dropped = 1;
            scale++;
        }
        p++;
    }
    if (p < end && *p == '.') {
        p++;
        while (p < end && *p >= '0' && *p <= '9') {
            any = 1;
            if (mantissa == 0 && *p == '0') {
                scale--;
            } else if (significant < 19) {
                mantissa = mantissa * 10 + (uint64_t)(*p - '0');
                significant++;
                scale--;
            } else {
                dropped = 1;
            }
            p++;
        }
    }
    if (!any) return 0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        p++;
        int minus = 0;
        if (p < end && (*p == '+' || *p == '-')) minus = *p++ == '-';
        if (p >= end || *p < '0' || *p > '9') return 0;
        long exponent = 0;
        while (p < end && *p >= '0' && *p <= '9') {
            if (exponent < 100000) exponent = exponent * 10 + (*p - '0');
            p++;
        }
        scale += (int)(minus ? -exponent : exponent);
    }
    if (p != end) return 0;
    double result;
    if (mantissa == 0) {
        result = 0.0;
    } else if (!dropped && mantissa <= (UINT64_C(1) << 53) && scale >= -22 && scale <= 22) {
        /* both exact doubles: one rounding */
        result = scale < 0 ? (double)mantissa / POWERS_OF_TEN[-scale] : (double)mantissa * POWERS_OF_TEN[scale];
    } else {
        /* the text itself, by Python's correctly rounded reader (the token is followed by a space, LF or the
         * bytes object's closing NUL, none of which a number takes) */
        char *stop = NULL;
        result = PyOS_string_to_double(at, &stop, NULL);
        if (result == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            return 0;
        }
        if (stop != end) return 0;
        *value = result;
        return 1;
    }
    *value = negative ? -result : result;
    return 1;
}

static PyObject *parse_motion(PyObject *self, PyObject *args) {
    Py_buffer out;
    PyObject *block, *target;
    Py_ssize_t channels, declared;
    double largest;
    if (!PyArg_ParseTuple(args, "SOnnd", &block, &target, &channels, &declared, &largest)) return NULL;
    if (PyObject_GetBuffer(target, &out, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) return NULL;
    if (channels < 1 || declared < 1 || declared > PY_SSIZE_T_MAX / 8 / channels || out.format == NULL ||
        strcmp(out.format, "d") != 0 || out.itemsize != (Py_ssize_t)sizeof(double) || !PyBuffer_IsContiguous(&out, 'C') ||
        out.len != declared * channels * (Py_ssize_t)sizeof(double)) {
        PyBuffer_Release(&out);
        PyErr_SetString(PyExc_ValueError, "parse_motion: out must be a C-contiguous float64 buffer of declared * channels");
        return NULL;
    }
    const char *at = PyBytes_AS_STRING(block), *end = at + PyBytes_GET_SIZE(block);
    double *values = (double *)out.buf;
    Py_ssize_t lines = 0, filled = 0;
    int fits = 1;
    while (at < end && fits) {
        const char *line_end = memchr(at, '\n', (size_t)(end - at));
        if (line_end == NULL) line_end = end;
        Py_ssize_t count = 0;
        if (lines < declared) {
            const char *p = at;
            while (p < line_end) {
                while (p < line_end && is_space((unsigned char)*p)) p++;
                if (p >= line_end) break;
                const char *token = p;
                while (p < line_end && !is_space((unsigned char)*p)) p++;
                double value;
                if (count >= channels || !parse_number(token, p, &value) || !(fabs(value) <= largest)) {
                    fits = 0;
                    break;
                }
                values[filled + count++] = value;
            }
            if (fits && count > 0 && count != channels) fits = 0;
            filled += count;
        } else { /* past the lines read: only whether it has values */
            for (const char *p = at; p < line_end; p++)
                if (!is_space((unsigned char)*p)) {
                    count = 1;
                    break;
                }
        }
        lines += count > 0;
        at = line_end + 1;
    }
    PyBuffer_Release(&out);
    if (!fits || lines < declared) return PyLong_FromLong(-1);
    return PyLong_FromSsize_t(lines);
}

static PyMethodDef methods[] = {
    {"format_fixed", format_fixed, METH_VARARGS,
     "format_fixed(values, rows, cols, decimals) -> bytes: fixed-point rows of float64 numbers."},
    {"format_columns", format_columns, METH_VARARGS,
     "format_columns(first, second, picks, rows, first_width, second_width, decimals) -> bytes: format_fixed's "
     "rows, each column taken from one of two tables."},
    {"parse_motion", parse_motion, METH_VARARGS,
     "parse_motion(block, out, channels, declared, largest) -> lines with values, or -1: BVH motion lines."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_formatting", NULL, -1, methods};

PyMODINIT_FUNC PyInit__formatting(void) { return PyModule_Create(&module); }
