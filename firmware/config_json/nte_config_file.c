/*
 * The estimator configuration file: the C twin of reference_py/tools/estconfig.py (read that
 * file's top comment for the mapping).  Shared by the host programs (nte-run) and the Linux
 * port (nte-node); cJSON is its only dependency besides libc.  Every check below has its twin there, in the same
 * order, with the same text: a file is accepted or refused alike by nte-ref and nte-run.
 */
#include "nte_config_file.h"

#include "nte.h"
#include "nte_constants.h"
#include "nte_file_in.h"

#include <cjson/cJSON.h>

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SCHEMA "nte-estimator-config/1"
#define PARAM_MAX 1000.0 /* config.NOMINAL_ABS_MAX */
/* |surface_mm|: a stage position, within the configuration's depth range (generated from
 * reference_py/config.py, the envelope's one source; estconfig.SURFACE_MAX_MM) */
#define SURFACE_MAX_MM ((double)NTE_K_DEF_DEPTH_MAX_MM)
/* RELAX_NOMINAL: the split of a relative decay between the two strengths */
#define G_FAST_NOMINAL 0.15
#define G_SLOW_NOMINAL 0.25

static const char* const param_names[7] = {"sigma0", "sigma1", "sigma2", "f1",
                                           "f2",     "alpha",  "beta"};
/* LAYER_SET_NAMES, the order of nte_layer_set_t.values */
static const char* const layer_names[NTE_LAYER_SET_VALUES] = {"sigma0", "f1", "beta", "sigma2"};

typedef struct reader_t {
    const char* path;
    char* msg;
    size_t cap;
} reader_t;

/* "FILE: key 'KEY': reason"; returns -1 for the caller to pass on */
static int fail(const reader_t* r, const char* key, const char* fmt, ...)
{
    char why[256];
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(why, sizeof why, fmt, ap);
    va_end(ap);
    (void)snprintf(r->msg, r->cap, "%s: key '%s': %s", r->path, key, why);
    return -1;
}

/* a finite JSON number (estconfig._is_num: true/false are not numbers) */
static int is_num(const cJSON* v)
{
    return (v != NULL) && cJSON_IsNumber(v) && isfinite(v->valuedouble);
}

/* an integral number in lo..hi (the reference's `v in (1, 2, 3)`; 2.0 counts as 2) */
static int is_int_in(const cJSON* v, double lo, double hi)
{
    return is_num(v) && (v->valuedouble >= lo) && (v->valuedouble <= hi) &&
           !(floor(v->valuedouble) < v->valuedouble);
}

static const cJSON* item(const cJSON* obj, const char* key)
{
    return cJSON_GetObjectItemCaseSensitive(obj, key);
}

/* estconfig's number(): absent or null -> 0 (not given), 1 (value in *x), -1 refused */
static int number(const reader_t* r, const cJSON* obj, const char* key, const char* name, double lo,
                  double hi, double* x)
{
    const cJSON* v = item(obj, key);
    if ((v == NULL) || cJSON_IsNull(v)) {
        return 0;
    }
    if (!is_num(v) || !(v->valuedouble > lo) || (v->valuedouble > hi)) {
        if (isfinite(hi)) {
            return fail(r, name, "must be a number > %g and <= %g", lo, hi);
        }
        return fail(r, name, "must be a number > %g", lo);
    }
    *x = v->valuedouble;
    return 1;
}

/* estconfig's section(): absent or null -> 0, an object -> 1 (*sec), else -1 */
static int section(const reader_t* r, const cJSON* obj, const char* key, const char* name,
                   const cJSON** sec)
{
    const cJSON* v = item(obj, key);
    if ((v == NULL) || cJSON_IsNull(v)) {
        return 0;
    }
    if (!cJSON_IsObject(v)) {
        return fail(r, name, "must be an object");
    }
    *sec = v;
    return 1;
}

/* estconfig._layer_sets: at most NTE_FILE_LAYER_SETS objects in depth order, each a start
 * (> 0, <= the depth range, above the previous) and the four positive values, g(0) > 0 with
 * the file's f2 (out->params read) */
