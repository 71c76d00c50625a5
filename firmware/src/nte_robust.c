/*
 * The robust estimator: reference_py/robust.py (RobustEstimator, ldlt_solve) in C for one run.
 * The bank runs first (nte_bank.c); this file keeps the decimated record of each insertion and,
 * when the needle leaves the tissue, fits the model to it by Levenberg-Marquardt from two
 * starts and restarts the bank from the better fit.  Every branch is one of the reference's
 * np.where selections; the floating-point operations and their order are the reference's.
 */
#include "nte_robust.h"

#include "nte_bank.h"
#include "nte_model.h"

#if NTE_ROBUST_BUFFER_LEN > 0

#define ROW_T 0U /* time since the buffer start, s */
#define ROW_L 1U /* depth, mm */
#define ROW_V 2U /* velocity, mm/s */
#define ROW_F 3U /* force, N */

bool nte_robust_ldlt_solve(const size_t n, nte_robust_mat_t M, const nte_real_t* b, nte_real_t* x)
{
    nte_robust_mat_t L;
    nte_real_t D[NTE_MODEL_PARAM_COUNT];
    nte_real_t y[NTE_MODEL_PARAM_COUNT];
    bool ok = true;
    for (size_t j = 0U; j < n; j++) {
        nte_real_t acc = M[j][j];
        for (size_t k = 0U; k < j; k++) {
            acc = acc - ((L[j][k] * L[j][k]) * D[k]);
        }
        ok = ok && (acc > NTE_C(0.0));
        D[j] = (acc > NTE_C(0.0)) ? acc : NTE_C(1.0);
        for (size_t i = j + 1U; i < n; i++) {
            acc = M[i][j];
            for (size_t k = 0U; k < j; k++) {
                acc = acc - ((L[i][k] * L[j][k]) * D[k]);
            }
            L[i][j] = acc / D[j];
        }
    }
    for (size_t i = 0U; i < n; i++) {
        nte_real_t acc = b[i];
        for (size_t k = 0U; k < i; k++) {
            acc = acc - (L[i][k] * y[k]);
        }
        y[i] = acc;
    }
    for (size_t ii = n; ii > 0U; ii--) {
        const size_t i = ii - 1U;
        nte_real_t acc = y[i] / D[i];
        for (size_t k = i + 1U; k < n; k++) {
            acc = acc - (L[k][i] * x[k]);
        }
        x[i] = acc;
    }
    for (size_t i = 0U; i < n; i++) {
        x[i] = ok ? x[i] : NTE_C(0.0);
    }
    return ok;
}

void nte_robust_start(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    (void)memset(rb->buf, 0, sizeof rb->buf);
    rb->t0_us = 0;
    rb->count = 0U;
    rb->decim = 1U;
    rb->phase = 0U;
    rb->inside = false;
    rb->has_refined = false;
    rb->converged = false;
    rb->tainted = false;
    rb->confidence = NTE_C(0.0);
    /* the anchor of a first insertion that starts in the tissue: t = 0 and zeros */
    rb->anchor_t_us = 0;
    for (size_t c = 0U; c < 3U; c++) {
        rb->anchor[c] = NTE_C(0.0);
    }
    /* start (b) of the first refinement: the bank's initial theta (the reference's
     * prev_theta and bank.initial_theta hold the same values until the first refinement) */
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        rb->prev_theta[j] = self->th.v[j];
    }
}

/* RobustEstimator._restart_buffer: a new insertion starts from the last surface sample. */
static void restart_buffer(nte_robust_t* rb)
{
    rb->t0_us = rb->anchor_t_us;
    rb->count = 1U;
    rb->decim = 1U;
    rb->phase = 1U;
    rb->buf[ROW_T][0] = NTE_C(0.0);
    rb->buf[ROW_L][0] = rb->anchor[0];
    rb->buf[ROW_V][0] = rb->anchor[1];
    rb->buf[ROW_F][0] = rb->anchor[2];
    rb->tainted = false;
}

