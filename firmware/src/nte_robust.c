/*
 * The robust estimator: reference_py/robust.py (RobustEstimator, ldlt_solve) in C for one run.
 * The bank runs first (nte_bank.c); this file keeps the decimated record of each insertion and,
 * from the sample where the needle leaves the tissue on, fits the model to it by
 * Levenberg-Marquardt from two starts, a slice per sample, and restarts the bank from the
 * better fit.  Every branch is one of the reference's
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
    rb->refining = false;
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
        rb->buf[ROW_T][idx] = nte_real_from_i64(s->t_us - rb->t0_us) / NTE_C(1.0e6);
        rb->buf[ROW_L][idx] = s->depth_mm;
        rb->buf[ROW_V][idx] = s->velocity_mm_s;
        rb->buf[ROW_F][idx] = s->force_n;
        rb->count++;
    }
    rb->phase++;
}

/*
 * The refinement, sliced (nte.h THE ROBUST ESTIMATOR).  RobustEstimator._fit runs two
 * Levenberg-Marquardt fits, each fit_iterations + 1 simulations of the buffer_len - 1 buffer
 * entries; here the same operations in the same order are spread over the samples after the
 * insertion: each nte_step simulates at most cfg.robust.slice_entries entries (0: all), and a
 * simulation's running sums live in nte_robust_t between the steps.  The reference fits at
 * once and adopts the result at the sample where this machine finishes (robust.py
 * RobustEstimator.slices), so both adopt the same bits at the same sample.
 */

/* The fit's model at log-parameters v around a start's nominal (0: start_a, 1: prev_theta). */
static void fit_theta(const nte_t* self, const uint8_t start, const nte_real_t* v, nte_theta_t* th)
{
    const nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    const nte_real_t* nominal = (start == 0U) ? rb->start_a : rb->prev_theta;
    const nte_real_t ex = nte_model_f1_excess(nominal[nte_param_f1], nominal[nte_param_f2],
                                              self->kappa);
    nte_real_t u[NTE_PARAM_COUNT];
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        u[j] = NTE_C(0.0);
    }
    for (size_t a = 0U; a < n; a++) {
        u[ids[a]] = v[a];
    }
    nte_model_theta(th, nominal, ex, self->kappa, u);
}

/* The simulation in progress: the start's first (iteration -1, at v into A, g) or an LM
 * iteration's trial (at v_try into A_try, g_try). */
static bool sim_is_trial(const nte_robust_t* rb) { return rb->iteration >= 0; }

/* The sums the simulation in progress accumulates into: J^T J and J^T r. */
static nte_robust_mat_t* sim_jtj(nte_robust_t* rb)
{
    return sim_is_trial(rb) ? &rb->A_try : &rb->A;
}
static nte_real_t* sim_jtr(nte_robust_t* rb) { return sim_is_trial(rb) ? rb->g_try : rb->g; }

/* A simulation starts: z from 0, the sums at 0 (RobustEstimator._simulate's set-up). */
static void sim_begin(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    nte_real_t* g = sim_jtr(rb);
    nte_robust_mat_t* A = sim_jtj(rb);
    /* the simulation's model, once: a slice may be a single entry, and the parameters'
     * exponentials would otherwise be taken again at every one */
    fit_theta(self, rb->start, sim_is_trial(rb) ? rb->v_try : rb->v, &rb->th);
    rb->z = NTE_C(0.0);
    rb->sim_cost = NTE_C(0.0);
    rb->entry = 1U;
    for (size_t a = 0U; a < n; a++) {
        rb->sz[a] = NTE_C(0.0);
        g[a] = NTE_C(0.0);
        for (size_t b = 0U; b < n; b++) {
            (*A)[a][b] = NTE_C(0.0);
        }
    }
}

