/* Strict CSV reader of the host programs; mirrors reference_py/tools/csvio.py read_trial. */
#include "csv_in.h"

#include "nte_units.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_COLS 64

static void fail(char* err, size_t size, const char* fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(err, size, fmt, ap);
    va_end(ap);
}

void nte_py_repr(const double x, char* buf, const size_t size)
{
    if (isnan(x)) {
        (void)snprintf(buf, size, "nan");
        return;
    }
    if (isinf(x)) {
        (void)snprintf(buf, size, (x < 0.0) ? "-inf" : "inf");
        return;
    }
    char e[40];
    int prec = 1;
    for (; prec <= 17; prec++) {
        (void)snprintf(e, sizeof e, "%.*e", prec - 1, x);
        const double back = strtod(e, NULL);
        if (memcmp(&back, &x, sizeof back) == 0) {
            break;
        }
    }
    /* e = [-]d[.ddd]e[+-]XX : digits and decimal exponent */
    char digits[24];
    size_t nd = 0U;
    const char* p = e;
    const int neg = (*p == '-');
    if (neg) {
        p++;
    }
    for (; (*p != 'e') && (*p != '\0'); p++) {
        if ((*p >= '0') && (*p <= '9') && (nd < (sizeof digits - 1U))) {
            digits[nd++] = *p;
        }
    }
    digits[nd] = '\0';
    const int exp10 = atoi(p + 1);
    char out[64];
    size_t o = 0U;
    if (neg) {
        out[o++] = '-';
    }
    if ((exp10 < -4) || (exp10 >= 16)) {
        out[o++] = digits[0];
        if (nd > 1U) {
            out[o++] = '.';
            for (size_t i = 1U; i < nd; i++) {
                out[o++] = digits[i];
            }
        }
        (void)snprintf(out + o, sizeof out - o, "e%c%02d", (exp10 < 0) ? '-' : '+', abs(exp10));
    } else if (exp10 < 0) {
        out[o++] = '0';
        out[o++] = '.';
        for (int i = -1; i > exp10; i--) {
            out[o++] = '0';
        }
        for (size_t i = 0U; i < nd; i++) {
            out[o++] = digits[i];
        }
        out[o] = '\0';
    } else {
        const size_t ip = (size_t)exp10 + 1U;
        for (size_t i = 0U; i < ip; i++) {
            out[o++] = (i < nd) ? digits[i] : '0';
        }
        out[o++] = '.';
        if (nd > ip) {
            for (size_t i = ip; i < nd; i++) {
                out[o++] = digits[i];
            }
        } else {
            out[o++] = '0';
        }
        out[o] = '\0';
    }
    (void)snprintf(buf, size, "%s", out);
}

static char* strip(char* s)
{
    while ((*s != '\0') && (strchr(" \t\r\n\v\f", *s) != NULL)) {
        s++;
    }
    size_t n = strlen(s);
    while ((n > 0U) && (strchr(" \t\r\n\v\f", s[n - 1U]) != NULL)) {
        s[--n] = '\0';
    }
    return s;
}

/* Split `line` in place at commas; returns the number of cells (or MAX_COLS + 1 if more). */
static size_t split(char* line, char** cells)
{
    size_t n = 0U;
    char* p = line;
    for (;;) {
        char* c = strchr(p, ',');
        if (n < MAX_COLS) {
            cells[n] = p;
        }
        n++;
        if (c == NULL) {
            break;
        }
        *c = '\0';
        p = c + 1;
    }
    return n;
}

static int push(nte_trial_t* tr, size_t* cap, const double t, const double l, const double v,
                const double f, const size_t lineno)
{
    if (tr->n == *cap) {
        const size_t nc = (*cap == 0U) ? 1024U : (*cap * 2U);
        double** a[4] = {&tr->t_s, &tr->depth_mm, &tr->velocity_mm_s, &tr->force_n};
        for (size_t i = 0U; i < 4U; i++) {
            double* b = realloc(*a[i], nc * sizeof(double));
            if (b == NULL) {
                return -1;
            }
            *a[i] = b;
        }
        size_t* ln = realloc(tr->line, nc * sizeof(size_t));
        if (ln == NULL) {
            return -1;
        }
        tr->line = ln;
        *cap = nc;
    }
    tr->t_s[tr->n] = t;
    tr->depth_mm[tr->n] = l;
    tr->velocity_mm_s[tr->n] = v;
    tr->force_n[tr->n] = f;
    tr->line[tr->n] = lineno;
    tr->n++;
    return 0;
}

