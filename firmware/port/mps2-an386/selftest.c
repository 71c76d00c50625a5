/*
 * selftest.c -- see selftest.h.  Line format (one per sample, fields separated by spaces):
 *
 *   S <run> <k> <force_hat> <z> <innovation> <nis> <status> <confidence> <n> {<id> <value> <sd>}
 *
 * reals as 8 hex digits (float32 bits), status and ids in hex, k in decimal.  Each run starts
 * with "R <run> model=<m> estimator=<e> schedule=<s> sizeof_nte_t=<bytes>" and ends with
 * "E <run> rejected=... gated=... resets=... gaps=...".
 */
#include "selftest.h"

#include <stdbool.h>
#include <string.h>

#include "scenario.h"

typedef struct run_spec_t {
    int32_t model;
    nte_estimator_t estimator;
    nte_schedule_t schedule;
} run_spec_t;

static const run_spec_t RUNS[] = {
    {1, nte_estimator_bank, nte_schedule_all},   {2, nte_estimator_bank, nte_schedule_rotate},
    {2, nte_estimator_robust, nte_schedule_all}, {2, nte_estimator_bank, nte_schedule_all},
    {3, nte_estimator_bank, nte_schedule_all},
};

char* nte_selftest_put_str(char* p, const char* s)
{
    while (*s != '\0') {
        *p = *s;
        p++;
        s++;
    }
    *p = '\0';
    return p;
}

char* nte_selftest_put_hex32(char* p, uint32_t v)
{
    static const char HEX[] = "0123456789abcdef";
    for (int i = 7; i >= 0; i--) {
        p[7 - i] = HEX[(v >> (4U * (uint32_t)i)) & 0xFU];
    }
    p[8] = '\0';
    return p + 8;
}

char* nte_selftest_put_u32(char* p, uint32_t v)
{
    char tmp[11];
    int n = 0;
    do {
        tmp[n] = (char)('0' + (char)(v % 10U));
        n++;
        v /= 10U;
    } while (v != 0U);
    while (n > 0) {
        n--;
        *p = tmp[n];
        p++;
    }
    *p = '\0';
    return p;
}

static char* put_real(char* p, nte_real_t x)
{
    uint32_t bits;
    memcpy(&bits, &x, sizeof bits);
    *p = ' ';
    return nte_selftest_put_hex32(p + 1, bits);
}

static nte_real_t real_of_bits(uint32_t bits)
{
    nte_real_t x;
    memcpy(&x, &bits, sizeof x);
    return x;
}

/* Sample k of the run: the scenario's row k, and past its end its last row held (the needle
 * resting at the surface), the time going on by the scenario's last interval. */
static void scenario_sample(const uint32_t k, nte_sample_t* s)
{
    const uint32_t last = (uint32_t)NTE_SCENARIO_LEN - 1U;
    const nte_scenario_row_t* row = &nte_scenario[(k < last) ? k : last];
    const uint32_t interval = nte_scenario[last].t_us - nte_scenario[last - 1U].t_us;
    const uint32_t beyond = (k < last) ? 0U : (k - last);
    s->t_us = (int64_t)row->t_us + ((int64_t)beyond * (int64_t)interval);
    s->depth_mm = real_of_bits(row->depth_bits);
    s->velocity_mm_s = real_of_bits(row->velocity_bits);
    s->force_n = real_of_bits(row->force_bits);
}

/* Whether the run goes on past the scenario at sample k: a refinement started and not yet
 * adopted (the robust estimator's default slicing takes longer than the scenario's rest at
 * the surface; nte.h THE ROBUST ESTIMATOR), at most NTE_SELFTEST_REST_MAX samples more. */
static bool still_refining(const uint32_t status, const uint32_t k)
{
    const bool slicing = (status & NTE_STATUS_REFINING) != 0U;
    const bool adopted = (status & NTE_STATUS_REFINED) != 0U;
    return slicing && !adopted && (k < ((uint32_t)NTE_SCENARIO_LEN + NTE_SELFTEST_REST_MAX));
}

/* the estimator instance lives in .bss: its size is a figure of the image, not of the stack */
static nte_t g_est;