/*
 * RobustEstimator._simulate (with_jac = True), entries rb->entry .. rb->entry + count - 1: the
 * squared output error over the buffer of the fit's model (z from 0, fit_substeps RK3
 * sub-steps between entries), and J^T J (upper triangle) and J^T r.  Every one of the
 * buffer_len - 1 entries is simulated, the ones past the insertion's count with dt = 0 and no
 * weight, as in the reference.
 */
static void sim_run(nte_t* self, const uint32_t count)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    const nte_real_t zero = NTE_C(0.0);
    nte_real_t* g = sim_jtr(rb);
    nte_robust_mat_t* A = sim_jtj(rb);
    const nte_theta_t* th = &rb->th;
    nte_real_t jrow[NTE_MODEL_PARAM_COUNT];
    const uint32_t end = rb->entry + count;
    for (uint32_t i = rb->entry; i < end; i++) {
        const bool live = i < rb->fit_count;
        const nte_real_t t_a = rb->buf[ROW_T][i - 1U];
        const nte_real_t t_b = rb->buf[ROW_T][i];
        const nte_real_t l_a = nte_model_clamp_depth(rb->buf[ROW_L][i - 1U]);
        const nte_real_t l_b = nte_model_clamp_depth(rb->buf[ROW_L][i]);
        const nte_real_t dt = live ? (t_b - t_a) : NTE_C(0.0);
        nte_rk3_result_t pred;
        nte_model_rk3(&pred, th, rb->z, l_a, l_b, dt, self->cfg.robust.fit_substeps, ids, n, NULL);
        const bool in_tissue = l_b > zero;
        rb->z = in_tissue ? pred.z : zero;
        /* the step's end is l_b's depth terms when the two depths are the same bits (both
         * clamped, the same theta): one exp and one division fewer per entry */
        nte_depth_terms_t d;
        if (!(pred.end.l < l_b) && !(pred.end.l > l_b)) {
            d = pred.end;
        } else {
            nte_model_depth_terms(&d, th, l_b);
        }
        const nte_real_t vel = rb->buf[ROW_V][i];
        const nte_real_t s = nte_model_smooth_sign(vel, self->cfg.eps_mm_s);
        nte_output_terms_t o;
        nte_model_output(&o, th, &d, rb->z, s);
        const nte_real_t r = rb->buf[ROW_F][i] - o.h;
        /* samples where the smooth sign may disagree with the true direction carry no weight */
        const bool sure = (nte_abs(s) > NTE_K_ROB_SURE) ||
                          !(nte_abs(vel) >= self->cfg.v_still_mm_s);
        const bool w = live && sure;
        rb->sim_cost = rb->sim_cost + (w ? (r * r) : zero);
        const nte_real_t hz = nte_model_output_dz(th, &d, &o);
        for (size_t a = 0U; a < n; a++) {
            /* total derivative through the whole record: chain the step's partials */
            rb->sz[a] = in_tissue ? ((pred.dz_dz0 * rb->sz[a]) + pred.dz_du[ids[a]]) : zero;
            jrow[a] = nte_model_output_du(th, &d, rb->z, &o, ids[a]) + (hz * rb->sz[a]);
        }
        for (size_t a = 0U; a < n; a++) {
            /* 0 * (inf or NaN) stays NaN here as in the reference: no shortcut for w false */
            const nte_real_t ja = w ? jrow[a] : zero;
            g[a] = g[a] + (ja * r);
            for (size_t b = a; b < n; b++) {
                (*A)[a][b] = (*A)[a][b] + (ja * jrow[b]);
            }
        }
    }
    rb->entry = end;
}

/* The simulation's end: A mirrored, the cost (a diverged one, inf or NaN, as the worst). */
static nte_real_t sim_end(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    nte_robust_mat_t* A = sim_jtj(rb);
    for (size_t a = 0U; a < n; a++) {
        for (size_t b = 0U; b < a; b++) {
            (*A)[a][b] = (*A)[b][a];
        }
    }
    return (rb->sim_cost <= NTE_K_ROB_COST_HUGE) ? rb->sim_cost : NTE_K_ROB_COST_HUGE;
}

