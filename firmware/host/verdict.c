/* The closing verdict; mirrors reference_py/tools/verdict.py (its numbers formatted as Python
 * formats them: "{x:.3g}", "{x:.1f}", "{x:.0f}" and "{x:g}" are C's %.3g, %.1f, %.0f, %g). */
#include "verdict.h"

#include "nte.h"
#include "nte_verdict_rules.h"

#include <math.h>
#include <stdio.h>

void nte_verdict_start(nte_verdict_acc_t* acc)
{
    acc->inside = 0U;
    acc->gated = 0U;
    acc->sum_sq = 0.0;
    acc->t_first = 0.0;
    acc->early = 0U;
    acc->early_sum_sq = 0.0;
    acc->last_status = 0U;
    acc->last_confidence = 0.0;
}

void nte_verdict_add(nte_verdict_acc_t* acc, double t_s, double innovation_n, uint32_t status,
                     double confidence)
{
    acc->last_status = status;
    acc->last_confidence = confidence;
    if ((status & NTE_VERDICT_NOT_IN_TISSUE) != 0U) {
        return;
    }
    if (acc->inside == 0U) {
        acc->t_first = t_s;
    }
    acc->inside++;
    acc->gated += ((status & NTE_STATUS_GATED) != 0U) ? 1U : 0U;
    acc->sum_sq += innovation_n * innovation_n;
    if (t_s <= (acc->t_first + NTE_VERDICT_START_WINDOW_S)) {
        acc->early++;
        acc->early_sum_sq += innovation_n * innovation_n;
    }
}

size_t nte_verdict_rest_noise(const double* depth_mm, const double* force_n, size_t n, double* sd_n)
{
    size_t m = 0U;
    while ((m < n) && (fabs(depth_mm[m] - depth_mm[0]) <= NTE_VERDICT_REST_DEPTH_MM)) {
        m++;
    }
    if (m < NTE_VERDICT_MIN_REST_SAMPLES) {
        return m;
    }
    double total = 0.0;
    for (size_t k = 0U; k < m; k++) {
        total += force_n[k];
    }
    const double mean = total / (double)m;
    double dev = 0.0;
    for (size_t k = 0U; k < m; k++) {
        dev += (force_n[k] - mean) * (force_n[k] - mean);
    }
    if (!(dev > 0.0)) {
        return 0U; /* a noise-free rest measures no noise (verdict.py rest_noise) */
    }
    *sd_n = sqrt(dev / (double)(m - 1U));
    return m;
}

/* Advance *o past w characters that snprintf wrote at *o of a cap-byte buffer; -1 when they
 * did not fit. */
static int put(size_t cap, size_t* o, int w)
{
    if ((w < 0) || ((size_t)w >= (cap - *o))) {
        return -1;
    }
    *o += (size_t)w;
    return 0;
}

int nte_verdict_text(const nte_verdict_acc_t* acc, const nte_verdict_opts_t* opts, char* line,
                     size_t ls, char* warning, size_t ws)
{
    char robust[128] = "";
    if (opts->robust != 0) {
        (void)snprintf(
            robust, sizeof robust, "; robust refinement: confidence %.3g, %s", acc->last_confidence,
            ((acc->last_status & NTE_STATUS_CONVERGED) != 0U) ? "converged" : "not converged");
    }
    size_t o = 0U;
    warning[0] = '\0';
    if (opts->predict_only != 0) {
        return put(ls, &o,
                   snprintf(line, ls,
                            "verdict: predict-only, the force was not "
                            "read: no verdict%s",
                            robust));
    }
    if (acc->inside == 0U) {
        return put(ls, &o,
                   snprintf(line, ls,
                            "verdict: no sample in tissue: no "
                            "verdict%s",
                            robust));
    }
    const double r_n = sqrt(acc->sum_sq / (double)acc->inside);
    const double gated = (100.0 * (double)acc->gated) / (double)acc->inside;
    if (isnan(opts->noise_n)) {
        return put(ls, &o,
                   snprintf(line, ls,
                            "verdict: innovation RMS %.3g mN; gated "
                            "%.1f %% of updates; noise unknown (no rest before "
                            "the stage moves): give --noise N%s",
                            1000.0 * r_n, gated, robust));
    }
    const double k = r_n / opts->noise_n;
    if (put(ls, &o,
            snprintf(line, ls,
                     "verdict: innovation RMS %.3g mN = %.1fx the "
                     "noise (%.3g mN, ",
                     1000.0 * r_n, k, 1000.0 * opts->noise_n)) != 0) {
        return -1;
    }
    const int w = (opts->rest_n == 0U)
                      ? snprintf(line + o, ls - o, "given by --noise")
                      : snprintf(line + o, ls - o, "measured in the first %zu samples at rest",
                                 opts->rest_n);
    if (put(ls, &o, w) != 0) {
        return -1;
    }
    const int c = (k <= NTE_VERDICT_FOLLOWS_FACTOR)
                      ? snprintf(line + o, ls - o,
                                 "); gated %.1f %% of updates; the model "
                                 "follows this file%s",
                                 gated, robust)
                      : snprintf(line + o, ls - o,
                                 "); gated %.1f %% of updates; the model does "
                                 "not fit this file (%.1fx the noise): see nte-discrepancy%s",
                                 gated, k, robust);
    if (put(ls, &o, c) != 0) {
        return -1;
    }
    const double k2 = sqrt(acc->early_sum_sq / (double)acc->early) / opts->noise_n;
    if (k2 > NTE_VERDICT_START_FACTOR) {
        size_t p = 0U;
        return put(ws, &p,
                   snprintf(warning, ws,
                            "warning: the first %g s in tissue "
                            "are %.0fx the noise off the start: set it with "
                            "--preset, --start or --config",
                            NTE_VERDICT_START_WINDOW_S, k2));
    }
    return 0;
}
