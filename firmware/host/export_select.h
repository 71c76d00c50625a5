/*
 * Which identified parameter set nte-run's --export-config writes: of EXPORT_CANDIDATES
 * snapshots of the estimates, evenly spaced over the record (the last sample among them), the
 * one whose replay from depth alone (--predict-only, as a reader of the file would run it) has
 * the smallest RMSE against the measured force less the tare, fitted to the record by the same
 * replay (export_refine.h).  Why: the bank's parameters at any sample follow the last stretch of
 * force one step ahead; the final ones are the retraction's and miss the insertion when
 * replayed.  Twin: reference_py/tools/export_select.py (the same candidates, the same replays
 * at 0 ULP, the same double sums in sample order, the first smallest RMSE wins, the same fit).
 */
#ifndef NTE_HOST_EXPORT_SELECT_H
#define NTE_HOST_EXPORT_SELECT_H

#include "csv_in.h"
#include "export_refine.h"
#include "nte.h"

#include <stddef.h>

/** Snapshots replayed per export. */
#define NTE_EXPORT_CANDIDATES 24U
/** Above this RMSE / peak the export warns that the parameters do not replay their record. */
#define NTE_EXPORT_WARN_FRACTION 0.15
/** Above this fitted RMSE / peak the fit runs again with the strengths at the first snapshot's
 * (export_select.py RESTART_FRACTION). */
#define NTE_EXPORT_RESTART_FRACTION 0.10

/** The estimates at one sample. */
typedef struct nte_export_snapshot_t {
    size_t sample; /**< index in the record */
    double t_s;    /**< its time, s */
    size_t np;     /**< identified parameters in pe */
    nte_param_estimate_t pe[NTE_IDENTIFIED_MAX];
} nte_export_snapshot_t;

/** The replay's verdict, and the values the export writes. */
typedef struct nte_export_choice_t {
    size_t candidate;    /**< index into the snapshots */
    double rmse_n;       /**< RMSE of its replay against force - tare, N (NaN: not replayed) */
    double final_rmse_n; /**< the same for the last snapshot (the final estimates), N */
    double peak_n;       /**< max |force - tare| over the record, N */
    /* the values to export: the chosen snapshot's, fitted to the record (export_refine.h) */
    double params[7]; /**< the seven force-model values, nte_param_id_t order */
    double sd[7];     /**< their sd: the fit's for the fitted ones, 0 for the fixed ones */
    size_t n_g;       /**< relaxation strengths identified (the branches in use) */
    const char* g_name[2];
    double g[2];
    double g_sd[2];
    double fit_rmse_n;          /**< RMSE of the fitted values' replay, N (NaN: not fitted) */
    unsigned fit_passes;        /**< the fit's replays */
    double restart_from_rmse_n; /**< the first fit's RMSE, N, when it missed by more than
                                     NTE_EXPORT_RESTART_FRACTION and the fit ran again from the
                                     first snapshot's strengths (NaN: it did not) */
    double presliding_mm;       /**< Model III's turn-over length replayed and exported, mm: the
                               last snapshot's identified delta, else the run's */
    size_t n_sets;              /**< layer sets fitted (0: none found, or they did not help) */
    double set_start_mm[NTE_LAYER_SETS_MAX]; /**< each one's start, mm below the surface */
    double set_values[NTE_LAYER_SETS_MAX][NTE_LAYER_SET_VALUES]; /**< nte_layer_set_t order */
    double set_sd[NTE_LAYER_SETS_MAX][NTE_LAYER_SET_VALUES];     /**< the fit's (NaN: none) */
} nte_export_choice_t;

/** Where the layers below the first begin (export_select.py layer_starts), gathered while the
 *  run goes: the depths below the surface of the tears the rupture detector found in the
 *  record's first insertion. */
typedef struct nte_export_layers_t {
    size_t count;                        /**< starts found */
    double start_mm[NTE_LAYER_SETS_MAX]; /**< mm below the surface, increasing */
    unsigned prev_layer;                 /**< the previous sample's published layer */
    int entered;                         /**< the tip has been in the tissue */
    int done;                            /**< the first insertion ended */
} nte_export_layers_t;

/** Start gathering (before the first sample). */
void nte_export_layers_start(nte_export_layers_t* acc);

/**
 * Sample k's published output `o` and its input depth (stage position with the front end on,
 * `contact`; the surface is o's).  Without the layer index (`with_layer` 0) nothing is found.
 */
void nte_export_layers_add(nte_export_layers_t* acc, size_t k, double depth_mm, int contact,
                           int with_layer, const nte_output_t* o);

/** Sample index of snapshot j (0-based, j < NTE_EXPORT_CANDIDATES) in a record of n samples:
 * ((j + 1) * n) / K - 1, at least 0. */
size_t nte_export_candidate_sample(size_t j, size_t n);

/**
 * The seven force-model values (and their sd) a snapshot exports: the identified ones from it,
 * the others at `fixed` (the preset or --config values; Model I's beta stays fixed[6], its
 * beta0); the relaxation strengths into g (in the order identified; *n_g of them).
 */
void nte_export_snapshot_values(const nte_export_snapshot_t* s, const double fixed[7], int model,
                                double params[7], double sd[7], double g[2], double g_sd[2],
                                const char* g_name[2], size_t* n_g);

/**
 * Replay every snapshot from depth alone over `tr` with the run's configuration `run_cfg`
 * (Model III: its presliding_mm replaced by the last snapshot's identified delta, exported as
 * out->presliding_mm) turned into a reader's (export_replay.h), choose the best and fit its identified values to
 * the record (export_refine.h); with layer starts, fit again with a layer set at each of them
 * (every set starting at the fitted values) and keep that when its replay is closer; `out`
 * holds the values to export.  `scratch` is an estimator
 * the replays run in.  With the front end on and no surface found nothing is replayed: the
 * last snapshot is exported as it is and rmse_n is NaN.  Returns 0, or -1 when a replay's
 * configuration is refused or memory runs out (not expected: the run accepted values of the
 * same form).
 */
int nte_export_choose(const nte_config_t* run_cfg, const nte_trial_t* tr,
                      const nte_export_snapshot_t snaps[NTE_EXPORT_CANDIDATES],
                      const nte_export_layers_t* layers, const double fixed[7], int model,
                      double surface_mm, double tare_n, nte_t* scratch, nte_export_choice_t* out);

#endif /* NTE_HOST_EXPORT_SELECT_H */
