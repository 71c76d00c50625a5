/* A units row: the twin of reference_py/tools/units_row.py (units_row.h). */
#include "units_row.h"

#include "name_value.h"
#include "nte_units.h"

#include <stdio.h>
#include <string.h>

/* 1 when the stripped s[0..n) is in one pair of () or []: then s and n are moved to the
 * stripped text inside (units_row._in_brackets); 0, and s and n untouched, otherwise. */
static int in_brackets(const char** s, size_t* n)
{
    const char* t = *s;
    const size_t len = *n;
    if ((len >= 2U) &&
        (((t[0] == '(') && (t[len - 1U] == ')')) || ((t[0] == '[') && (t[len - 1U] == ']')))) {
        *s = t + 1;
        *n = nte_py_strip(s, len - 2U);
        return 1;
    }
    return 0;
}

/* The unit tables (nte_units.h, generated from read_options.py), by quantity; constant. */
static const nte_unit_t time_units[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNITS;
static const nte_unit_t depth_units[NTE_DEPTH_UNIT_COUNT] = NTE_DEPTH_UNITS;
static const nte_unit_t force_units[NTE_FORCE_UNIT_COUNT] = NTE_FORCE_UNITS;
static const struct {
    const char* kind;
    const nte_unit_t* units;
    size_t count;
} unit_tables[3] = {{"time", time_units, NTE_TIME_UNIT_COUNT},
                    {"depth", depth_units, NTE_DEPTH_UNIT_COUNT},
                    {"force", force_units, NTE_FORCE_UNIT_COUNT}};

int nte_unit_of_token(const char* s, size_t n, const char** kind, const char** unit)
{
    static const struct {
        const char* unit;
        const char* spelled;
    } spellings[NTE_UNIT_NAME_SPELLING_COUNT] = NTE_UNIT_NAME_SPELLINGS;
    (void)in_brackets(&s, &n);
    for (size_t k = 0U; k < 3U; k++) {
        for (size_t u = 0U; u < unit_tables[k].count; u++) {
            const char* name = unit_tables[k].units[u].name;
            int found = nte_py_ascii_same(s, n, name);
            for (size_t sp = 0U; (sp < NTE_UNIT_NAME_SPELLING_COUNT) && (found == 0); sp++) {
                found = (strcmp(spellings[sp].unit, name) == 0) &&
                        nte_py_ascii_same(s, n, spellings[sp].spelled);
            }
            if (found != 0) {
                *kind = unit_tables[k].kind;
                *unit = name;
                return 1;
            }
        }
    }
    return 0;
}

int nte_unit_like(const char* s, size_t n)
{
    const char* kind = NULL;
    const char* unit = NULL;
    if (nte_unit_of_token(s, n, &kind, &unit) != 0) {
        return 1;
    }
    return (in_brackets(&s, &n) != 0) && (n > 0U);
}

/* "s, ms, us, ns": the names of a unit table, for a refusal */
static void unit_names(const nte_unit_t* units, const size_t count, char* out, const size_t size)
{
    size_t used = 0U;
    out[0] = '\0';
    for (size_t u = 0U; (u < count) && (used < size); u++) {
        const int w = snprintf(out + used, size - used, "%s%s", (u > 0U) ? ", " : "",
                               units[u].name);
        used += (w > 0) ? (size_t)w : 0U;
    }
}

int nte_units_row_check(const char* path, const nte_trial_t* tr, const nte_units_t* u, char* err,
                        const size_t es)
{
    const char* const columns[3] = {u->columns.t, u->columns.depth, u->columns.force};
    const char* const given[3] = {u->time, u->depth, u->force};
    for (size_t k = 0U; k < 3U; k++) {
        const char* cell = tr->units_row[k];
        if (cell == NULL) {
            continue;
        }
        const char* kind = NULL;
        const char* unit = NULL;
        const int named = nte_unit_of_token(cell, strlen(cell), &kind, &unit);
        char shown[256];
        nte_py_repr_bytes(cell, strlen(cell), shown, sizeof shown);
        if ((named == 0) || (strcmp(kind, unit_tables[k].kind) != 0)) {
            char read[64];
            unit_names(unit_tables[k].units, unit_tables[k].count, read, sizeof read);
            (void)snprintf(err, es,
                           "%s:%zu: column '%s': the units row's %s is not a unit of %s the "
                           "tools read (%s): convert the column to one of them",
                           path, tr->units_row_line, columns[k], shown, unit_tables[k].kind, read);
            return -1;
        }
        if (strcmp(unit, given[k]) != 0) {
            (void)snprintf(err, es,
                           "%s:%zu: column '%s': the units row gives %s: convert with --%s-unit %s",
                           path, tr->units_row_line, columns[k], shown, unit_tables[k].kind, unit);
            return -1;
        }
    }
    return 0;
}