static int layer_sets(const reader_t* r, const cJSON* items, nte_file_config_t* out)
{
    if (!cJSON_IsArray(items) || (cJSON_GetArraySize(items) > NTE_FILE_LAYER_SETS)) {
        return fail(r, "model3.layer_sets", "must be a list of at most %d objects",
                    NTE_FILE_LAYER_SETS);
    }
    const double f2 = out->params[4];
    double previous = 0.0;
    int k = 0;
    const cJSON* set = NULL;
    cJSON_ArrayForEach(set, items)
    {
        char key[64];
        (void)snprintf(key, sizeof key, "model3.layer_sets[%d]", k);
        if (!cJSON_IsObject(set)) {
            return fail(r, key, "must be an object");
        }
        char name[80];
        (void)snprintf(name, sizeof name, "%s.start_mm", key);
        const cJSON* start = item(set, "start_mm");
        if (!(is_num(start) && (start->valuedouble > 0.0) &&
              (start->valuedouble <= SURFACE_MAX_MM))) {
            return fail(r, name, "must be a number > 0 and <= %g", SURFACE_MAX_MM);
        }
        if (!(start->valuedouble > previous)) {
            return fail(r, name, "must be above the previous layer's start_mm");
        }
        previous = start->valuedouble;
        out->layer_start_mm[k] = previous;
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            const cJSON* v = item(set, layer_names[j]);
            if (!(is_num(v) && (v->valuedouble > 0.0) && (v->valuedouble <= PARAM_MAX))) {
                (void)snprintf(name, sizeof name, "%s.%s", key, layer_names[j]);
                return fail(r, name, "must be a positive number <= %g", PARAM_MAX);
            }
            out->layer_values[k][j] = v->valuedouble;
        }
        if ((f2 < 0.0) && !((out->layer_values[k][nte_layer_f1] + f2) > 0.0)) {
            (void)snprintf(name, sizeof name, "%s.f1", key);
            return fail(r, name, "g(0) = f1 + f2 must be > 0");
        }
        k++;
    }
    out->layer_sets = k;
    return 0;
}

