/*
 * --export-config's choice of parameter set: the snapshot that replays the record best from
 * depth alone, fitted to it (and fitted again from the record's first relaxation strengths
 * when that misses).  Twin: reference_py/tools/export_select.py.
 */
#include "export_select.h"
#include "export_replay.h"

#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
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
        } else if (((id == (size_t)nte_param_g_fast) || (id == (size_t)nte_param_g_slow)) &&
                   (*n_g < 2U)) {
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

static void keep_snapshot(const nte_export_snapshot_t* s, const double fixed[7], int model,
                          nte_export_choice_t* out)
{
    nte_export_snapshot_values(s, fixed, model, out->params, out->sd, out->g, out->g_sd,
                               out->g_name, &out->n_g);
}

void nte_export_layers_start(nte_export_layers_t* acc) { (void)memset(acc, 0, sizeof *acc); }

void nte_export_layers_add(nte_export_layers_t* acc, size_t k, double depth_mm, int contact,
                           int with_layer, const nte_output_t* o)
{
    const unsigned prev = acc->prev_layer;
    acc->prev_layer = (unsigned)o->layer;
    if ((with_layer == 0) || (k == 0U) || (acc->done != 0)) {
        return;
    }
    double depth = depth_mm;
    if (contact != 0) {
        const double surface = (double)o->surface_mm;
        depth = isfinite(surface) ? (depth_mm - surface) : 0.0;
    }
    if (depth > 0.0) {
        acc->entered = 1;
    } else if (acc->entered != 0) {
        acc->done = 1; /* the first insertion ended */
        return;
    }
    if (((unsigned)o->layer > prev) && (depth > 0.0) &&
        ((acc->count == 0U) || (depth > acc->start_mm[acc->count - 1U])) &&
        (acc->count < NTE_LAYER_SETS_MAX)) {
        acc->start_mm[acc->count] = depth;
        acc->count++;
    }
}

/* The fit again with a layer set at each start, all from the fitted values (export_select.py
 * choose_export): kept when its replay is closer.  Returns -1 as nte_export_refine. */
static int fit_layers(const nte_config_t* replay_cfg, const nte_trial_t* tr,
                      const nte_export_layers_t* layers, const bool fitted[NTE_EXPORT_ROW_MAX],
                      size_t row_len, double surface_mm, double tare_n, nte_t* scratch,
                      nte_export_fit_t* fit, nte_export_choice_t* out)
{
    static const size_t ids[NTE_LAYER_SET_VALUES] = {(size_t)nte_param_sigma0, (size_t)nte_param_f1,
                                                     (size_t)nte_param_beta,
                                                     (size_t)nte_param_sigma2};
    nte_config_t cfg = *replay_cfg;
    double row[NTE_EXPORT_ROW_MAX];
    bool moved[NTE_EXPORT_ROW_MAX];
    (void)memcpy(row, fit->row, row_len * sizeof row[0]);
    (void)memcpy(moved, fitted, sizeof moved);
    cfg.layer_sets = (uint32_t)layers->count;
    size_t len = row_len;
    for (size_t k = 0U; k < layers->count; k++) {
        cfg.layer_set[k].start_mm = (nte_real_t)layers->start_mm[k];
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            cfg.layer_set[k].values[j] = (nte_real_t)fit->row[ids[j]];
            row[len] = fit->row[ids[j]];
            moved[len] = true;
            len++;
        }
    }
    nte_export_fit_t layered;
    if (nte_export_refine(&cfg, tr, row, len, moved, surface_mm, tare_n, scratch, &layered) != 0) {
        return -1;
    }
    const unsigned passes = fit->passes + layered.passes;
    if (layered.rmse_n < fit->rmse_n) {
        out->n_sets = layers->count;
        for (size_t k = 0U; k < layers->count; k++) {
            out->set_start_mm[k] = layers->start_mm[k];
            for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
                const size_t e = row_len + (k * NTE_LAYER_SET_VALUES) + j;
                out->set_values[k][j] = layered.row[e];
                out->set_sd[k][j] = layered.has_sd[e] ? layered.sd[e] : (double)NAN;
            }
        }
        *fit = layered; /* its first row_len entries: the seven and the strengths */
    }
    fit->passes = passes;
    return 0;
}

