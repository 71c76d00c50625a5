/* A units row: the twin of reference_py/tools/units_row.py (units_row.h). */
#include "units_row.h"

#include "name_value.h"
#include "nte_units.h"

#include <stdio.h>
#include <string.h>

int nte_unit_of_token(const char* s, size_t n, const char** kind, const char** unit)
{
    static const nte_unit_t time_units[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNITS;
    static const nte_unit_t depth_units[NTE_DEPTH_UNIT_COUNT] = NTE_DEPTH_UNITS;
    static const nte_unit_t force_units[NTE_FORCE_UNIT_COUNT] = NTE_FORCE_UNITS;
    static const struct {
        const char* unit;
        const char* spelled;
    } spellings[NTE_UNIT_NAME_SPELLING_COUNT] = NTE_UNIT_NAME_SPELLINGS;
    static const struct {
        const char* kind;
        const nte_unit_t* units;
        size_t count;
    } tables[3] = {{"time", time_units, NTE_TIME_UNIT_COUNT},
                   {"depth", depth_units, NTE_DEPTH_UNIT_COUNT},
                   {"force", force_units, NTE_FORCE_UNIT_COUNT}};
    /* one pair of brackets, and the spaces inside them */
    if ((n >= 2U) &&
        (((s[0] == '(') && (s[n - 1U] == ')')) || ((s[0] == '[') && (s[n - 1U] == ']')))) {
        s++;
        n = nte_py_strip(&s, n - 2U);
    }
    for (size_t k = 0U; k < 3U; k++) {
        for (size_t u = 0U; u < tables[k].count; u++) {
            const char* name = tables[k].units[u].name;
            int found = nte_py_ascii_same(s, n, name);
            for (size_t sp = 0U; (sp < NTE_UNIT_NAME_SPELLING_COUNT) && (found == 0); sp++) {
                found = (strcmp(spellings[sp].unit, name) == 0) &&
                        nte_py_ascii_same(s, n, spellings[sp].spelled);
            }
            if (found != 0) {
                *kind = tables[k].kind;
                *unit = name;
                return 1;
            }
        }
    }
    return 0;
}

int nte_units_row_check(const char* path, const nte_trial_t* tr, const nte_units_t* u, char* err,
                        const size_t es)
{
    const char* const columns[3] = {u->columns.t, u->columns.depth, u->columns.force};
    const char* const kinds[3] = {"time", "depth", "force"};
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
        if ((named == 0) || (strcmp(kind, kinds[k]) != 0)) {
            (void)snprintf(err, es, "%s:%zu: column '%s': the units row's %s is not a unit of %s",
                           path, tr->units_row_line, columns[k], shown, kinds[k]);
            return -1;
        }
        if (strcmp(unit, given[k]) != 0) {
            (void)snprintf(err, es,
                           "%s:%zu: column '%s': the units row gives %s: convert with --%s-unit %s",
                           path, tr->units_row_line, columns[k], shown, kinds[k], unit);
            return -1;
        }
    }
    return 0;
}