/* RobustEstimator._lm's iteration: the damped system at the current point, its solution, the
 * trial point clipped to |v| <= u_max; the trial's simulation begins. */
static void lm_trial(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    const nte_real_t umax = self->cfg.u_max;
    nte_robust_mat_t M; /* the damped system (scratch of this iteration) */
    for (size_t a = 0U; a < n; a++) {
        for (size_t b = 0U; b < n; b++) {
            M[a][b] = rb->A[a][b] + ((a == b) ? (rb->lam * rb->A[a][a]) : NTE_C(0.0));
        }
    }
    nte_real_t delta[NTE_MODEL_PARAM_COUNT];
    rb->trial_ok = nte_robust_ldlt_solve(n, M, rb->g, delta);
    for (size_t a = 0U; a < n; a++) {
        /* np.clip = minimum(maximum(x, -umax), umax); NaN passes through */
        nte_real_t x = rb->v[a] + delta[a];
        x = (x < -umax) ? -umax : x;
        x = (x > umax) ? umax : x;
        rb->v_try[a] = x;
    }
    sim_begin(self);
}

/* A start's fit begins at v = 0 around its nominal (start 0: the bank's parameters at the end
 * of the insertion; start 1: the previous refinement's, at first the nominal). */
static void lm_begin(nte_t* self, const uint8_t start)
{
    nte_robust_t* rb = &self->robust;
    rb->start = start;
    rb->iteration = -1;
    for (size_t a = 0U; a < NTE_MODEL_PARAM_COUNT; a++) {
        rb->v[a] = NTE_C(0.0);
    }
    sim_begin(self);
}

/* RobustEstimator._fit's end and _adopt: the better start, confidence and convergence, and the bank
 * restarted from it -- unless the parameters are held or predict-only is on by now: the
 * result is then dropped (nte.h THE ROBUST ESTIMATOR).  Returns whether it was adopted. */
static bool refine_end(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    rb->refining = false;
    if (self->cfg.predict_only || self->frozen) {
        return false;
    }
    /* start 1's fit is in v; start 0's in v_a */
    const bool second = rb->cost < rb->cost_a;
    const nte_real_t best_cost = second ? rb->cost : rb->cost_a;
    nte_theta_t th;
    fit_theta(self, second ? 1U : 0U, second ? rb->v : rb->v_a, &th);
    const nte_real_t n_used = (nte_real_t)((rb->fit_count > 1U) ? rb->fit_count : 1U);
    const nte_real_t rms = nte_sqrt(best_cost / n_used);
    const nte_real_t sq_r = nte_sqrt(self->cfg.r_n2);
    const nte_real_t conf = sq_r / ((rms > sq_r) ? rms : sq_r);
    nte_real_t change = NTE_C(0.0);
    for (size_t a = 0U; a < n; a++) {
        const uint8_t j = ids[a];
        const nte_real_t rel = nte_abs(th.v[j] - rb->prev_theta[j]) / nte_abs(rb->prev_theta[j]);
        change = (rel > change) ? rel : change;
    }
    rb->converged = rb->has_refined && (conf >= self->cfg.robust.converged_confidence) &&
                    (change <= self->cfg.robust.converged_change);
    rb->confidence = conf;
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        rb->prev_theta[j] = th.v[j];
    }
    rb->has_refined = true;
    nte_bank_restart_from(self, th.v, self->cfg.robust.restart_p0_u);
    return true;
}

/* What follows a finished simulation (RobustEstimator._lm's loop): the first one's cost, or
 * the trial's acceptance and the damping's update; then the next trial, the other start, or
 * the end.  Returns whether the refinement was adopted now. */
