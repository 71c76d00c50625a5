/*
 * A reader's replay of an exported parameter set.  Twin: reference_py/tools/export_replay.py.
 */
#include "export_replay.h"
#include "nte_preset_config.h"
#include "starts.h"

#include <math.h>

/* The configuration a reader of the exported file builds (nte_run.c main): the values as the
 * nominal (nte_preset_nominal, as main does), the strengths as given, the layer sets' values at
 * the run's starts, predict-only, the known surface when the front end is on. */
static int reader_config(const nte_config_t* run_cfg, const double* row, size_t row_len,
                         double surface_mm, nte_config_t* cfg)
{
    *cfg = *run_cfg;
    const size_t tail = NTE_LAYER_SET_VALUES * (size_t)run_cfg->layer_sets;
    if ((row_len < (7U + tail)) || (row_len > NTE_EXPORT_ROW_MAX) ||
        (nte_preset_nominal(cfg, row) != 0)) {
        return -1;
    }
    const size_t base_len = row_len - tail;
    for (size_t k = 7U; k < base_len; k++) {
        cfg->nominal[k] = (nte_real_t)row[k];
    }
    for (size_t k = 0U; k < run_cfg->layer_sets; k++) {
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            cfg->layer_set[k].values[j] =
                (nte_real_t)row[base_len + (k * NTE_LAYER_SET_VALUES) + j];
        }
    }
    cfg->predict_only = true;
    if (cfg->contact.enabled) {
        cfg->contact.surface_mm = (nte_real_t)surface_mm;
    }
    return 0;
}

/* One replay of the reader's configuration, appending to res from out->counted on. */
static int replay_once(const nte_config_t* cfg, const nte_trial_t* tr, double tare_n,
                       nte_t* scratch, double* res, nte_export_replay_t* out)
{
    if (nte_init(scratch, cfg) != nte_err_ok) {
        return -1;
    }
    for (size_t k = 0U; k < tr->n; k++) {
        nte_sample_t s;
        nte_output_t o;
        nte_trial_sample(tr, k, 1, &s);
        (void)nte_step(scratch, &s, &o);
        const double f = tr->force_n[k];
        if (!isfinite(f)) {
            continue;
        }
        const double target = f - tare_n;
        if (fabs(target) > out->peak_n) {
            out->peak_n = fabs(target);
        }
        if (res != NULL) {
            res[out->counted] = (double)o.force_hat_n - target;
        }
        out->counted++;
    }
    return 0;
}

int nte_export_replay(const nte_config_t* run_cfg, const nte_trial_t* tr, const double* row,
                      size_t row_len, double surface_mm, double tare_n, nte_t* scratch, double* res,
                      nte_export_replay_t* out)
{
    static const double shifts[NTE_EXPORT_LAYER_SHIFTS] = NTE_EXPORT_LAYER_SHIFTS_MM;
    nte_config_t cfg;
    out->counted = 0U;
    out->peak_n = 0.0;
    if (reader_config(run_cfg, row, row_len, surface_mm, &cfg) != 0) {
        return -1;
    }
    if (cfg.layer_sets == 0U) {
        return replay_once(&cfg, tr, tare_n, scratch, res, out);
    }
    for (size_t i = 0U; i < NTE_EXPORT_LAYER_SHIFTS; i++) {
        for (size_t k = 0U; k < cfg.layer_sets; k++) {
            /* in nte_real_t, as export_replay.py adds them */
            cfg.layer_set[k].start_mm = run_cfg->layer_set[k].start_mm + (nte_real_t)shifts[i];
        }
        if (replay_once(&cfg, tr, tare_n, scratch, res, out) != 0) {
            return -1;
        }
    }
    return 0;
}