/* The fit of one row (export_refine.h) from snapshot `snap`: it moves the identified values,
 * the seven's (Model I's beta is its fixed beta0), then every strength; `fitted` says which. */
static int fit_row(const nte_config_t* replay_cfg, const nte_trial_t* tr,
                   const nte_export_snapshot_t* snap, int model, const double* row, size_t row_len,
                   double surface_mm, double tare_n, nte_t* scratch,
                   bool fitted[NTE_EXPORT_ROW_MAX], nte_export_fit_t* fit)
{
    for (size_t j = 0U; j < NTE_EXPORT_ROW_MAX; j++) {
        fitted[j] = (j >= 7U) && (j < row_len);
    }
    for (size_t j = 0U; (j < snap->np) && (j < NTE_IDENTIFIED_MAX); j++) {
        const size_t id = (size_t)snap->pe[j].id;
        if ((id < 7U) && !((model == 1) && (id == (size_t)nte_param_beta))) {
            fitted[id] = true;
        }
    }
    return nte_export_refine(replay_cfg, tr, row, row_len, fitted, surface_mm, tare_n, scratch,
                             fit);
}

/* fit_row, then the layer sets (fit_layers) when the record's first insertion tore: `fit` and
 * `out`'s sets are what this start gives. */
static int fit_with_sets(const nte_config_t* replay_cfg, const nte_trial_t* tr,
                         const nte_export_snapshot_t* snap, int model, const double* row,
                         size_t row_len, const nte_export_layers_t* layers, double surface_mm,
                         double tare_n, nte_t* scratch, bool fitted[NTE_EXPORT_ROW_MAX],
                         nte_export_fit_t* fit, nte_export_choice_t* out)
{
    if (fit_row(replay_cfg, tr, snap, model, row, row_len, surface_mm, tare_n, scratch, fitted,
                fit) != 0) {
        return -1;
    }
    if ((layers != NULL) && (layers->count > 0U)) {
        return fit_layers(replay_cfg, tr, layers, fitted, row_len, surface_mm, tare_n, scratch, fit,
                          out);
    }
    return 0;
}