static bool sim_done(nte_t* self, const nte_real_t c)
{
    nte_robust_t* rb = &self->robust;
    const uint8_t* ids = NULL;
    const size_t n = nte_bank_identified(self, &ids);
    if (!sim_is_trial(rb)) {
        rb->cost = c;
        rb->lam = self->cfg.robust.lm_lambda0;
    } else {
        const bool accept = rb->trial_ok && (c < rb->cost);
        if (accept) {
            rb->cost = c;
            for (size_t a = 0U; a < n; a++) {
                rb->v[a] = rb->v_try[a];
                rb->g[a] = rb->g_try[a];
                for (size_t b = 0U; b < n; b++) {
                    rb->A[a][b] = rb->A_try[a][b];
                }
            }
        }
        nte_real_t lam = accept ? (rb->lam / NTE_C(3.0)) : (rb->lam * NTE_C(4.0));
        lam = (lam < NTE_K_ROB_LAMBDA_MIN) ? NTE_K_ROB_LAMBDA_MIN : lam;
        rb->lam = (lam > NTE_K_ROB_LAMBDA_MAX) ? NTE_K_ROB_LAMBDA_MAX : lam;
    }
    if ((rb->iteration + 1) < self->cfg.robust.fit_iterations) {
        rb->iteration++;
        lm_trial(self);
        return false;
    }
    if (rb->start == 0U) {
        for (size_t a = 0U; a < NTE_MODEL_PARAM_COUNT; a++) {
            rb->v_a[a] = rb->v[a];
        }
        rb->cost_a = rb->cost;
        lm_begin(self, 1U);
        return false;
    }
    return refine_end(self);
}

/* One slice: at most cfg.robust.slice_entries buffer entries (0: all that are left), with the
 * bookkeeping of every simulation finished on the way.  Returns whether the refinement was
 * adopted at this slice. */
static bool refine_slice(nte_t* self)
{
    nte_robust_t* rb = &self->robust;
    const uint32_t per_sim = (uint32_t)self->cfg.robust.buffer_len;
    const uint32_t budget = (uint32_t)self->cfg.robust.slice_entries;
    uint32_t left = budget;
    while (rb->refining) {
        const uint32_t todo = per_sim - rb->entry;
        const uint32_t take = ((budget == 0U) || (todo < left)) ? todo : left;
        sim_run(self, take);
        left = left - ((budget == 0U) ? 0U : take);
        if (rb->entry < per_sim) {
            break; /* the budget ended inside this simulation */
        }
        if (sim_done(self, sim_end(self))) {
            return true;
        }
        if ((budget != 0U) && (left == 0U)) {
            break;
        }
    }
    return false;
}

uint32_t nte_robust_step(nte_t* self, const nte_sample_t* sample, const bool valid)
{
    nte_robust_t* rb = &self->robust;
    const nte_real_t l = sample->depth_mm;
    const bool at_surface = valid && !(l > NTE_C(0.0));
    const bool entering = valid && (l > NTE_C(0.0)) && !rb->inside;
    const bool leaving = at_surface && rb->inside;
    if (entering && rb->refining) {
        /* the buffer still holds the last insertion, being fitted: this one is not recorded */
        rb->tainted = true;
    } else if (entering) {
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
    if (leaving && !rb->tainted && (rb->count >= (uint32_t)self->cfg.robust.min_entries)) {
        /* the refinement starts from the bank's estimate of this sample and runs on the
         * buffer as it is (RobustEstimator._fit's snapshot) */
        for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
            rb->start_a[j] = self->th.v[j];
        }
        rb->fit_count = rb->count;
        rb->refining = true;
        lm_begin(self, 0U);
    }
    const bool slicing = rb->refining;
    const bool refined = slicing && refine_slice(self);
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
    status |= slicing ? NTE_STATUS_REFINING : 0U;
    status |= rb->converged ? NTE_STATUS_CONVERGED : 0U;
    return status;
}

#endif /* NTE_ROBUST_BUFFER_LEN > 0 */