static char* slurp(const char* path, size_t* len)
{
    FILE* fh = fopen(path, "rb");
    if (fh == NULL) {
        return NULL;
    }
    size_t cap = 65536U;
    size_t n = 0U;
    char* buf = malloc(cap);
    for (;;) {
        if (buf == NULL) {
            break;
        }
        if ((n + 1U) >= cap) {
            char* b = realloc(buf, cap * 2U);
            if (b == NULL) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = b;
            cap *= 2U;
        }
        const size_t got = fread(&buf[n], 1U, cap - n - 1U, fh);
        n += got;
        if (got == 0U) {
            break;
        }
    }
    (void)fclose(fh);
    if (buf != NULL) {
        buf[n] = '\0';
        *len = n;
    }
    return buf;
}

void nte_columns_standard(nte_columns_t* c)
{
    (void)snprintf(c->t, sizeof c->t, "t_s");
    (void)snprintf(c->depth, sizeof c->depth, "depth_mm");
    (void)snprintf(c->force, sizeof c->force, "force_n");
    (void)snprintf(c->velocity, sizeof c->velocity, "velocity_mm_s");
    c->velocity_required = 0;
}

/* ASCII case-insensitive equality (a header's names are compared as csvio compares them
 * lowered). */
static int same_ignoring_case(const char* a, const char* b)
{
    while ((*a != '\0') && (*b != '\0')) {
        if (tolower((unsigned char)*a) != tolower((unsigned char)*b)) {
            return 0;
        }
        a++;
        b++;
    }
    return (*a == '\0') && (*b == '\0');
}

/* Twin of csvio.unit_suffix_hint: "read it with --columns t=..,depth=..,force=.. [--KIND-unit
 * U]..." when each of the time, depth and force has exactly one column named QUANTITY_UNIT
 * (case aside: t_ms, depth_m, force_mN), "" otherwise.  The reader does not guess from a name
 * (a column so named may hold anything); the refusal says how to read the file. */
static void unit_suffix_hint(char* const* header, const size_t nc, char* out, const size_t cap)
{
    static const nte_unit_t time_units[] = NTE_TIME_UNITS;
    static const nte_unit_t depth_units[] = NTE_DEPTH_UNITS;
    static const nte_unit_t force_units[] = NTE_FORCE_UNITS;
    const struct {
        const char* key;  /* the --columns key, also the name's first part */
        const char* kind; /* --KIND-unit */
        const nte_unit_t* units;
        size_t n_units;
    } quantities[3] = {{"t", "time", time_units, NTE_TIME_UNIT_COUNT},
                       {"depth", "depth", depth_units, NTE_DEPTH_UNIT_COUNT},
                       {"force", "force", force_units, NTE_FORCE_UNIT_COUNT}};
    char mapped[512] = "";
    char options[256] = "";
    out[0] = '\0';
    for (size_t q = 0U; q < 3U; q++) {
        size_t found = 0U;
        const char* column = NULL;
        const nte_unit_t* unit = NULL;
        size_t unit_index = 0U;
        for (size_t c = 0U; c < nc; c++) {
            for (size_t u = 0U; u < quantities[q].n_units; u++) {
                char name[64];
                (void)snprintf(name, sizeof name, "%s_%s", quantities[q].key,
                               quantities[q].units[u].name);
                if (same_ignoring_case(header[c], name) != 0) {
                    found++;
                    column = header[c];
                    unit = &quantities[q].units[u];
                    unit_index = u;
                }
            }
        }
        if (found != 1U) {
            return;
        }
        size_t o = strlen(mapped);
        (void)snprintf(mapped + o, sizeof mapped - o, "%s%s=%s", (q > 0U) ? "," : "",
                       quantities[q].key, column);
        if (unit_index != 0U) { /* the first unit of each table is the tools' own */
            o = strlen(options);
            (void)snprintf(options + o, sizeof options - o, " --%s-unit %s", quantities[q].kind,
                           unit->name);
        }
    }
    (void)snprintf(out, cap, "; read it with --columns %s%s", mapped, options);
}

