/*
 * --export-config's choice of parameter set: the snapshot that replays the record best from
 * depth alone.  Twin: reference_py/tools/export_select.py.
 */
#include "export_select.h"
#include "starts.h"

#include <math.h>
#include <string.h>

size_t nte_export_candidate_sample(size_t j, size_t n)
{
    const size_t k = ((j + 1U) * n) / NTE_EXPORT_CANDIDATES;
    return (k > 0U) ? (k - 1U) : 0U;
}

void nte_export_snapshot_values(const nte_export_snapshot_t* s, const double fixed[7], int model,
                                double params[7], double sd[7], double g[2], double g_sd[2],
                                const char* g_name[2], size_t* n_g)
{
    *n_g = 0U;
    for (size_t j = 0U; j < 7U; j++) {
        params[j] = fixed[j];
        sd[j] = 0.0;
    }
    for (size_t j = 0U; (j < s->np) && (j < NTE_IDENTIFIED_MAX); j++) {
        const size_t id = (size_t)s->pe[j].id;
        if (id < 7U) {
            params[id] = (double)s->pe[j].value;
            sd[id] = (double)s->pe[j].sd;
        } else if (*n_g < 2U) {
            g_name[*n_g] = nte_param_name(s->pe[j].id);
            g[*n_g] = (double)s->pe[j].value;
            g_sd[*n_g] = (double)s->pe[j].sd;
            (*n_g)++;
        }
    }
    if (model == 1) { /* Model I's beta is its fixed beta0 */
        params[6] = fixed[6];
    }
}

/* The configuration a reader of the exported file builds (nte_run.c main): the exported values
 * as the nominal (nte_set_nominal, as main does); the strengths as given; predict-only; the
 * known surface.  Returns -1 when the values are refused (not expected: the run accepted
 * values of the same form). */
static int reader_config(const nte_config_t* run_cfg, const double params[7], const double g[2],
                         size_t n_g, double surface_mm, nte_config_t* cfg)
{
    *cfg = *run_cfg;
    if (nte_set_nominal(cfg, params) != 0) {
        return -1;
    }
    for (size_t k = 0U; k < n_g; k++) {
        cfg->nominal[7U + k] = (nte_real_t)g[k];
    }
    cfg->predict_only = true;
    if (cfg->contact.enabled) {
        cfg->contact.surface_mm = (nte_real_t)surface_mm;
    }
    return 0;
}

int nte_export_choose(const nte_config_t* run_cfg, const nte_trial_t* tr,
                      const nte_export_snapshot_t snaps[NTE_EXPORT_CANDIDATES],
                      const double fixed[7], int model, double surface_mm, double tare_n,
                      nte_t* scratch, nte_export_choice_t* out)
{
    out->candidate = NTE_EXPORT_CANDIDATES - 1U;
    out->rmse_n = (double)NAN;
    out->final_rmse_n = (double)NAN;
    out->peak_n = (double)NAN;
    if (run_cfg->contact.enabled && !isfinite(surface_mm)) {
        return 0; /* no surface: a reader could not predict from this file either */
    }
    double rmse[NTE_EXPORT_CANDIDATES];
    double peak = 0.0;
    for (size_t c = 0U; c < NTE_EXPORT_CANDIDATES; c++) {
        double params[7];
        double sd[7];
        double g[2];
        double g_sd[2];
        const char* g_name[2];
        size_t n_g = 0U;
        nte_export_snapshot_values(&snaps[c], fixed, model, params, sd, g, g_sd, g_name, &n_g);
        nte_config_t cfg;
        if ((reader_config(run_cfg, params, g, n_g, surface_mm, &cfg) != 0) ||
            (nte_init(scratch, &cfg) != nte_err_ok)) {
            return -1;
        }
        double sum = 0.0;
        size_t counted = 0U;
        for (size_t k = 0U; k < tr->n; k++) {
            nte_sample_t s;
            nte_output_t o;
            s.t_us = (int64_t)floor((tr->t_s[k] * 1e6) + 0.5);
            s.depth_mm = (nte_real_t)tr->depth_mm[k];
            s.velocity_mm_s = (nte_real_t)tr->velocity_mm_s[k];
            s.force_n = (nte_real_t)0; /* predict-only: the force is ignored */
            (void)nte_step(scratch, &s, &o);
            const double f = tr->force_n[k];
            if (!isfinite(f)) {
                continue;
            }
            const double target = f - tare_n;
            const double e = (double)o.force_hat_n - target;
            sum = sum + (e * e);
            counted++;
            if ((c == 0U) && (fabs(target) > peak)) {
                peak = fabs(target);
            }
        }
        rmse[c] = (counted > 0U) ? sqrt(sum / (double)counted) : (double)NAN;
    }
    size_t best = 0U;
    for (size_t c = 1U; c < NTE_EXPORT_CANDIDATES; c++) {
        if (rmse[c] < rmse[best]) {
            best = c;
        }
    }
    out->candidate = best;
    out->rmse_n = rmse[best];
    out->final_rmse_n = rmse[NTE_EXPORT_CANDIDATES - 1U];
    out->peak_n = peak;
    return 0;
}