int nte_export_choose(const nte_config_t* run_cfg, const nte_trial_t* tr,
                      const nte_export_snapshot_t snaps[NTE_EXPORT_CANDIDATES],
                      const nte_export_layers_t* layers, const double fixed[7], int model,
                      double surface_mm, double tare_n, nte_t* scratch, nte_export_choice_t* out)
{
    /* Model III's turn-over length as identified by the end of the record (it is learned from
     * the turn-overs only): every replay and the fit run with it, and it is exported */
    nte_config_t replay_cfg = *run_cfg;
    const nte_export_snapshot_t* last = &snaps[NTE_EXPORT_CANDIDATES - 1U];
    for (size_t j = 0U; (j < last->np) && (j < NTE_IDENTIFIED_MAX); j++) {
        if (last->pe[j].id == nte_param_delta) {
            replay_cfg.presliding_mm = last->pe[j].value;
        }
    }
    out->presliding_mm = (double)replay_cfg.presliding_mm;
    out->candidate = NTE_EXPORT_CANDIDATES - 1U;
    out->rmse_n = (double)NAN;
    out->final_rmse_n = (double)NAN;
    out->peak_n = (double)NAN;
    out->fit_rmse_n = (double)NAN;
    out->fit_passes = 0U;
    out->restart_from_rmse_n = (double)NAN;
    out->n_sets = 0U;
    keep_snapshot(&snaps[out->candidate], fixed, model, out);
    if (replay_cfg.contact.enabled && !isfinite(surface_mm)) {
        return 0; /* no surface: a reader could not predict from this file either */
    }
    double* res = malloc((tr->n > 0U ? tr->n : 1U) * sizeof(double));
    if (res == NULL) {
        return -1;
    }
    double rmse[NTE_EXPORT_CANDIDATES];
    double row[NTE_EXPORT_CANDIDATES][NTE_EXPORT_ROW_MAX];
    size_t row_len = 7U;
    nte_export_replay_t rep = {0U, 0.0};
    for (size_t c = 0U; c < NTE_EXPORT_CANDIDATES; c++) {
        nte_export_choice_t v;
        keep_snapshot(&snaps[c], fixed, model, &v);
        row_len = 7U + v.n_g;
        for (size_t j = 0U; j < row_len; j++) {
            row[c][j] = (j < 7U) ? v.params[j] : v.g[j - 7U];
        }
        if (nte_export_replay(&replay_cfg, tr, row[c], row_len, surface_mm, tare_n, scratch, res,
                              &rep) != 0) {
            free(res);
            return -1;
        }
        double sum = 0.0;
        for (size_t k = 0U; k < rep.counted; k++) {
            sum = sum + (res[k] * res[k]);
        }
        rmse[c] = (rep.counted > 0U) ? sqrt(sum / (double)rep.counted) : (double)NAN;
    }
    free(res);
    size_t best = 0U;
    for (size_t c = 1U; c < NTE_EXPORT_CANDIDATES; c++) {
        if (rmse[c] < rmse[best]) {
            best = c;
        }
    }
    out->candidate = best;
    out->rmse_n = rmse[best];
    out->final_rmse_n = rmse[NTE_EXPORT_CANDIDATES - 1U];
    out->peak_n = rep.peak_n; /* the same over every replay: the record's */
    keep_snapshot(&snaps[best], fixed, model, out);
    if (rep.counted == 0U) {
        return 0;
    }
    bool fitted[NTE_EXPORT_ROW_MAX];
    nte_export_fit_t fit;
    if (fit_with_sets(&replay_cfg, tr, &snaps[best], model, row[best], row_len, layers, surface_mm,
                      tare_n, scratch, fitted, &fit, out) != 0) {
        return -1;
    }
    if ((row_len > 7U) && (fit.rmse_n > (NTE_EXPORT_RESTART_FRACTION * rep.peak_n))) {
        /* the strengths may have collapsed in a minimum of their own: the same snapshot again
         * with the first snapshot's strengths, the closer result kept (export_select.py
         * choose_export) */
        double restart[NTE_EXPORT_ROW_MAX];
        (void)memcpy(restart, row[best], row_len * sizeof restart[0]);
        for (size_t j = 7U; j < row_len; j++) {
            restart[j] = row[0][j];
        }
        nte_export_choice_t again_out = *out;
        again_out.n_sets = 0U;
        nte_export_fit_t again;
        if (fit_with_sets(&replay_cfg, tr, &snaps[best], model, restart, row_len, layers,
                          surface_mm, tare_n, scratch, fitted, &again, &again_out) != 0) {
            return -1;
        }
        const unsigned passes = fit.passes + again.passes;
        const double first_rmse_n = fit.rmse_n;
        if (again.rmse_n < fit.rmse_n) {
            fit = again;
            *out = again_out;
        }
        fit.passes = passes;
        out->restart_from_rmse_n = first_rmse_n;
    }
    for (size_t j = 0U; j < row_len; j++) {
        const double sd = fit.has_sd[j] ? fit.sd[j] : ((j < 7U) ? out->sd[j] : out->g_sd[j - 7U]);
        if (j < 7U) {
            out->params[j] = fit.row[j];
            out->sd[j] = fitted[j] ? sd : out->sd[j];
        } else {
            out->g[j - 7U] = fit.row[j];
            out->g_sd[j - 7U] = sd;
        }
    }
    out->fit_rmse_n = fit.rmse_n;
    out->fit_passes = fit.passes;
    return 0;
}
