/* Python's repr() of a float and of a str in C, for messages that read exactly like the Python
 * models' (see pyrepr.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pyrepr.h"

#define N_DIGITS 24 /* a digit string and its terminating zero */

/* The shortest correctly rounded digit string of x (finite, not zero) that reads back as x,
 * trailing zeros dropped, into digits; returns their number, *decpt such that
 * |x| = 0.d1d2... * 10**decpt. */
static int shortest_digits(double x, char digits[N_DIGITS], int *decpt)
{
    char tmp[48];
    const char *p;
    int prec, nd = 0, exp10;
    for (prec = 1; prec < 17; prec++) {
        snprintf(tmp, sizeof tmp, "%.*e", prec - 1, x);
        if (strtod(tmp, NULL) == x) {
            break;
        }
    }
    snprintf(tmp, sizeof tmp, "%.*e", prec - 1, x);
    p = tmp;
    if (*p == '-') {
        p++;
    }
    for (; *p && *p != 'e' && *p != 'E'; p++) {
        if (*p >= '0' && *p <= '9' && nd < N_DIGITS - 1) {
            digits[nd++] = *p;
        }
    }
    exp10 = (*p) ? (int)strtol(p + 1, NULL, 10) : 0;
    while (nd > 1 && digits[nd - 1] == '0') {
        nd--;
    }
    digits[nd] = '\0';
    *decpt = exp10 + 1;
    return nd;
}

/* The nd digits with the point at decpt written as repr() writes them, at out + pos; returns the
 * position after them. */
static int place_digits(const char *digits, int nd, int decpt, char *out, size_t size, int pos)
{
    if (decpt <= -4 || decpt > 16) { /* float_repr_style 'r': exponent notation */
        out[pos++] = digits[0];
        if (nd > 1) {
            out[pos++] = '.';
            memcpy(out + pos, digits + 1, (size_t)(nd - 1));
            pos += nd - 1;
        }
        pos += snprintf(out + pos, size - (size_t)pos, "e%+.2d", decpt - 1);
    } else if (decpt <= 0) {
        out[pos++] = '0';
        out[pos++] = '.';
        for (int k = 0; k < -decpt; k++) {
            out[pos++] = '0';
        }
        memcpy(out + pos, digits, (size_t)nd);
        pos += nd;
    } else if (decpt >= nd) {
        memcpy(out + pos, digits, (size_t)nd);
        pos += nd;
        for (int k = 0; k < decpt - nd; k++) {
            out[pos++] = '0';
        }
        out[pos++] = '.';
        out[pos++] = '0';
    } else {
        memcpy(out + pos, digits, (size_t)decpt);
        pos += decpt;
        out[pos++] = '.';
        memcpy(out + pos, digits + decpt, (size_t)(nd - decpt));
        pos += nd - decpt;
    }
    return pos;
}

void py_float_repr(double x, char *buf, size_t size)
{
    char digits[N_DIGITS], out[48];
    int nd, decpt, pos = 0;
    if (size == 0) {
        return;
    }
    if (isnan(x)) {
        snprintf(buf, size, "nan");
        return;
    }
    if (isinf(x)) {
        snprintf(buf, size, "%s", x > 0.0 ? "inf" : "-inf");
        return;
    }
    if (x == 0.0) {
        snprintf(buf, size, "%s", signbit(x) ? "-0.0" : "0.0");
        return;
    }
    nd = shortest_digits(x, digits, &decpt);
    if (x < 0.0) {
        out[pos++] = '-';
    }
    pos = place_digits(digits, nd, decpt, out, sizeof out, pos);
    out[pos] = '\0';
    snprintf(buf, size, "%s", out);
}

/* repr(s) of a str (ASCII escapes; other bytes copied as they are) */
void py_str_repr(const char *s, size_t max_len, char *buf, size_t size)
{
    char out[4 * PY_REPR_STR_MAX + 3];
    size_t n = 0, k, len = 0;
    char quote;
    if (max_len > PY_REPR_STR_MAX) {
        max_len = PY_REPR_STR_MAX;
    }
    while (len < max_len && s[len]) {
        len++;
    }
    quote = memchr(s, '\'', len) && !memchr(s, '"', len) ? '"' : '\'';
    out[n++] = quote;
    for (k = 0; k < len; k++) {
        const unsigned char ch = (unsigned char)s[k];
        if (ch == (unsigned char)quote || ch == '\\') {
            out[n++] = '\\';
            out[n++] = (char)ch;
        } else if (ch == '\n' || ch == '\r' || ch == '\t') {
            out[n++] = '\\';
            out[n++] = ch == '\n' ? 'n' : ch == '\r' ? 'r' : 't';
        } else if (ch < 0x20 || ch == 0x7f) {
            n += (size_t)sprintf(out + n, "\\x%02x", ch);
        } else {
            out[n++] = (char)ch;
        }
    }
    out[n++] = quote;
    out[n] = '\0';
    snprintf(buf, size, "%s", out);
}
