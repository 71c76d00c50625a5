/*
 * The replay a reader of an exported configuration gets: the model alone, from depth alone.
 * --export-config judges parameter sets by what `--config FILE --predict-only` would do with
 * them on the record they came from: the run's configuration turned into a reader's (the set
 * as the nominal values, predict-only, the surface the front end ended with), the record
 * stepped with the force ignored, the prediction compared with the measured force less the
 * tare.  export_select.c replays the run's snapshots this way, export_refine.c perturbed sets.
 * Twin: reference_py/tools/export_replay.py (C ≡ reference at 0 ULP).
 */
#ifndef NTE_HOST_EXPORT_REPLAY_H
#define NTE_HOST_EXPORT_REPLAY_H

#include "csv_in.h"
#include "nte.h"

#include <stddef.h>

/** Entries of a replayed row: the seven force-model values, up to two strengths, then the
 *  NTE_LAYER_SET_VALUES values of each of the configuration's layer sets. */
#define NTE_EXPORT_ROW_MAX (9U + (NTE_LAYER_SET_VALUES * NTE_LAYER_SETS_MAX))

/** With layer sets, every row is replayed with their starts moved by each of these (mm) and
 *  the residuals follow one another: a trial of the same condition tears a little deeper or
 *  shallower, and a set fitted at one depth alone switched its force 1 mm early or late on the
 *  next trial (export_replay.py LAYER_SHIFTS_MM, the measurement). */
#define NTE_EXPORT_LAYER_SHIFTS 3U
/* clang-format 14 spreads a braced initializer in a #define over four lines */
/* clang-format off */
#define NTE_EXPORT_LAYER_SHIFTS_MM {-1.0, 0.0, 1.0}
/* clang-format on */

/** One replay's verdict. */
typedef struct nte_export_replay_t {
    size_t counted; /**< samples with a finite force (the others are not compared) */
    double peak_n;  /**< max |force - tare| over them, N */
} nte_export_replay_t;

/**
 * Replay `row` (row_len entries: the seven values in nte_param_id_t order, the relaxation
 * strengths in use, then the values of each of run_cfg's layer_sets, nte_layer_set_t order)
 * over `tr` with the run's configuration `run_cfg` turned into a reader's.
 * Writes prediction - (force - tare) of every counted sample, in sample order, into `res`
 * (capacity tr->n, NTE_EXPORT_LAYER_SHIFTS times that with layer sets: one replay per shift
 * of their starts, one after the other; may be NULL when only the verdict is wanted) and
 * returns 0, or -1 when the row is refused as a configuration.  out->counted counts every
 * replay's samples.  `scratch` is the estimator the replay runs in.
 */
int nte_export_replay(const nte_config_t* run_cfg, const nte_trial_t* tr, const double* row,
                      size_t row_len, double surface_mm, double tare_n, nte_t* scratch, double* res,
                      nte_export_replay_t* out);

#endif /* NTE_HOST_EXPORT_REPLAY_H */