/* RobustEstimator._record for a sample inside the tissue (or entering it). */
static void record(nte_robust_t* rb, const uint32_t buffer_len, const nte_sample_t* s)
{
    bool take = (rb->phase % rb->decim) == 0U;
    if (take && (rb->count >= buffer_len)) {
        /* keep entries 0, 2, 4, ...: the buffer stays uniformly decimated (in place: the
         * source index 2i is never below the target i) */
        const uint32_t half = buffer_len / 2U;
        for (size_t row = 0U; row < 4U; row++) {
            for (uint32_t i = 0U; i < half; i++) {
                rb->buf[row][i] = rb->buf[row][2U * i];
            }
        }
        rb->count = half;
        rb->decim = rb->decim * 2U;
        take = (rb->phase % rb->decim) == 0U;
    }
    if (take) {
        const uint32_t idx = (rb->count < (buffer_len - 1U)) ? rb->count : (buffer_len - 1U);
        rb->buf[ROW_T][idx] = (nte_real_t)(s->t_us - rb->t0_us) / NTE_C(1.0e6);
        rb->buf[ROW_L][idx] = s->depth_mm;
        rb->buf[ROW_V][idx] = s->velocity_mm_s;
        rb->buf[ROW_F][idx] = s->force_n;
        rb->count++;
    }
    rb->phase++;
}

/*
 * RobustEstimator._simulate (with_jac = True): the squared output error over the buffer of the
 * model with log-parameters v around `nominal` (z from 0, fit_substeps RK3 sub-steps between
 * entries), and J^T J (A, mirrored) and J^T r (g).  Every one of the buffer_len - 1 entries is
 * simulated, the ones past `count` with dt = 0 and no weight, as in the reference.
 */
static nte_real_t simulate(const nte_t* self, const nte_real_t nominal[NTE_PARAM_COUNT],
                           const nte_real_t ex_nominal, const nte_real_t* v, nte_robust_mat_t A,
                           nte_real_t* g)
{
    const nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    const uint32_t buffer_len = (uint32_t)self->cfg.robust.buffer_len;
    const nte_real_t zero = NTE_C(0.0);
    nte_real_t u[NTE_PARAM_COUNT];
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        u[j] = NTE_C(0.0);
    }
    for (size_t a = 0U; a < n; a++) {
        u[ids[a]] = v[a];
    }
    nte_theta_t th;
    nte_model_theta(&th, nominal, ex_nominal, self->kappa, u);
    nte_real_t z = NTE_C(0.0);
    nte_real_t sz[NTE_MODEL_PARAM_COUNT];
    nte_real_t jrow[NTE_MODEL_PARAM_COUNT];
    nte_real_t cost = NTE_C(0.0);
    for (size_t a = 0U; a < n; a++) {
        sz[a] = NTE_C(0.0);
        g[a] = NTE_C(0.0);
        for (size_t b = 0U; b < n; b++) {
            A[a][b] = NTE_C(0.0);
        }
    }
    for (uint32_t i = 1U; i < buffer_len; i++) {
        const bool live = i < rb->count;
        const nte_real_t t_a = rb->buf[ROW_T][i - 1U];
        const nte_real_t t_b = rb->buf[ROW_T][i];
        const nte_real_t l_a = nte_model_clamp_depth(rb->buf[ROW_L][i - 1U]);
        const nte_real_t l_b = nte_model_clamp_depth(rb->buf[ROW_L][i]);
        const nte_real_t dt = live ? (t_b - t_a) : NTE_C(0.0);
        nte_rk3_result_t pred;
        nte_model_rk3(&pred, &th, z, l_a, l_b, dt, self->cfg.robust.fit_substeps, ids, n);
        const bool in_tissue = l_b > zero;
        z = in_tissue ? pred.z : zero;
        nte_depth_terms_t d;
        nte_model_depth_terms(&d, &th, l_b);
        const nte_real_t vel = rb->buf[ROW_V][i];
        const nte_real_t s = nte_model_smooth_sign(vel, self->cfg.eps_mm_s);
        nte_output_terms_t o;
        nte_model_output(&o, &th, &d, z, s);
        const nte_real_t r = rb->buf[ROW_F][i] - o.h;
        /* samples where the smooth sign may disagree with the true direction carry no weight */
        const bool sure = (nte_abs(s) > NTE_K_ROB_SURE) ||
                          !(nte_abs(vel) >= self->cfg.v_still_mm_s);
        const bool w = live && sure;
        cost = cost + (w ? (r * r) : zero);
        const nte_real_t hz = nte_model_output_dz(&th, &d, &o);
        for (size_t a = 0U; a < n; a++) {
            /* total derivative through the whole record: chain the step's partials */
            sz[a] = in_tissue ? ((pred.dz_dz0 * sz[a]) + pred.dz_du[ids[a]]) : zero;
            jrow[a] = nte_model_output_du(&th, &d, z, &o, ids[a]) + (hz * sz[a]);
        }
        for (size_t a = 0U; a < n; a++) {
            /* 0 * (inf or NaN) stays NaN here as in the reference: no shortcut for w false */
            const nte_real_t ja = w ? jrow[a] : zero;
            g[a] = g[a] + (ja * r);
            for (size_t b = a; b < n; b++) {
                A[a][b] = A[a][b] + (ja * jrow[b]);
            }
        }
    }
    for (size_t a = 0U; a < n; a++) {
        for (size_t b = 0U; b < a; b++) {
            A[a][b] = A[b][a];
        }
    }
    /* a diverged trial (inf or NaN) must compare as the worst possible cost */
    return (cost <= NTE_K_ROB_COST_HUGE) ? cost : NTE_K_ROB_COST_HUGE;
}

