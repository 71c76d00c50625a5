/*
 * --export-config of nte-run (the reader is firmware/config_json/nte_config_file.h).
 */
#ifndef NTE_HOST_CONFIG_FILE_H
#define NTE_HOST_CONFIG_FILE_H

#include "nte_config_file.h"

#include <stddef.h>

/** What --export-config writes (reference_py/tools/estimate.py export_config). */
typedef struct nte_export_t {
    const char* source; /**< "nte-run" */
    int model;
    double params[7]; /**< the chosen estimates fitted, the fixed ones at their nominal */
    double sd[7];     /**< 0 for the fixed ones */
    double r_n2;
    size_t samples;
    /* the replay from depth alone that chose the values (export_select.h); NaN: null */
    double replay_t_s;          /**< time of the chosen snapshot, s */
    unsigned replay_candidates; /**< snapshots replayed */
    double replay_rmse_n;       /**< its RMSE against force - tare, N */
    double replay_final_rmse_n; /**< the final estimates' RMSE, N */
    double replay_peak_n;       /**< max |force - tare|, N */
    double fit_rmse_n;          /**< the fitted values' replay RMSE, N (export_refine.h) */
    unsigned fit_passes;        /**< the fit's replays */
    /* Model III */
    int direction_memory;
    double presliding_mm;
    int relaxation;
    int relax_branches;
    double tau_fast_s;
    double tau_slow_s;
    size_t n_g; /**< strengths identified (the branches in use) */
    const char* g_name[2];
    double g[2];
    double g_sd[2];
    size_t n_sets; /**< layer sets fitted (written as model3.layer_sets) */
    double set_start_mm[NTE_FILE_LAYER_SETS];
    double set_values[NTE_FILE_LAYER_SETS][4]; /**< sigma0, f1, beta, sigma2 */
    double set_sd[NTE_FILE_LAYER_SETS][4];     /**< NaN: null */
    /* the contact front end */
    int contact;
    double surface_mm; /**< NaN: not found (null) */
    double tare_n;
} nte_export_t;

/**
 * The configuration as JSON text, byte for byte what the reference's json.dumps(..., indent=2)
 * writes for the same values (floats in Python's shortest round-trip form).  Returns the
 * length, or -1 when cap is too small.
 */
int nte_config_file_export_text(const nte_export_t* e, char* buf, size_t cap);

#endif /* NTE_HOST_CONFIG_FILE_H */