int nte_trial_read(const char* path, nte_trial_t* tr, char* err, const size_t es)
{
    nte_columns_t c;
    (void)memset(&c, 0, sizeof c);
    nte_columns_standard(&c);
    return nte_trial_read_columns(path, &c, tr, err, es);
}

int nte_trial_read_columns(const char* path, const nte_columns_t* cols, nte_trial_t* tr, char* err,
                           const size_t es)
{
    memset(tr, 0, sizeof *tr);
    size_t len = 0U;
    errno = 0;
    char* text = slurp(path, &len);
    if (text == NULL) {
        fail(err, es, "%s: cannot read: %s", path, strerror((errno != 0) ? errno : EIO));
        return -1;
    }
    if (strlen(text) != len) {
        fail(err, es, "%s: not a text file", path);
        free(text);
        return -1;
    }
    size_t n_lines = 1U;
    for (size_t i = 0U; i < len; i++) {
        n_lines += (text[i] == '\n') ? 1U : 0U;
    }
    char* header[MAX_COLS];
    char hbuf[4096];
    size_t ncols = 0U;
    size_t header_line = 0U;
    int ti = -1;
    int li = -1;
    int fi = -1;
    int vi = -1;
    size_t cap = 0U;
    double prev_t = -HUGE_VAL;
    int rc = 0;
    char* line = text;
    for (size_t lineno = 1U; (lineno <= n_lines) && (rc == 0); lineno++) {
        char* nl = strchr(line, '\n');
        if (nl != NULL) {
            *nl = '\0';
        }
        char* next = (nl != NULL) ? (nl + 1) : (line + strlen(line));
        size_t ll = strlen(line);
        while ((ll > 0U) && (line[ll - 1U] == '\r')) {
            line[--ll] = '\0';
        }
        if (line[0] == '#') {
            line = next;
            continue;
        }
        if (ll == 0U) {
            if (lineno != n_lines) {
                fail(err, es, "%s:%zu: empty line", path, lineno);
                rc = -1;
            }
            line = next;
            continue;
        }
        char* cells[MAX_COLS];
        const size_t nc = split(line, cells);
        if (ncols == 0U) {
            if (nc > MAX_COLS) {
                fail(err, es, "%s:%zu: more than %d columns", path, lineno, MAX_COLS);
                rc = -1;
                break;
            }
            size_t o = 0U;
            for (size_t c = 0U; c < nc; c++) {
                header[c] = strip(cells[c]);
                const int w = snprintf(hbuf + o, sizeof hbuf - o, "%s%s", (c > 0U) ? ", " : "",
                                       header[c]);
                if ((w > 0) && ((size_t)w < (sizeof hbuf - o))) {
                    o += (size_t)w;
                }
                if (strcmp(header[c], cols->t) == 0) {
                    ti = (int)c;
                }
                if (strcmp(header[c], cols->depth) == 0) {
                    li = (int)c;
                }
                if (strcmp(header[c], cols->force) == 0) {
                    fi = (int)c;
                }
                if ((cols->velocity[0] != '\0') && (strcmp(header[c], cols->velocity) == 0)) {
                    vi = (int)c;
                }
            }
            const char* req[4] = {cols->t, cols->depth, cols->force, cols->velocity};
            const int idx[4] = {ti, li, fi, vi};
            const size_t n_req = (cols->velocity_required != 0) ? 4U : 3U;
            for (size_t r = 0U; (r < n_req) && (rc == 0); r++) {
                if (idx[r] < 0) {
                    char advice[1024] = "";
                    if (cols->mapped == 0) {
                        unit_suffix_hint(header, nc, advice, sizeof advice);
                    }
                    fail(err, es, "%s:%zu: column '%s': missing from the header (have: %s)%s", path,
                         lineno, req[r], hbuf, advice);
                    rc = -1;
                }
            }
            for (size_t a = 0U; (a < nc) && (rc == 0); a++) {
                for (size_t b = a + 1U; (b < nc) && (rc == 0); b++) {
                    if (strcmp(header[a], header[b]) == 0) {
                        fail(err, es, "%s:%zu: column '%s': duplicate column name in the header",
                             path, lineno, header[a]);
                        rc = -1;
                    }
                }
            }
            ncols = nc;
            header_line = lineno;
            line = next;
            continue;
        }
        if (nc != ncols) {
            fail(err, es, "%s:%zu: expected %zu cells, found %zu", path, lineno, ncols, nc);
            rc = -1;
            break;
        }
        double row[MAX_COLS];
        for (size_t c = 0U; (c < nc) && (rc == 0); c++) {
            char* cell = strip(cells[c]);
            char* end = NULL;
            const int hex = (strchr(cell, 'x') != NULL) || (strchr(cell, 'X') != NULL);
            row[c] = strtod(cell, &end);
            if ((cell[0] == '\0') || (end == NULL) || (*end != '\0') || hex) {
                fail(err, es, "%s:%zu: column '%s': not a number: '%s'", path, lineno, header[c],
                     cell);
                rc = -1;
            } else if (!isfinite(row[c])) {
                fail(err, es, "%s:%zu: column '%s': not finite: '%s'", path, lineno, header[c],
                     cell);
                rc = -1;
            } else {
                /* a valid number */
            }
        }
        if (rc != 0) {
            break;
        }
        const double t = row[ti];
        if (!(t > prev_t)) {
            char a[40];
            char b[40];
            nte_py_repr(t, a, sizeof a);
            nte_py_repr(prev_t, b, sizeof b);
            fail(err, es, "%s:%zu: column '%s': time %s does not increase (previous %s)", path,
                 lineno, cols->t, a, b);
            rc = -1;
            break;
        }
        prev_t = t;
        if (push(tr, &cap, t, row[li], (vi >= 0) ? row[vi] : 0.0, row[fi], lineno) != 0) {
            fail(err, es, "%s:%zu: out of memory", path, lineno);
            rc = -1;
        }
        line = next;
    }
    free(text);
    if ((rc == 0) && (ncols == 0U)) {
        fail(err, es, "%s:1: no header line", path);
        rc = -1;
    }
    if ((rc == 0) && (tr->n == 0U)) {
        fail(err, es, "%s:%zu: no samples after the header", path, header_line + 1U);
        rc = -1;
    }
    if (rc != 0) {
        nte_trial_free(tr);
        return -1;
    }
    tr->velocity_given = (vi >= 0);
    if (vi < 0) {
        nte_central_difference(tr->t_s, tr->depth_mm, tr->n, tr->velocity_mm_s);
    }
    return 0;
}