static int check(const reader_t* r, const cJSON* doc, nte_file_config_t* out)
{
    const cJSON* schema = item(doc, "schema");
    if (!cJSON_IsString(schema) || (strcmp(schema->valuestring, SCHEMA) != 0)) {
        return fail(r, "schema", "must be \"" SCHEMA "\"");
    }
    const cJSON* m = item(doc, "model");
    if (m == NULL) {
        return fail(r, "model", "missing");
    }
    if (!is_int_in(m, 1.0, 3.0)) {
        return fail(r, "model", "must be 1, 2 or 3");
    }
    out->model = (int)m->valuedouble;
    const cJSON* ps = item(doc, "params");
    if (ps == NULL) {
        return fail(r, "params", "missing");
    }
    if (!cJSON_IsObject(ps)) {
        return fail(r, "params", "must be an object");
    }
    for (size_t j = 0U; j < 7U; j++) {
        char key[32];
        (void)snprintf(key, sizeof key, "params.%s", param_names[j]);
        const cJSON* v = item(ps, param_names[j]);
        if (v == NULL) {
            return fail(r, key, "missing");
        }
        if (j != 4U) { /* every parameter but f2 keeps a positive sign */
            if (!is_num(v) || !(v->valuedouble > 0.0) || (v->valuedouble > PARAM_MAX)) {
                return fail(r, key, "must be a positive number <= %g", PARAM_MAX);
            }
        } else if (!is_num(v) || (fabs(v->valuedouble) > PARAM_MAX)) {
            return fail(r, key, "must be a number with |x| <= %g", PARAM_MAX);
        }
        out->params[j] = v->valuedouble;
    }
    if ((out->params[4] < 0.0) && !((out->params[3] + out->params[4]) > 0.0)) {
        return fail(r, "params.f1", "g(0) = f1 + f2 must be > 0");
    }
    int got = number(r, doc, "r_n2", "r_n2", 0.0, (double)INFINITY, &out->r_n2);
    if (got < 0) {
        return -1;
    }
    out->has_r_n2 = got;

    const cJSON* s = item(doc, "surface_mm");
    if (cJSON_IsArray(s)) {
        const cJSON* x = NULL;
        cJSON_ArrayForEach(x, s)
        {
            if (!cJSON_IsNull(x) && !(is_num(x) && (fabs(x->valuedouble) <= SURFACE_MAX_MM))) {
                return fail(r, "surface_mm",
                            "must be a number with |x| <= %g, null or a list "
                            "of them",
                            SURFACE_MAX_MM);
            }
        }
        out->surface_list = 1;
    } else if ((s != NULL) && !cJSON_IsNull(s)) {
        if (!(is_num(s) && (fabs(s->valuedouble) <= SURFACE_MAX_MM))) {
            return fail(r, "surface_mm",
                        "must be a number with |x| <= %g, null or a list of "
                        "them",
                        SURFACE_MAX_MM);
        }
        out->has_surface = 1;
        out->surface_mm = s->valuedouble;
    }
    const cJSON* t = item(doc, "tare_n");
    int tare_ok = (t == NULL) || cJSON_IsNull(t) || is_num(t);
    if (cJSON_IsArray(t)) {
        tare_ok = 1;
        const cJSON* x = NULL;
        cJSON_ArrayForEach(x, t) { tare_ok = tare_ok && (cJSON_IsNull(x) || is_num(x)); }
    }
    if (!tare_ok) {
        return fail(r, "tare_n", "must be a number, null or a list of them");
    }

    const cJSON* eff = NULL;
    got = section(r, doc, "effects", "effects", &eff);
    if (got < 0) {
        return -1;
    }
    if (got > 0) {
        const cJSON* dw = NULL;
        got = section(r, eff, "dwell_relaxation", "effects.dwell_relaxation", &dw);
        if (got < 0) {
            return -1;
        }
        if (got > 0) {
            got = number(r, dw, "tau_fast_s", "effects.dwell_relaxation.tau_fast_s", 0.0, 3600.0,
                         &out->tau_fast_s);
            if (got < 0) {
                return -1;
            }
            out->has_tau_fast = out->has_tau_fast || got;
            got = number(r, dw, "tau_slow_s", "effects.dwell_relaxation.tau_slow_s", 0.0, 3600.0,
                         &out->tau_slow_s);
            if (got < 0) {
                return -1;
            }
            out->has_tau_slow = out->has_tau_slow || got;
            const cJSON* rd = item(dw, "relative_decay_median");
            if ((rd != NULL) && !cJSON_IsNull(rd)) {
                if (!(is_num(rd) && (rd->valuedouble > 0.0) && (rd->valuedouble < 1.0))) {
                    return fail(r, "effects.dwell_relaxation.relative_decay_median",
                                "must be a number > 0 and < 1, or null");
                }
                /* the reference's float(rd) * RELAX_NOMINAL[nm] / total, same order */
                const double total = G_FAST_NOMINAL + G_SLOW_NOMINAL;
                out->g[0] = (rd->valuedouble * G_FAST_NOMINAL) / total;
                out->g[1] = (rd->valuedouble * G_SLOW_NOMINAL) / total;
                out->has_strengths = 1;
            }
        }
        const cJSON* pr = NULL;
        got = section(r, eff, "reversal_presliding", "effects.reversal_presliding", &pr);
        if (got < 0) {
            return -1;
        }
        if (got > 0) {
            got = number(r, pr, "presliding_mm", "effects.reversal_presliding.presliding_mm", 0.0,
                         1000.0, &out->presliding_mm);
            if (got < 0) {
                return -1;
            }
            out->has_presliding = out->has_presliding || got;
        }
    }

    const cJSON* m3 = NULL;
    got = section(r, doc, "model3", "model3", &m3);
    if (got < 0) {
        return -1;
    }
    if (got > 0) {
        static const char* const flags[2] = {"direction_memory", "relaxation"};
        for (size_t k = 0U; k < 2U; k++) {
            const cJSON* v = item(m3, flags[k]);
            if ((v == NULL) || cJSON_IsNull(v)) {
                continue;
            }
            if (!cJSON_IsBool(v)) {
                char key[40];
                (void)snprintf(key, sizeof key, "model3.%s", flags[k]);
                return fail(r, key, "must be true or false");
            }
            if (k == 0U) {
                out->has_direction_memory = 1;
                out->direction_memory = cJSON_IsTrue(v) ? 1 : 0;
            } else {
                out->has_relaxation = 1;
                out->relaxation = cJSON_IsTrue(v) ? 1 : 0;
            }
        }
        const cJSON* rb = item(m3, "relax_branches");
        if ((rb != NULL) && !cJSON_IsNull(rb)) {
            if (!is_int_in(rb, 1.0, 2.0)) {
                return fail(r, "model3.relax_branches", "must be 1 or 2");
            }
            out->has_relax_branches = 1;
            out->relax_branches = (int)rb->valuedouble;
        }
        got = number(r, m3, "presliding_mm", "model3.presliding_mm", 0.0, 1000.0,
                     &out->presliding_mm);
        if (got < 0) {
            return -1;
        }
        out->has_presliding = out->has_presliding || got;
        got = number(r, m3, "tau_fast_s", "model3.tau_fast_s", 0.0, 3600.0, &out->tau_fast_s);
        if (got < 0) {
            return -1;
        }
        out->has_tau_fast = out->has_tau_fast || got;
        got = number(r, m3, "tau_slow_s", "model3.tau_slow_s", 0.0, 3600.0, &out->tau_slow_s);
        if (got < 0) {
            return -1;
        }
        out->has_tau_slow = out->has_tau_slow || got;
        const cJSON* ls = item(m3, "layer_sets");
        if ((ls != NULL) && !cJSON_IsNull(ls) && (layer_sets(r, ls, out) < 0)) {
            return -1;
        }
        const cJSON* st = NULL;
        got = section(r, m3, "strengths", "model3.strengths", &st);
        if (got < 0) {
            return -1;
        }
        if (got > 0) {
            static const char* const names[2] = {"g_fast", "g_slow"};
            for (size_t k = 0U; k < 2U; k++) {
                const cJSON* v = item(st, names[k]);
                if ((v == NULL) || cJSON_IsNull(v)) {
                    continue;
                }
                if (!(is_num(v) && (v->valuedouble > 0.0) && (v->valuedouble < 1.0))) {
                    char key[40];
                    (void)snprintf(key, sizeof key, "model3.strengths.%s", names[k]);
                    return fail(r, key, "must be a number > 0 and < 1");
                }
                if (!out->has_strengths) { /* the other one keeps its nominal */
                    out->g[0] = G_FAST_NOMINAL;
                    out->g[1] = G_SLOW_NOMINAL;
                    out->has_strengths = 1;
                }
                out->g[k] = v->valuedouble;
            }
        }
    }
    if (out->has_strengths && !((out->g[0] + out->g[1]) < 1.0)) {
        return fail(r, "model3.strengths", "g_fast + g_slow must be < 1");
    }
    return 0;
}

int nte_config_file_read(const char* path, nte_file_config_t* out, char* msg, size_t cap)
{
    reader_t r = {path, msg, cap};
    (void)memset(out, 0, sizeof *out);
    size_t len = 0U;
    char* buf = nte_file_read_all(path, &len);
    if (buf == NULL) {
        (void)snprintf(msg, cap, "%s: cannot read: %s", path, strerror(errno));
        return -1;
    }
    const char* end = NULL;
    /* the whole file one JSON value (json.loads: trailing whitespace only) */
    cJSON* doc = (strlen(buf) == len) ? cJSON_ParseWithOpts(buf, &end, 1) : NULL;
    free(buf);
    if (doc == NULL) {
        (void)snprintf(msg, cap, "%s: not valid JSON", path);
        return -1;
    }
    int rc = 0;
    if (!cJSON_IsObject(doc)) {
        (void)snprintf(msg, cap, "%s: not a JSON object", path);
        rc = -1;
    } else {
        rc = check(&r, doc, out);
    }
    cJSON_Delete(doc);
    return rc;
}