/* RobustEstimator._lm: fit_iterations LM iterations from theta0; the fitted theta and cost. */
static nte_real_t lm(nte_t* self, const nte_real_t theta0[NTE_PARAM_COUNT],
                     nte_real_t theta_out[NTE_PARAM_COUNT])
{
    nte_robust_t* rb = &self->robust;
    const nte_robust_config_t* rc = &self->cfg.robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    nte_real_t nominal[NTE_PARAM_COUNT];
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        nominal[j] = theta0[j];
    }
    const nte_real_t f2 = theta0[nte_param_f2];
    const nte_real_t ex_nominal = nte_model_f1_excess(theta0[nte_param_f1], f2, self->kappa);
    for (size_t a = 0U; a < n; a++) {
        rb->v[a] = NTE_C(0.0);
    }
    nte_real_t cost = simulate(self, nominal, ex_nominal, rb->v, rb->A, rb->g);
    nte_real_t lam = rc->lm_lambda0;
    const nte_real_t umax = self->cfg.u_max;
    for (int32_t it = 0; it < rc->fit_iterations; it++) {
        nte_robust_mat_t M; /* the damped system (scratch of this iteration) */
        for (size_t a = 0U; a < n; a++) {
            for (size_t b = 0U; b < n; b++) {
                M[a][b] = rb->A[a][b] + ((a == b) ? (lam * rb->A[a][a]) : NTE_C(0.0));
            }
        }
        nte_real_t delta[NTE_MODEL_PARAM_COUNT];
        const bool ok = nte_robust_ldlt_solve(n, M, rb->g, delta);
        for (size_t a = 0U; a < n; a++) {
            /* np.clip = minimum(maximum(x, -umax), umax); NaN passes through */
            nte_real_t x = rb->v[a] + delta[a];
            x = (x < -umax) ? -umax : x;
            x = (x > umax) ? umax : x;
            rb->v_try[a] = x;
        }
        const nte_real_t c_try = simulate(self, nominal, ex_nominal, rb->v_try, rb->A_try,
                                          rb->g_try);
        const bool accept = ok && (c_try < cost);
        if (accept) {
            cost = c_try;
            for (size_t a = 0U; a < n; a++) {
                rb->v[a] = rb->v_try[a];
                rb->g[a] = rb->g_try[a];
                for (size_t b = 0U; b < n; b++) {
                    rb->A[a][b] = rb->A_try[a][b];
                }
            }
        }
        lam = accept ? (lam / NTE_C(3.0)) : (lam * NTE_C(4.0));
        lam = (lam < NTE_K_ROB_LAMBDA_MIN) ? NTE_K_ROB_LAMBDA_MIN : lam;
        lam = (lam > NTE_K_ROB_LAMBDA_MAX) ? NTE_K_ROB_LAMBDA_MAX : lam;
    }
    nte_real_t u[NTE_PARAM_COUNT];
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        u[j] = NTE_C(0.0);
    }
    for (size_t a = 0U; a < n; a++) {
        u[ids[a]] = rb->v[a];
    }
    nte_theta_t th;
    nte_model_theta(&th, nominal, ex_nominal, self->kappa, u);
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        theta_out[j] = th.v[j];
    }
    return cost;
}

