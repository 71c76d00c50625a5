/*
 * The closing verdict of nte-run (the C twin of reference_py/tools/verdict.py): does the model
 * follow this file, judged by its innovation against the sensor's own noise?  The line and
 * its forms are verdict.py's, to the character; the arithmetic is in double whatever the
 * library's precision, sums in sample order.  Host only.
 */
#ifndef NTE_VERDICT_H
#define NTE_VERDICT_H

#include <stddef.h>
#include <stdint.h>

/** The in-tissue samples seen so far (those without INIT, REJECTED, OUT_OF_TISSUE and
 *  PREDICT_ONLY), fed one sample at a time in order. */
typedef struct nte_verdict_acc_t {
    size_t inside;          /**< in-tissue samples */
    size_t gated;           /**< of them with NTE_STATUS_GATED */
    double sum_sq;          /**< sum of their innovation^2, N^2 */
    double t_first;         /**< the first one's time, s */
    size_t early;           /**< of them within NTE_VERDICT_START_WINDOW_S of the first */
    double early_sum_sq;    /**< their innovation^2 summed, N^2 */
    uint32_t last_status;   /**< the last sample's status (any sample) */
    double last_confidence; /**< the last sample's confidence (the robust estimator's) */
} nte_verdict_acc_t;

void nte_verdict_start(nte_verdict_acc_t* acc);
/** One sample's time (s), innovation (N), status and confidence, in order. */
void nte_verdict_add(nte_verdict_acc_t* acc, double t_s, double innovation_n, uint32_t status,
                     double confidence);

/** The force's sample standard deviation (n - 1) over the leading samples while
 *  |depth - depth[0]| <= NTE_VERDICT_REST_DEPTH_MM; returns how many led at rest (the sd is
 *  set only when at least NTE_VERDICT_MIN_REST_SAMPLES). */
size_t nte_verdict_rest_noise(const double* depth_mm, const double* force_n, size_t n,
                              double* sd_n);

/** What to judge by: the noise (N) and its source, which form, the robust suffix. */
typedef struct nte_verdict_opts_t {
    double noise_n;   /**< given by --noise, else measured at rest; NaN: unknown */
    size_t rest_n;    /**< 0: noise_n given by --noise; else the samples it was measured on */
    int predict_only; /**< the force was not read */
    int robust;       /**< append the robust refinement's confidence and convergence */
} nte_verdict_opts_t;

/** The verdict line (stdout, no newline) and the start's warning (stderr, no newline; empty
 *  when none).  Returns 0, or -1 when a buffer is too small. */
int nte_verdict_text(const nte_verdict_acc_t* acc, const nte_verdict_opts_t* opts, char* line,
                     size_t line_size, char* warning, size_t warning_size);

#endif /* NTE_VERDICT_H */