static int one_run(uint32_t run, const run_spec_t* spec, nte_selftest_emit_t emit,
                   nte_selftest_mark_t mark, void* ctx)
{
    char line[256];
    char* p;
    nte_config_t cfg;
    nte_config_default(&cfg, spec->model, spec->schedule);
    cfg.estimator = spec->estimator;
    const nte_err_t ierr = nte_init(&g_est, &cfg);
    if (ierr != nte_err_ok) {
        return (int)ierr;
    }
    p = nte_selftest_put_str(line, "R ");
    p = nte_selftest_put_u32(p, run);
    p = nte_selftest_put_str(p, " model=");
    p = nte_selftest_put_u32(p, (uint32_t)spec->model);
    p = nte_selftest_put_str(p, (spec->estimator == nte_estimator_robust) ? " estimator=robust"
                                                                          : " estimator=bank");
    p = nte_selftest_put_str(p, (spec->schedule == nte_schedule_rotate) ? " schedule=rotate"
                                                                        : " schedule=all");
    p = nte_selftest_put_str(p, " sizeof_nte_t=");
    p = nte_selftest_put_u32(p, (uint32_t)sizeof(nte_t));
    (void)nte_selftest_put_str(p, "\n");
    emit(ctx, line);

    uint32_t status = 0U;
    for (uint32_t k = 0U; (k < (uint32_t)NTE_SCENARIO_LEN) || still_refining(status, k); k++) {
        nte_sample_t s;
        nte_output_t out;
        nte_param_estimate_t par[NTE_IDENTIFIED_MAX];
        scenario_sample(k, &s);
        if (mark != NULL) {
            mark(ctx, 1);
        }
        const nte_err_t serr = nte_step(&g_est, &s, &out);
        if (mark != NULL) {
            mark(ctx, 0);
        }
        if (serr != nte_err_ok) {
            return (int)serr;
        }
        status = out.status;
        const size_t n = nte_get_params(&g_est, par, NTE_IDENTIFIED_MAX);
        p = nte_selftest_put_str(line, "S ");
        p = nte_selftest_put_u32(p, run);
        p = nte_selftest_put_str(p, " ");
        p = nte_selftest_put_u32(p, k);
        p = put_real(p, out.force_hat_n);
        p = put_real(p, out.z);
        p = put_real(p, out.innovation_n);
        p = put_real(p, out.nis);
        p = nte_selftest_put_str(p, " ");
        p = nte_selftest_put_hex32(p, out.status);
        p = put_real(p, out.confidence);
        p = nte_selftest_put_str(p, " ");
        p = nte_selftest_put_u32(p, (uint32_t)n);
        for (size_t j = 0U; (j < n) && (j < NTE_IDENTIFIED_MAX); j++) {
            p = nte_selftest_put_str(p, " ");
            p = nte_selftest_put_u32(p, (uint32_t)par[j].id);
            p = put_real(p, par[j].value);
            p = put_real(p, par[j].sd);
        }
        (void)nte_selftest_put_str(p, "\n");
        emit(ctx, line);
    }

    p = nte_selftest_put_str(line, "E ");
    p = nte_selftest_put_u32(p, run);
    p = nte_selftest_put_str(p, " rejected=");
    p = nte_selftest_put_u32(p, g_est.counters.rejected[0] + g_est.counters.rejected[1] +
                                    g_est.counters.rejected[2]);
    p = nte_selftest_put_str(p, " gated=");
    p = nte_selftest_put_u32(p, g_est.counters.gated);
    p = nte_selftest_put_str(p, " resets=");
    p = nte_selftest_put_u32(p, g_est.counters.filter_resets);
    p = nte_selftest_put_str(p, " gaps=");
    p = nte_selftest_put_u32(p, g_est.counters.gaps);
    (void)nte_selftest_put_str(p, "\n");
    emit(ctx, line);
    return 0;
}

int nte_selftest_run(nte_selftest_emit_t emit, nte_selftest_mark_t mark, void* ctx)
{
    for (uint32_t r = 0U; r < (uint32_t)(sizeof RUNS / sizeof RUNS[0]); r++) {
        const int rc = one_run(r, &RUNS[r], emit, mark, ctx);
        if (rc != 0) {
            return rc;
        }
    }
    return 0;
}
