/* --start NAME=VALUE[,...]; mirrors reference_py/tools/cli.py start_values. */
#include "start_flag.h"

#include "name_value.h"
#include "nte_constants.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

/* --start names every parameter but Model III's turn-over length, which starts at
 * --presliding-mm (cli.start_values) */
#define START_COUNT ((int)nte_param_delta)

static int find(const char* name)
{
    for (int j = 0; j < START_COUNT; j++) {
        if (strcmp(nte_param_name((nte_param_id_t)j), name) == 0) {
            return j;
        }
    }
    return -1;
}

/* One item NAME=VALUE: its checks in start_values's order. */
static int parse_item(const nte_nv_t* it, nte_start_flag_t* out, char* msg, size_t cap)
{
    char shown[(2U * NTE_NV_TEXT) + 8U];
    const char* name = it->name;
    const char* value = it->value;
    if ((it->has_eq == 0) || (name[0] == '\0')) {
        nte_py_repr_text(it->item, shown, sizeof shown);
        (void)snprintf(msg, cap, "%s is not NAME=VALUE", shown);
        return -1;
    }
    const int j = find(name);
    nte_py_repr_text(name, shown, sizeof shown);
    if (j < 0) {
        size_t o = (size_t)snprintf(msg, cap, "unknown parameter %s (valid: ", shown);
        for (int k = 0; (k < START_COUNT) && (o < cap); k++) {
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
            (void)snprintf(msg, cap,
                           "%s=%s: must be > 0 and < 1 (a fraction of the elastic "
                           "force)",
                           name, value);
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
    static nte_nv_t items[NTE_NV_MAX];
    const size_t n = nte_nv_split(text, items, NTE_NV_MAX);
    (void)memset(out, 0, sizeof *out);
    for (size_t i = 0U; i < n; i++) {
        if (parse_item(&items[i], out, msg, cap) != 0) {
            return -1;
        }
    }
    return 0;
}
