/*
 * Refining the exported parameters: a Levenberg-Marquardt fit of the reader's replay
 * (export_replay.h) to the record, from the snapshot export_select.c chose.  Why and how, step
 * by step: reference_py/tools/export_refine.py, the twin (the same operations in the same
 * order: C ≡ reference at 0 ULP).
 */
#ifndef NTE_HOST_EXPORT_REFINE_H
#define NTE_HOST_EXPORT_REFINE_H

#include "export_replay.h"

#include <stdbool.h>
#include <stddef.h>

#define NTE_REFINE_PASSES 20U /**< passes at most (the first: the start's Jacobian) */
#define NTE_REFINE_H 1e-3     /**< relative finite-difference step of every value */
#define NTE_REFINE_TOL 1e-4   /**< a kept step lowering the SSE by less than this ends */
#define NTE_REFINE_LAMBDA_START 1e-3
#define NTE_REFINE_LAMBDA_MAX 1e8
#define NTE_REFINE_LAMBDA_WIDE 10.0 /**< the second step's damping: lambda times this */
#define NTE_REFINE_LAMBDA_DOWN 0.1  /**< the lighter step kept: lambda times this */
#define NTE_REFINE_STEP_MIN (-1.5)  /**< clip of each log change per step */
#define NTE_REFINE_STEP_MAX 1.5
#define NTE_REFINE_STRENGTH_MAX 0.98 /**< the strengths' sum at most (a reader: sum < 1) */
#define NTE_REFINE_G0_MARGIN 1.01    /**< f1 >= -f2 * this when f2 < 0 (g(0) > 0) */
#define NTE_REFINE_PARAM_MAX 1000.0  /**< |value| a reader accepts (estconfig.PARAM_MAX) */

/** The fit's result. */
typedef struct nte_export_fit_t {
    double row[NTE_EXPORT_ROW_MAX];  /**< the fitted row (the seven values, the strengths, the
                                          layer sets' values) */
    double sd[NTE_EXPORT_ROW_MAX];   /**< the fit's sd of each fitted entry */
    bool has_sd[NTE_EXPORT_ROW_MAX]; /**< false: not fitted, or A could not be factored */
    double rmse_n;                   /**< RMSE of the fitted values' replay, N */
    unsigned passes;                 /**< replays done (each of 1 + fitted rows) */
} nte_export_fit_t;

/**
 * Fit the entries of `start` (row_len of them) marked in `fitted` to `tr`.  Returns 0, or -1
 * when memory runs out or a replay's configuration is refused (the caller keeps `start`).
 */
int nte_export_refine(const nte_config_t* run_cfg, const nte_trial_t* tr, const double* start,
                      size_t row_len, const bool fitted[NTE_EXPORT_ROW_MAX], double surface_mm,
                      double tare_n, nte_t* scratch, nte_export_fit_t* out);

#endif /* NTE_HOST_EXPORT_REFINE_H */