void nte_trial_free(nte_trial_t* tr)
{
    free(tr->t_s);
    free(tr->depth_mm);
    free(tr->velocity_mm_s);
    free(tr->force_n);
    free(tr->line);
    memset(tr, 0, sizeof *tr);
}

void nte_trial_convert(nte_trial_t* tr, const nte_units_t* u)
{
    const double kt = u->time_factor;
    const double kd = u->depth_factor * (double)u->depth_sign;
    const double kf = u->force_factor * (double)u->force_sign;
    const double kv = kd / kt;
    for (size_t k = 0U; k < tr->n; k++) {
        tr->t_s[k] *= kt;
        tr->depth_mm[k] *= kd;
        tr->force_n[k] *= kf;
        if (tr->velocity_given != 0) {
            tr->velocity_mm_s[k] *= kv;
        }
    }
    if (tr->velocity_given == 0) {
        nte_central_difference(tr->t_s, tr->depth_mm, tr->n, tr->velocity_mm_s);
    }
}

void nte_central_difference(const double* t, const double* x, const size_t n, double* v)
{
    if (n < 2U) {
        for (size_t k = 0U; k < n; k++) {
            v[k] = 0.0;
        }
        return;
    }
    v[0] = (x[1] - x[0]) / (t[1] - t[0]);
    for (size_t k = 1U; k < (n - 1U); k++) {
        v[k] = (x[k + 1U] - x[k - 1U]) / (t[k + 1U] - t[k - 1U]);
    }
    v[n - 1U] = (x[n - 1U] - x[n - 2U]) / (t[n - 1U] - t[n - 2U]);
}

void nte_trial_sample(const nte_trial_t* tr, size_t k, int force_ignored, nte_sample_t* s)
{
    s->t_us = (int64_t)floor((tr->t_s[k] * 1e6) + 0.5);
    s->depth_mm = (nte_real_t)tr->depth_mm[k];
    s->velocity_mm_s = (nte_real_t)tr->velocity_mm_s[k];
    s->force_n = (force_ignored != 0) ? (nte_real_t)0 : (nte_real_t)tr->force_n[k];
}