/* RobustEstimator._refine: two starts, the better fit, confidence and convergence, restart. */
static void refine(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    nte_real_t start_a[NTE_PARAM_COUNT];
    nte_real_t start_b[NTE_PARAM_COUNT];
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        start_a[j] = self->th.v[j];
        start_b[j] = rb->prev_theta[j];
    }
    nte_real_t best[NTE_PARAM_COUNT];
    nte_real_t other[NTE_PARAM_COUNT];
    nte_real_t best_cost = lm(self, start_a, best);
    const nte_real_t cost_b = lm(self, start_b, other);
    if (cost_b < best_cost) {
        best_cost = cost_b;
        for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
            best[j] = other[j];
        }
    }
    const nte_real_t n_used = (nte_real_t)((rb->count > 1U) ? rb->count : 1U);
    const nte_real_t rms = nte_sqrt(best_cost / n_used);
    const nte_real_t sq_r = nte_sqrt(self->cfg.r_n2);
    const nte_real_t conf = sq_r / ((rms > sq_r) ? rms : sq_r);
    nte_real_t change = NTE_C(0.0);
    for (size_t a = 0U; a < n; a++) {
        const uint8_t j = ids[a];
        const nte_real_t rel = nte_abs(best[j] - rb->prev_theta[j]) / nte_abs(rb->prev_theta[j]);
        change = (rel > change) ? rel : change;
    }
    rb->converged = rb->has_refined && (conf >= self->cfg.robust.converged_confidence) &&
                    (change <= self->cfg.robust.converged_change);
    rb->confidence = conf;
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        rb->prev_theta[j] = best[j];
    }
    rb->has_refined = true;
    nte_bank_restart_from(self, best, self->cfg.robust.restart_p0_u);
}

uint32_t nte_robust_step(nte_t* self, const nte_sample_t* sample, const bool valid)
{
    nte_robust_t* rb = &self->robust;
    const nte_real_t l = sample->depth_mm;
    const bool at_surface = valid && !(l > NTE_C(0.0));
    const bool entering = valid && (l > NTE_C(0.0)) && !rb->inside;
    const bool leaving = at_surface && rb->inside;
    if (entering) {
        restart_buffer(rb);
    }
    /* an insertion during which predict-only was on, or the parameters were held, is neither
     * recorded further nor refined (nte.h THE PREDICT-ONLY MODE, HELD PARAMETERS) */
    if (self->cfg.predict_only || self->frozen) {
        rb->tainted = true;
    }
    if (valid && (rb->inside || entering) && !rb->tainted) {
        record(rb, (uint32_t)self->cfg.robust.buffer_len, sample);
    }
    rb->inside = (rb->inside || entering) && !at_surface;
    const bool refined = leaving && !rb->tainted &&
                         (rb->count >= (uint32_t)self->cfg.robust.min_entries);
    if (refined) {
        refine(self);
    }
    if (leaving) {
        rb->count = 0U;
    }
    if (at_surface) {
        /* the anchor (z = 0) of the next insertion's record */
        rb->anchor_t_us = sample->t_us;
        rb->anchor[0] = sample->depth_mm;
        rb->anchor[1] = sample->velocity_mm_s;
        rb->anchor[2] = sample->force_n;
    }
    uint32_t status = refined ? NTE_STATUS_REFINED : 0U;
    status |= rb->converged ? NTE_STATUS_CONVERGED : 0U;
    return status;
}

#endif /* NTE_ROBUST_BUFFER_LEN > 0 */
