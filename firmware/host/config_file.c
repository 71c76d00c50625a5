/*
 * --export-config of nte-run: the configuration as the reference's json.dumps(indent=2)
 * writes it (reference_py/tools/estimate.py export_config).
 */
#include "config_file.h"
#include "csv_in.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define SCHEMA "nte-estimator-config/1"

static const char* const param_names[7] = {"sigma0", "sigma1", "sigma2", "f1",
                                           "f2",     "alpha",  "beta"};

typedef struct text_t {
    char* buf;
    size_t cap;
    size_t len;
    int overflow;
} text_t;

static void put(text_t* t, const char* fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    const int n = vsnprintf(t->buf + t->len, t->cap - t->len, fmt, ap);
    va_end(ap);
    if ((n < 0) || ((size_t)n >= (t->cap - t->len))) {
        t->overflow = 1;
        return;
    }
    t->len += (size_t)n;
}

static void put_real(text_t* t, const char* indent, const char* key, double x, int last)
{
    char r[40];
    if (isfinite(x)) {
        nte_py_repr(x, r, sizeof r); /* name_value.h: Python's repr, the reference's floats */
    } else {
        (void)snprintf(r, sizeof r, "null");
    }
    put(t, "%s\"%s\": %s%s\n", indent, key, r, last ? "" : ",");
}

/* model3.layer_sets as json.dumps(indent=2) writes estimate.py's list of objects */
static void put_layer_sets(text_t* t, const nte_export_t* e)
{
    static const char* const names[4] = {"sigma0", "f1", "beta", "sigma2"};
    put(t, "    \"layer_sets\": [\n");
    for (size_t k = 0U; k < e->n_sets; k++) {
        put(t, "      {\n");
        put_real(t, "        ", "start_mm", e->set_start_mm[k], 0);
        for (size_t j = 0U; j < 4U; j++) {
            put_real(t, "        ", names[j], e->set_values[k][j], 0);
        }
        put(t, "        \"sd\": {\n");
        for (size_t j = 0U; j < 4U; j++) {
            put_real(t, "          ", names[j], e->set_sd[k][j], j == 3U);
        }
        put(t, "        }\n      }%s\n", (k + 1U < e->n_sets) ? "," : "");
    }
    put(t, "    ]\n");
}

int nte_config_file_export_text(const nte_export_t* e, char* buf, size_t cap)
{
    text_t t = {buf, cap, 0U, 0};
    put(&t, "{\n  \"schema\": \"" SCHEMA "\",\n  \"source\": \"%s\",\n  \"model\": %d,\n",
        e->source, e->model);
    for (int block = 0; block < 2; block++) {
        put(&t, "  \"%s\": {\n", (block == 0) ? "params" : "params_sd");
        for (size_t j = 0U; j < 7U; j++) {
            put_real(&t, "    ", param_names[j], (block == 0) ? e->params[j] : e->sd[j], j == 6U);
        }
        put(&t, "  },\n");
    }
    put_real(&t, "  ", "r_n2", e->r_n2, 0);
    put(&t, "  \"samples\": %zu,\n  \"replay\": {\n", e->samples);
    put_real(&t, "    ", "t_s", e->replay_t_s, 0);
    put(&t, "    \"candidates\": %u,\n", e->replay_candidates);
    put_real(&t, "    ", "rmse_n", e->replay_rmse_n, 0);
    put_real(&t, "    ", "final_rmse_n", e->replay_final_rmse_n, 0);
    put_real(&t, "    ", "peak_n", e->replay_peak_n, 0);
    put_real(&t, "    ", "fit_rmse_n", e->fit_rmse_n, 0);
    put(&t, "    \"fit_passes\": %u\n", e->fit_passes);
    put(&t, "  }%s\n", ((e->model == 3) || e->contact) ? "," : "");
    if (e->model == 3) {
        put(&t, "  \"model3\": {\n    \"direction_memory\": %s,\n",
            e->direction_memory ? "true" : "false");
        put_real(&t, "    ", "presliding_mm", e->presliding_mm, 0);
        put(&t, "    \"relaxation\": %s,\n    \"relax_branches\": %d,\n",
            e->relaxation ? "true" : "false", e->relax_branches);
        put_real(&t, "    ", "tau_fast_s", e->tau_fast_s, 0);
        put_real(&t, "    ", "tau_slow_s", e->tau_slow_s, 0);
        for (int block = 0; block < 2; block++) {
            put(&t, "    \"%s\": ", (block == 0) ? "strengths" : "strengths_sd");
            if (e->n_g == 0U) {
                put(&t, "{}%s\n", ((block == 0) || (e->n_sets > 0U)) ? "," : "");
                continue;
            }
            put(&t, "{\n");
            for (size_t k = 0U; k < e->n_g; k++) {
                put_real(&t, "      ", e->g_name[k], (block == 0) ? e->g[k] : e->g_sd[k],
                         k + 1U == e->n_g);
            }
            put(&t, "    }%s\n", ((block == 0) || (e->n_sets > 0U)) ? "," : "");
        }
        if (e->n_sets > 0U) {
            put_layer_sets(&t, e);
        }
        put(&t, "  }%s\n", e->contact ? "," : "");
    }
    if (e->contact) {
        put_real(&t, "  ", "surface_mm", e->surface_mm, 0);
        put_real(&t, "  ", "tare_n", e->tare_n, 1);
    }
    put(&t, "}\n");
    return t.overflow ? -1 : (int)t.len;
}
