/* --start NAME=VALUE[,...]; mirrors reference_py/tools/cli.py start_values. */
#include "start_flag.h"

#include "nte_constants.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ITEM_MAX 256

/* Python's str.strip() of s[0..n) (ASCII whitespace), into buf. */
static void stripped(const char* s, size_t n, char* buf, size_t cap)
{
    while ((n > 0U) && (strchr(" \t\r\n\v\f", s[0]) != NULL)) {
        s++;
        n--;
    }
    while ((n > 0U) && (strchr(" \t\r\n\v\f", s[n - 1U]) != NULL)) {
        n--;
    }
    (void)snprintf(buf, cap, "%.*s", (int)n, s);
}

/* Python's repr() of an ASCII string: single quotes unless it holds one and no double. */
static void py_repr(const char* s, char* buf, size_t cap)
{
    const char q = ((strchr(s, '\'') != NULL) && (strchr(s, '"') == NULL)) ? '"' : '\'';
    size_t o = 0U;
    buf[o++] = q;
    for (; (*s != '\0') && ((o + 5U) < cap); s++) {
        const unsigned char c = (unsigned char)*s;
        if ((c == (unsigned char)q) || (c == '\\')) {
            buf[o++] = '\\';
            buf[o++] = (char)c;
        } else if ((c < 0x20U) || (c == 0x7fU)) {
            const char* esc = (c == '\n') ? "\\n" : ((c == '\r') ? "\\r" : ((c == '\t') ? "\\t" : NULL));
            if (esc != NULL) {
                (void)memcpy(&buf[o], esc, 2U);
                o += 2U;
            } else {
                (void)snprintf(&buf[o], cap - o, "\\x%02x", (unsigned)c);
                o += 4U;
            }
        } else {
            buf[o++] = (char)c;
        }
    }
    buf[o++] = q;
    buf[o] = '\0';
}

/* float(text) as Python takes it, NaN when it is no number (no hexadecimal). */
static double number(const char* text)
{
    char* end = NULL;
    const double x = strtod(text, &end);
    if ((text[0] == '\0') || (*end != '\0') || (strpbrk(text, "xX(") != NULL)) {
        return (double)NAN;
    }
    return x;
}

static int find(const char* name)
{
    for (int j = 0; j < NTE_PARAM_COUNT; j++) {
        if (strcmp(nte_param_name((nte_param_id_t)j), name) == 0) {
            return j;
        }
    }
    return -1;
}

/* One item NAME=VALUE: its checks in start_values's order. */
static int parse_item(const char* item, size_t n, nte_start_flag_t* out, char* msg, size_t cap)
{
    char whole[ITEM_MAX];
    char name[ITEM_MAX];
    char value[ITEM_MAX];
    char shown[(2U * ITEM_MAX) + 8U];
    const char* eq = memchr(item, '=', n);
    stripped(item, (eq != NULL) ? (size_t)(eq - item) : n, name, sizeof name);
    if ((eq == NULL) || (name[0] == '\0')) {
        stripped(item, n, whole, sizeof whole);
        py_repr(whole, shown, sizeof shown);
        (void)snprintf(msg, cap, "%s is not NAME=VALUE", shown);
        return -1;
    }
    stripped(eq + 1, n - (size_t)(eq + 1 - item), value, sizeof value);
    const int j = find(name);
    py_repr(name, shown, sizeof shown);
    if (j < 0) {
        size_t o = (size_t)snprintf(msg, cap, "unknown parameter %s (valid: ", shown);
        for (int k = 0; (k < NTE_PARAM_COUNT) && (o < cap); k++) {
            o += (size_t)snprintf(msg + o, cap - o, "%s%s", (k > 0) ? ", " : "",
                                  nte_param_name((nte_param_id_t)k));
        }
        if (o < cap) {
            (void)snprintf(msg + o, cap - o, ")");
        }
        return -1;
    }
    if (out->given[j] != 0) {
        (void)snprintf(msg, cap, "%s given twice", shown);
        return -1;
    }
    const double x = number(value);
    const double hi = (double)NTE_K_RANGE_NOMINAL_ABS_MAX;
    if (!isfinite(x)) {
        (void)snprintf(msg, cap, "%s=%s: not a finite number", name, value);
        return -1;
    }
    if ((j == (int)nte_param_g_fast) || (j == (int)nte_param_g_slow)) {
        if (!((x > 0.0) && (x < 1.0))) {
            (void)snprintf(msg, cap, "%s=%s: must be > 0 and < 1 (a fraction of the elastic "
                           "force)", name, value);
            return -1;
        }
    } else if (j != (int)nte_param_f2) {
        if (!((x > 0.0) && (x <= hi))) {
            (void)snprintf(msg, cap, "%s=%s: must be > 0 and <= %g", name, value, hi);
            return -1;
        }
    } else if (!(fabs(x) <= hi)) {
        (void)snprintf(msg, cap, "%s=%s: must be within \xc2\xb1%g", name, value, hi);
        return -1;
    } else {
        /* f2 within the range */
    }
    out->given[j] = 1;
    out->value[j] = x;
    return 0;
}

int nte_start_flag_parse(const char* text, nte_start_flag_t* out, char* msg, size_t cap)
{
    (void)memset(out, 0, sizeof *out);
    const char* item = text;
    for (;;) {
        const char* comma = strchr(item, ',');
        const size_t n = (comma != NULL) ? (size_t)(comma - item) : strlen(item);
        if (parse_item(item, n, out, msg, cap) != 0) {
            return -1;
        }
        if (comma == NULL) {
            return 0;
        }
        item = comma + 1;
    }
}
