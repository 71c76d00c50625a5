/*
 * The bank of three joint state-parameter EKFs in switching mode (paper §IV, Fig. 1, Table I):
 * reference_py/bank.py in C for one run.  Every branch below is one of the reference's
 * np.where selections; the order of the floating-point operations is the reference's.  Each
 * filter of a sample runs predict -> measure -> update_and_guard, the functions of the same
 * names in bank.py (FilterBank._predict, _measure, _update_and_guard).
 */
#include "nte_bank.h"

#include "nte_ekf.h"
#include "nte_layers.h"
#include "nte_model.h"

/* Table I: the parameters each filter identifies together with z, per model (Model III:
 * Model II with the relaxation strengths in filter 1 and the turn-over length in filter 2;
 * bank.py filter_subsets drops those a configuration switches off, as subset_count does). */
static const uint8_t subset_len[3][NTE_FILTER_COUNT] = {{2U, 2U, 2U}, {1U, 2U, 2U}, {3U, 3U, 2U}};
static const uint8_t subsets[3][NTE_FILTER_COUNT][3] = {
    {{nte_param_f2, nte_param_sigma0, 0U},
     {nte_param_f1, nte_param_sigma1, 0U},
     {nte_param_alpha, nte_param_sigma2, 0U}},
    {{nte_param_sigma0, 0U, 0U},
     {nte_param_f1, nte_param_sigma1, 0U},
     {nte_param_beta, nte_param_sigma2, 0U}},
    {{nte_param_sigma0, nte_param_g_fast, nte_param_g_slow},
     {nte_param_f1, nte_param_sigma1, nte_param_delta},
     {nte_param_beta, nte_param_sigma2, 0U}}};
/* The leading entries of each subset that enter the state equation (bank._dynamic, identified.
 * dynamic): the relaxation strengths and delta come after them and every configuration keeps
 * these, so the count is the table's, not a walk of the list each sample. */
static const uint8_t dynamic_len[3][NTE_FILTER_COUNT] = {{2U, 2U, 2U}, {1U, 2U, 2U}, {1U, 2U, 2U}};
/* reference MODEL_PARAMS: the identified parameters in output order; Model III's by its
 * relaxation branches in use (0, 1, 2), delta last (identified.identified_names) */
static const uint8_t identified_len[3] = {6U, 5U, 5U};
static const uint8_t identified[2][NTE_IDENTIFIED_MAX] = {
    {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2, nte_param_f1, nte_param_f2,
     nte_param_alpha, 0U, 0U},
    {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2, nte_param_f1, nte_param_beta, 0U, 0U,
     0U}};
static const uint8_t identified_m3[3][NTE_IDENTIFIED_MAX] = {
    {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2, nte_param_f1, nte_param_beta,
     nte_param_delta, 0U, 0U},
    {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2, nte_param_f1, nte_param_beta,
     nte_param_g_fast, nte_param_delta, 0U},
    {nte_param_sigma0, nte_param_sigma1, nte_param_sigma2, nte_param_f1, nte_param_beta,
     nte_param_g_fast, nte_param_g_slow, nte_param_delta}};

static size_t model_index(const nte_t* self)
{
    return (self->cfg.model == 1) ? 0U : ((self->cfg.model == 2) ? 1U : 2U);
}

/* identified.relax_count: Model III's relaxation branches in use (0 for Models I and II). */
static size_t relax_count(const nte_t* self)
{
    /* 1 or 2 (nte_config_check) */
    return ((self->cfg.model == 3) && self->cfg.relaxation)
               ? ((self->cfg.relax_branches == 1) ? 1U : 2U)
               : 0U;
}

/* identified.identifies_delta: Model III identifies its turn-over length with the direction
 * memory on. */
static bool identifies_delta(const nte_t* self)
{
    return (self->cfg.model == 3) && self->cfg.direction_memory;
}

/* The parameter count of filter i (identified.filter_subsets). */
static size_t subset_count(const nte_t* self, const size_t i)
{
    const size_t mi = model_index(self);
    if ((mi == 2U) && (i == 0U)) {
        return 1U + relax_count(self);
    }
    if ((mi == 2U) && (i == 1U)) {
        return identifies_delta(self) ? 3U : 2U;
    }
    return (size_t)subset_len[mi][i];
}

/* The identified parameters in output order (identified.identified_names); returns their count. */
static size_t identified_ids(const nte_t* self, const uint8_t** ids)
{
    const size_t mi = model_index(self);
    if (mi < 2U) {
        *ids = identified[mi];
        return (size_t)identified_len[mi];
    }
    const size_t nr = relax_count(self);
    *ids = identified_m3[nr];
    return (size_t)identified_len[mi] + nr + (identifies_delta(self) ? 1U : 0U);
}

/* The leading parameters of ids[0..count) that enter the state equation (bank._dynamic): the
 * relaxation strengths act on the output only and come last in every list. */
static size_t dynamic_count(const uint8_t* ids, const size_t count)
{
    size_t n = 0U;
    while ((n < count) && (ids[n] < (uint8_t)nte_param_g_fast)) {
        n++;
    }
    return n;
}

size_t nte_bank_identified(const nte_t* self, const uint8_t** ids)
{
    return identified_ids(self, ids);
}

/* bank._p0: the initial covariance of a filter with n states, var(u) = p0_u. */
static void p0_with(const nte_t* self, const size_t n, nte_mat3_t P, const nte_real_t p0_u)
{
    for (size_t a = 0U; a < NTE_EKF_N_MAX; a++) {
        for (size_t b = 0U; b < NTE_EKF_N_MAX; b++) {
            P[a][b] = NTE_C(0.0);
        }
    }
    P[0][0] = NTE_C(0.0) + self->cfg.p0_z;
    for (size_t a = 1U; a < n; a++) {
        P[a][a] = NTE_C(0.0) + p0_u;
    }
}

static void p0(const nte_t* self, const size_t n, nte_mat3_t P)
{
    p0_with(self, n, P, self->cfg.p0_u);
}

/* The identified part of the configured nominal f1, f1 - kappa (-f2) (self->kappa set). */
static nte_real_t configured_ex(const nte_t* self)
{
    const nte_config_t* cfg = &self->cfg;
    return (cfg->f1_excess > NTE_C(0.0))
               ? cfg->f1_excess
               : nte_model_f1_excess(cfg->nominal[nte_param_f1], cfg->nominal[nte_param_f2],
                                     self->kappa);
}

/* The configured nominal (bank.reset restores it: a robust restart re-centres it). */
static void set_nominal(nte_t* self)
{
    const nte_config_t* cfg = &self->cfg;
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        self->nominal[j] = cfg->nominal[j];
    }
    if (cfg->model == 1) {
        /* Model I: beta is the fixed normalising constant beta0 */
        self->nominal[nte_param_beta] = cfg->beta0;
    }
    self->kappa = nte_model_f1_kappa(cfg->nominal[nte_param_f2]);
    self->ex_nominal = configured_ex(self);
    const size_t nr = relax_count(self);
    if (nr > 0U) {
        /* relax.relax_odds: the strengths g (fractions) as the odds G the filters scale,
         * G_i = g_i / (1 - sum g), so that g_i = G_i / (1 + sum G) */
        const nte_real_t g0 = cfg->nominal[nte_param_g_fast];
        const nte_real_t g1 = cfg->nominal[nte_param_g_slow];
        const nte_real_t total = (nr == 1U) ? g0 : (g0 + g1);
        const nte_real_t den = NTE_C(1.0) - total;
        self->nominal[nte_param_g_fast] = g0 / den;
        if (nr == 2U) {
            self->nominal[nte_param_g_slow] = g1 / den;
        }
    }
    /* Model III's turn-over length starts at the configured presliding_mm */
    self->nominal[nte_param_delta] = cfg->presliding_mm;
}

/* The filters started on the nominal values: every u 0, covariances P0 with var(u) = p0_u,
 * no gate run (the start and a restart share it). */
static void start_filters(nte_t* self, const nte_real_t p0_u)
{
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        self->u[j] = NTE_C(0.0);
    }
    nte_model_theta(&self->th, self->nominal, self->ex_nominal, self->kappa, self->u);
    for (size_t i = 0U; i < NTE_FILTER_COUNT; i++) {
        p0_with(self, subset_count(self, i) + 1U, self->P[i], p0_u);
        self->gated_run[i] = 0U;
    }
}

void nte_bank_restart_from(nte_t* self, const nte_real_t theta[NTE_PARAM_COUNT],
                           const nte_real_t p0_u)
{
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        self->nominal[j] = theta[j];
    }
    self->ex_nominal = nte_model_f1_excess(theta[nte_param_f1], theta[nte_param_f2], self->kappa);
    start_filters(self, p0_u);
}

void nte_bank_start(nte_t* self)
{
    set_nominal(self);
    start_filters(self, self->cfg.p0_u);
    self->z = NTE_C(0.0);
    self->sdir = NTE_C(0.0);
    self->sdir_du = NTE_C(0.0);
    self->turned = false;
    self->mrel[0] = NTE_C(0.0);
    self->mrel[1] = NTE_C(0.0);
    self->initialised = false;
    self->t_prev_us = 0;
    self->l_prev = NTE_C(0.0);
    self->y_max = NTE_C(0.0);
    self->unit = NTE_C(1.0);
    self->set_layer = 0U;
    self->k_mod3 = 0U;
    /* every output and counter 0 (all bits zero is +0.0 in IEEE 754, which C99's Annex F
     * floats are; the contact front end and the layers publish their fields after this) */
    (void)memset(&self->last, 0, sizeof self->last);
    (void)memset(&self->counters, 0, sizeof self->counters);
}

/* Clip |u|, floor variances, reset the filter when its prior, P or x went bad (bank._guard):
 * P back to its initial value, the state back to the prior (0 where not finite). */
static uint32_t guard(nte_t* self, const size_t n, nte_real_t* x, nte_mat3_t P,
                      const nte_real_t* x_prior, const bool prior_ok, const bool diverged,
                      const nte_real_t z_ss)
{
    const nte_real_t umax = self->cfg.u_max;
    uint32_t status = 0U;
    for (size_t a = 1U; a < n; a++) {
        if (nte_abs(x[a]) > umax) {
            status |= NTE_STATUS_CLIPPED;
        }
        x[a] = (x[a] > umax) ? umax : ((x[a] < -umax) ? -umax : x[a]);
    }
    bool ok = prior_ok && nte_ekf_positive_definite(n, P);
    for (size_t a = 0U; a < n; a++) {
        ok = ok && nte_isfinite(x[a]);
    }
    for (size_t a = 0U; a < n; a++) {
        const nte_real_t floor = (a == 0U) ? self->cfg.var_floor_z : self->cfg.var_floor_u;
        if (P[a][a] < floor) {
            P[a][a] = floor;
            if (ok) {
                status |= NTE_STATUS_FLOORED;
            }
        }
    }
    if (!ok) {
        for (size_t a = 0U; a < n; a++) {
            x[a] = nte_isfinite(x_prior[a]) ? x_prior[a] : NTE_C(0.0);
        }
        p0(self, n, P);
        status |= NTE_STATUS_FILTER_RESET;
        self->counters.filter_resets++;
    }
    if (diverged) {
        x[0] = z_ss;
        status |= NTE_STATUS_DIVERGED;
        self->counters.diverged++;
    }
    return status;
}

/* bank._in_range: the physical range of a predicted force h = sigma0 z l + ... and of z: both
 * |h| and the elastic part |sigma0 z l| within force_max_n (|z| <= force_max_n / (sigma0 l)).
 * NaN is out of range. */
static bool in_range(const nte_t* self, const nte_depth_terms_t* d, const nte_real_t z,
                     const nte_real_t h)
{
    const nte_real_t fmax = self->cfg.force_max_n * self->unit;
    return (nte_abs(h) <= fmax) && (nte_abs((self->th.v[nte_param_sigma0] * z) * d->l) <= fmax);
}

/* One filter of the bank at a running sample (one pass of bank._advance's loop). */
typedef struct step_ctx_t {
    nte_real_t l;
    nte_real_t l_prev;
    nte_real_t dt;
    nte_real_t v;
    nte_real_t y;
    nte_real_t s;
    nte_real_t s_du; /* Model III: ds/du_delta (bank._direction) */
    bool turned;     /* ... and whether the motion went against s since the surface */
    nte_real_t z_prev;
    nte_real_t a_rel[2]; /* Model III: each relaxation branch's decay over the sample */
    bool surface;
    bool gap;
    bool rotate;
    bool tear;                  /* Model III: a layer tore at this sample (nte_layers_watch) */
    nte_real_t tear_z;          /* ... filter 1's prior z at it (tear_rescale) */
    nte_real_t tear_innovation; /* ... and its innovation, N */
    /* exp(-alpha l) at this sample's RK3 stage depths, shared by the filters' predictions
     * and, with alpha unchanged, the output (never NULL) */
    nte_stage_exps_t* stage;
} step_ctx_t;

/* ---- Model III (reference_py/MODEL.md §3b, JACOBIANS.md §7) ---- */

/* relax.relax_fractions: g_i = G_i / (1 + sum G), each in (0, 1), their sum below 1. */
static void relax_fractions(const nte_t* self, const size_t nr, nte_real_t g[2])
{
    const nte_real_t G0 = self->th.v[nte_param_g_fast];
    const nte_real_t G1 = self->th.v[nte_param_g_slow];
    const nte_real_t den = NTE_C(1.0) + ((nr == 1U) ? G0 : (G0 + G1));
    g[0] = G0 / den;
    g[1] = (nr == 2U) ? (G1 / den) : NTE_C(0.0);
}

/* relax.relax_terms: the strengths g, each branch's memory after this sample for the elastic
 * force fe, m_i' = a_i m_i + (1 - a_i) fe, and what the branches take off, sum g_i m_i'. */
static nte_real_t relax_terms(const nte_t* self, const step_ctx_t* c, const size_t nr,
                              const nte_real_t fe, nte_real_t g[2], nte_real_t mp[2])
{
    relax_fractions(self, nr, g);
    for (size_t k = 0U; k < nr; k++) {
        mp[k] = (c->a_rel[k] * self->mrel[k]) + ((NTE_C(1.0) - c->a_rel[k]) * fe);
    }
    return (nr == 1U) ? (g[0] * mp[0]) : ((g[0] * mp[0]) + (g[1] * mp[1]));
}

/* Model III's exponentials of a sample (bank._direction, bank._advance): e[0] =
 * exp(-|dl| / delta) for the direction state (its exponent |dl| / delta kept in *adl for
 * delta's sensitivity), e[1], e[2] = exp(-dt / tau_i) for the relaxation branches, only those
 * in use.  One call site of the inline nte_exp keeps the code small. */
static void model3_exps(const nte_t* self, const bool dir, const size_t nr, const nte_real_t dl,
                        const nte_real_t dt, nte_real_t e[3], nte_real_t* adl)
{
    const nte_real_t den[3] = {self->th.v[nte_param_delta], self->cfg.tau_fast_s,
                               self->cfg.tau_slow_s};
    *adl = NTE_C(0.0);
    for (size_t i = 0U; i < 3U; i++) {
        e[i] = NTE_C(0.0);
        if ((i == 0U) ? dir : (i <= nr)) {
            const nte_real_t x = ((i == 0U) ? nte_abs(dl) : dt) / den[i];
            *adl = (i == 0U) ? x : *adl;
            e[i] = nte_exp(-x);
        }
    }
}

/* bank._direction: the direction state after the depth step dl, ds/dl = (1 - s sign(dl)) /
 * delta integrated exactly: s' = sigma + (s - sigma) E, E = exp(-|dl| / delta), sigma =
 * sign(dl) (s held when dl = 0); its sensitivity to u_delta (delta = nominal e^u, so dE/du =
 * E |dl| / delta; JACOBIANS.md §8): ds'/du = E ds/du + (s - sigma) E |dl| / delta, whose
 * second term counts once the motion has gone against s since the surface (the entry's rise
 * is the tissue's contact, not a turn-over). */
static void direction(const nte_t* self, const nte_real_t dl, const nte_real_t E,
                      const nte_real_t adl, step_ctx_t* c)
{
    const nte_real_t sig = (dl > NTE_C(0.0)) ? NTE_C(1.0)
                                             : ((dl < NTE_C(0.0)) ? NTE_C(-1.0) : NTE_C(0.0));
    c->s = sig + ((self->sdir - sig) * E);
    c->turned = self->turned || ((sig * self->sdir) < NTE_C(0.0));
    c->s_du = (E * self->sdir_du) + (c->turned ? (((self->sdir - sig) * E) * adl) : NTE_C(0.0));
}

/* bank._direction_update: s after filter 2 changed u_delta by du, s + ds/du du within
 * [-1, 1]. */
static nte_real_t direction_update(const step_ctx_t* c, const nte_real_t du)
{
    const nte_real_t s = c->s + (c->s_du * du);
    return (s > NTE_C(1.0)) ? NTE_C(1.0) : ((s < NTE_C(-1.0)) ? NTE_C(-1.0) : s);
}

typedef struct filter_out_t {
    bool active;
    nte_real_t z_post;
    nte_real_t innovation;
    nte_real_t nis;
} filter_out_t;

/* One filter's working set at a running sample: its state (z, its u) and covariance. */
typedef struct filter_work_t {
    size_t n;                    /* 1 + the number of parameters of the filter */
    const uint8_t* names;        /* its parameters (Table I) */
    size_t nd;                   /* the leading ones that enter the state equation */
    nte_real_t x[NTE_EKF_N_MAX]; /* prior state */
    nte_mat3_t P;                /* predicted covariance */
    nte_real_t h[NTE_EKF_N_MAX]; /* measurement Jacobian at the prior */
    nte_real_t innovation;
    nte_real_t r_eff;
    bool in_range; /* the prior z and its force within their range (in_range) */
} filter_work_t;

/* bank._predict: the prior state (z restarted at the surface or after a gap) and the predicted
 * covariance F P F^T + Q of filter i. */
static void predict(nte_t* self, const step_ctx_t* c, const size_t i, const nte_rk3_result_t* pred,
                    const nte_depth_terms_t* d, filter_work_t* w)
{
    const size_t na = w->n - 1U;
    /* out of tissue z is 0; after a gap it has relaxed to its steady state: either way the
     * prior z carries no memory of z(k-1) */
    const bool restart = c->gap || c->surface;
    nte_real_t zp = pred->z;
    if (restart) {
        zp = c->surface ? NTE_C(0.0) : nte_model_steady_state_z(&self->th, d);
    }
    /* z's row of the transition (the parameters' rows are a random walk: nte_ekf_predict) */
    nte_real_t f[NTE_EKF_N_MAX];
    nte_real_t q[NTE_EKF_N_MAX];
    f[0] = restart ? NTE_C(0.0) : pred->dz_dz0;
    q[0] = self->cfg.q_z;
    w->x[0] = zp;
    for (size_t a = 0U; a < na; a++) {
        /* the relaxation strengths act on the output only: dz/du_g = 0 */
        const bool dyn = w->names[a] < (uint8_t)nte_param_g_fast;
        f[a + 1U] = (restart || !dyn) ? NTE_C(0.0) : pred->dz_du[w->names[a]];
        q[a + 1U] = self->q_u[w->names[a]];
        w->x[a + 1U] = self->u[w->names[a]];
    }
    nte_ekf_predict(w->n, self->P[i], f, q, w->P);
}

/* bank._measure: the predicted force, its Jacobian, the innovation and the effective R. */
static uint32_t measure(const nte_t* self, const step_ctx_t* c, const nte_depth_terms_t* d,
                        const bool active, filter_work_t* w)
{
    const size_t na = w->n - 1U;
    uint32_t status = 0U;
    nte_output_terms_t o;
    nte_model_output(&o, &self->th, d, w->x[0], c->s);
    w->h[0] = nte_model_output_dz(&self->th, d, &o);
    const size_t nd = w->nd;
    for (size_t a = 0U; a < nd; a++) {
        w->h[a + 1U] = nte_model_output_du(&self->th, d, w->x[0], &o, w->names[a]);
    }
    /* the elastic rows end after delta's: dfe/du_delta = l fr ds/du_delta */
    size_t ne = nd;
    if ((ne < na) && (w->names[ne] == (uint8_t)nte_param_delta)) {
        w->h[ne + 1U] = (d->l * o.fr) * c->s_du;
        ne++;
    }
    nte_real_t h = o.h;
    const size_t nr = relax_count(self);
    if (nr > 0U) {
        /* relax.relax_output: h = fe - sum g_i m_i'; the elastic row times the fraction a
         * change of fe keeps, 1 - sum g_i (1 - a_i) (the memories' past is known, not a
         * state); dh/du_gk = -g_k (m_k' - sum g_i m_i') */
        nte_real_t g[2];
        nte_real_t mp[2];
        const nte_real_t M = relax_terms(self, c, nr, o.h, g, mp);
        nte_real_t lost = g[0] * (NTE_C(1.0) - c->a_rel[0]);
        if (nr == 2U) {
            lost = lost + (g[1] * (NTE_C(1.0) - c->a_rel[1]));
        }
        const nte_real_t keep = NTE_C(1.0) - lost;
        for (size_t a = 0U; a <= ne; a++) {
            w->h[a] = w->h[a] * keep;
        }
        for (size_t a = ne; a < na; a++) {
            const size_t k = (size_t)w->names[a] - (size_t)nte_param_g_fast;
            w->h[a + 1U] = -(g[k] * (mp[k] - M));
        }
        h = o.h - M;
    }
    w->r_eff = self->cfg.r_n2;
    /* Model III's direction state is known from the depth: no sign to be wrong about */
    if (self->cfg.sign_inflation && !((self->cfg.model == 3) && self->cfg.direction_memory)) {
        /* the data follow sign(v), the model tanh(v/eps): their difference is at most
         * (1 - |s|) l fr, treated as extra measurement noise */
        const nte_real_t dw = (NTE_C(1.0) - nte_abs(c->s)) * (d->l * o.fr);
        const bool moving = nte_abs(c->v) >= self->cfg.v_still_mm_s;
        const nte_real_t ww = dw * dw;
        w->r_eff = self->cfg.r_n2 + (moving ? ww : NTE_C(0.0));
        if (active && moving && (ww > self->cfg.r_n2)) {
            status |= NTE_STATUS_SIGN_UNCERTAIN;
        }
    }
    w->innovation = c->y - h;
    w->in_range = in_range(self, d, w->x[0], h);
    return status;
}

/* layers.tear_prior: at a tear the needle meets new tissue.  The filter's covariance restarts
 * at P0 (the estimates carry over as the new layer's start, with the uncertainty of a start),
 * and the tear's own sample updates z alone (its row on the parameters 0): the drop is the
 * tissue's, which no parameter of the torn layer explains. */
static void tear_prior(const nte_t* self, filter_work_t* w)
{
    p0(self, w->n, w->P);
    for (size_t a = 1U; a < NTE_EKF_N_MAX; a++) {
        w->h[a] = NTE_C(0.0);
    }
}

/* layers.tear_rescale: after a tear's sample the model's force is scaled down to the force
 * measured after the drop, by r = y / h (h: filter 1's prior force), at least
 * NTE_K_LAYER_TEAR_RATIO_MIN and only for a drop.  z, beta and sigma2 times r scale the whole
 * model exactly (dz/dt = l (beta - sigma0 z / g) and the force are linear in the three), and
 * the relaxation memories follow the elastic force: the tear ends on the measured force
 * without moving a parameter along the gain (the derivation and the measurements:
 * reference_py/layers.py).  Returns the posterior z. */
static nte_real_t tear_rescale(nte_t* self, const step_ctx_t* c, const nte_real_t z_post)
{
    const nte_real_t h = c->y - c->tear_innovation;
    nte_real_t r = (h > NTE_C(0.0)) ? (c->y / h) : NTE_C(1.0);
    if (!(r < NTE_C(1.0))) {
        return z_post;
    }
    r = (r > NTE_K_LAYER_TEAR_RATIO_MIN) ? r : NTE_K_LAYER_TEAR_RATIO_MIN;
    self->nominal[nte_param_beta] *= r;
    self->nominal[nte_param_sigma2] *= r;
    self->th.v[nte_param_beta] *= r;
    self->th.v[nte_param_sigma2] *= r;
    self->mrel[0] *= r;
    self->mrel[1] *= r;
    return c->tear_z * r;
}

/* bank._update_and_guard: the gated Joseph update (active filters only), the guard, and the
 * commit of the filter's covariance and parameters to the shared model. */
static uint32_t update_and_guard(nte_t* self, const size_t i, const nte_depth_terms_t* d,
                                 const bool tear, filter_work_t* w, filter_out_t* fo)
{
    /* 2 <= w->n <= NTE_EKF_N_MAX always (z and a subset); the bounds say so to the
     * compiler's and the static analyser's array checks */
    const size_t n = (w->n < 2U) ? 2U : ((w->n < NTE_EKF_N_MAX) ? w->n : NTE_EKF_N_MAX);
    const size_t na = n - 1U;
    uint32_t status = 0U;
    nte_real_t xn[NTE_EKF_N_MAX];
    for (size_t a = 0U; a < n; a++) {
        xn[a] = w->x[a];
    }
    /* the update writes the posterior into the filter's own covariance (w->P stays the prior,
     * which the checks below judge), and the guard works on it */
    nte_real_t(*const Pn)[NTE_EKF_N_MAX] = self->P[i];
    /* a gate that refused too many samples in a row would lock the filter out: open it */
    const bool open_gate = (self->gated_run[i] >= (uint32_t)self->cfg.gate_reopen_after) || tear;
    /* u_step_max: the update's step bound (reference_py/config.py U_STEP_MAX); frozen: the
     * parameters held (nte.h HELD PARAMETERS) */
    const nte_ekf_update_t upd = nte_ekf_joseph_update(n, xn, w->P, Pn, w->h, w->innovation,
                                                       w->r_eff, self->gate2, open_gate, fo->active,
                                                       self->cfg.u_step_max, self->frozen);
    if (!(fo->active && upd.accepted)) {
        /* not updated: the posterior is the prior */
        for (size_t a = 0U; a < n; a++) {
            for (size_t b = 0U; b < n; b++) {
                Pn[a][b] = w->P[a][b];
            }
        }
    }
    if (fo->active) {
        if (upd.accepted) {
            self->gated_run[i] = 0U;
        } else {
            status |= NTE_STATUS_GATED;
            self->gated_run[i]++;
            self->counters.gated++;
        }
        /* a diverged prior's innovation is not published (it may not be finite) */
        fo->innovation = w->in_range ? w->innovation : NTE_C(0.0);
        /* an overflowed NIS (tiny R) is published saturated at COST_HUGE */
        const nte_real_t nis = (upd.nis <= NTE_K_ROB_COST_HUGE) ? upd.nis : NTE_K_ROB_COST_HUGE;
        fo->nis = w->in_range ? nis : NTE_C(0.0);
    }
    /* a prior that is not positive definite (or a non-positive innovation variance) can still
     * yield a plausible-looking posterior: judge the filter on both */
    /* and a prior whose force left its physical range has diverged: z to its steady state */
    const bool prior_ok = nte_ekf_positive_definite(n, w->P) && (upd.s > NTE_C(0.0)) && w->in_range;
    nte_real_t z_ss = NTE_C(0.0);
    if (!w->in_range) {
        z_ss = nte_model_steady_state_z(&self->th, d);
        z_ss = nte_isfinite(z_ss) ? z_ss : NTE_C(0.0);
    }
    status |= guard(self, n, xn, Pn, w->x, prior_ok, !w->in_range, z_ss);
    for (size_t a = 0U; a < na; a++) {
        self->u[w->names[a]] = xn[a + 1U];
    }
    nte_model_refresh(&self->th, self->nominal, self->ex_nominal, self->kappa, self->u, w->names,
                      na);
    fo->z_post = xn[0];
    return status;
}

/* The depth terms at this sample's depth with the current theta, from the sample's last
 * stage exponential when it was taken at the same depth (both clamped: equal values are equal
 * bits) with the same alpha (Model I's third filter may have changed it since). */
static void sample_depth_terms(const nte_t* self, const step_ctx_t* c, nte_depth_terms_t* d)
{
    const nte_stage_exps_t* st = c->stage;
    const nte_real_t alpha = self->th.v[nte_param_alpha];
    if (st->ready && !(st->l_end < c->l) && !(st->l_end > c->l) && !(st->alpha < alpha) &&
        !(st->alpha > alpha)) {
        nte_model_depth_terms_e(d, &self->th, c->l, st->e[(size_t)2U * (size_t)self->cfg.substeps]);
    } else {
        nte_model_depth_terms(d, &self->th, c->l);
    }
}

/* The depth terms at this sample's depth with the current theta: the prediction's end when
 * it ran with this theta (same_theta: the filter's own prediction, or the shared one before
 * any filter updated) and ended at the same depth.  Both depths are clamped (never NaN, never
 * -0), so equal values are equal bits: one exp and one division fewer per filter. */
static void depth_terms_now(const nte_t* self, const step_ctx_t* c, const nte_rk3_result_t* pred,
                            const bool same_theta, nte_depth_terms_t* d)
{
    if (same_theta && !(pred->end.l < c->l) && !(pred->end.l > c->l)) {
        *d = pred->end;
    } else {
        sample_depth_terms(self, c, d);
    }
}

/* One filter of the bank at a running sample (one pass of bank._advance's loop). */
static uint32_t run_filter(nte_t* self, step_ctx_t* c, const size_t i,
                           const nte_rk3_result_t* shared, filter_out_t* fo)
{
    const size_t mi = model_index(self);
    /* predict writes x and P, measure every row of h the filter has and the rest; h's other
     * rows are cleared for the tear's prior, and x and the scalars so that no field is ever
     * read unset (what cppcheck checks of the whole set).  Not a memset of the whole set:
     * that library call cost more than the filter's covariance prediction. */
    filter_work_t w;
    w.n = subset_count(self, i) + 1U;
    w.names = subsets[mi][i];
    w.nd = (size_t)dynamic_len[mi][i];
    for (size_t a = 0U; a < NTE_EKF_N_MAX; a++) {
        w.x[a] = NTE_C(0.0);
        w.h[a] = NTE_C(0.0);
    }
    w.innovation = NTE_C(0.0);
    w.r_eff = NTE_C(0.0);
    w.in_range = false;
    nte_rk3_result_t own;
    fo->innovation = NTE_C(0.0);
    fo->nis = NTE_C(0.0);
    const nte_rk3_result_t* pred = shared;
    if (c->rotate) {
        fo->active = (self->k_mod3 == (uint8_t)i);
    } else {
        nte_model_rk3(&own, &self->th, c->z_prev, c->l_prev, c->l, c->dt, self->cfg.substeps,
                      w.names, w.nd, c->stage);
        pred = &own;
        fo->active = true;
    }
    /* predict_only: the model alone, no filter updates (z is filter 0's prior, guarded) */
    fo->active = fo->active && !self->cfg.predict_only;
    nte_depth_terms_t d;
    depth_terms_now(self, c, pred, !c->rotate || (i == 0U), &d);
    predict(self, c, i, pred, &d, &w);
    uint32_t status = measure(self, c, &d, fo->active, &w);
    if ((i == 0U) && (self->cfg.model == 3) && self->cfg.layers) {
        /* layers.RuptureDetector.watch: the rupture detector on filter 1's prior innovation, before any
         * update of this sample, so that a tear's sample is treated as one (tear_prior); the
         * filters run on running samples only (at the first one the detector is at its start,
         * where the reference's call leaves it) */
        const bool watched = !self->cfg.predict_only && w.in_range;
        const uint32_t torn = nte_layers_watch(self, c->l, c->v,
                                               watched ? w.innovation : NTE_C(0.0));
        c->tear = torn != 0U;
        status |= torn;
        c->tear_z = w.x[0];
        c->tear_innovation = w.innovation;
    }
    if (c->tear) {
        tear_prior(self, &w);
    }
    status |= update_and_guard(self, i, &d, c->tear, &w, fo);
    return status;
}

/* Model III's layer sets (layers.LayerSets.enter; nte.h THE LAYER SETS): in predict-only
 * mode the deepest set whose start the tip has reached since it entered replaces the nominal
 * sigma0, f1, beta, sigma2 (their u restart at 0); out of the tissue the configured ones
 * return. */
static void enter_layer_sets(nte_t* self, const nte_real_t l, const bool surface)
{
    static const uint8_t ids[NTE_LAYER_SET_VALUES] = {
        (uint8_t)nte_param_sigma0, (uint8_t)nte_param_f1, (uint8_t)nte_param_beta,
        (uint8_t)nte_param_sigma2};
    const nte_config_t* cfg = &self->cfg;
    uint32_t target = self->set_layer;
    if (surface) {
        target = 0U;
    } else if (cfg->predict_only) {
        uint32_t reached = 0U;
        for (uint32_t k = 0U; k < cfg->layer_sets; k++) {
            reached += (l >= cfg->layer_set[k].start_mm) ? 1U : 0U;
        }
        target = (reached > target) ? reached : target;
    }
    if (target == self->set_layer) {
        return;
    }
    for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
        self->nominal[ids[j]] = (target == 0U) ? cfg->nominal[ids[j]]
                                               : cfg->layer_set[target - 1U].values[j];
        self->u[ids[j]] = NTE_C(0.0);
    }
    self->ex_nominal = (target == 0U)
                           ? configured_ex(self)
                           : nte_model_f1_excess(cfg->layer_set[target - 1U].values[nte_layer_f1],
                                                 cfg->nominal[nte_param_f2], self->kappa);
    nte_model_refresh(&self->th, self->nominal, self->ex_nominal, self->kappa, self->u, ids,
                      NTE_LAYER_SET_VALUES);
    self->set_layer = target;
}

void nte_bank_advance(nte_t* self, const bool first, const nte_real_t dt, const nte_real_t l_in,
                      const nte_real_t v, const nte_real_t y, nte_output_t* out)
{
    /* every field is written below; these only where a branch may not write them (set here
     * rather than by a memset of the whole context: a library call on every sample) */
    step_ctx_t c;
    nte_stage_exps_t stage; /* its e[] is written before it is read (nte_model.h) */
    stage.ready = false;
    stage.l_end = NTE_C(0.0);
    c.s = NTE_C(0.0);
    c.s_du = NTE_C(0.0);
    c.turned = false;
    c.tear = false;
    c.tear_z = NTE_C(0.0);
    c.tear_innovation = NTE_C(0.0);
    /* every filter's prediction steps from the same depths with the same alpha: one exp per
     * stage for the three (and the output), not one per stage per filter; empty until the
     * first prediction of the sample fills it */
    c.stage = &stage;
    for (size_t i = 0U; i < NTE_FILTER_COUNT; i++) {
        out->filter_status[i] = 0U;
    }
    c.l = nte_model_clamp_depth(l_in);
    c.l_prev = nte_model_clamp_depth(self->l_prev);
    c.dt = dt;
    c.v = v;
    c.y = y;
    c.surface = !(c.l > NTE_C(0.0));
    c.gap = (!first) && (dt > self->cfg.dt_max_s);
    const bool m3 = self->cfg.model == 3;
    if (m3 && (self->cfg.layer_sets > 0U)) {
        enter_layer_sets(self, c.l, c.surface);
    }
    const size_t nr = relax_count(self);
    /* 0 at the surface and at the first sample, like z */
    const bool dir = m3 && self->cfg.direction_memory && !(c.surface || first);
    const nte_real_t dl = c.l - c.l_prev;
    nte_real_t e3[3];
    nte_real_t adl;
    model3_exps(self, dir, nr, dl, dt, e3, &adl);
    if (m3 && self->cfg.direction_memory) {
        if (dir) {
            direction(self, dl, e3[0], adl, &c);
        }
    } else {
        c.s = nte_model_smooth_sign(v, self->cfg.eps_mm_s);
    }
    /* each relaxation branch's decay over this sample: exact for an input held over the
     * sample, stable at every rate */
    c.a_rel[0] = e3[1];
    c.a_rel[1] = e3[2];
    c.z_prev = self->z;
    c.rotate = self->cfg.schedule == nte_schedule_rotate;
    uint32_t status = c.surface ? NTE_STATUS_OUT_OF_TISSUE : 0U;
    nte_real_t innovation0 = NTE_C(0.0);
    nte_real_t nis0 = NTE_C(0.0);
    if (!first) {
        if (c.gap) {
            status |= NTE_STATUS_GAP;
            self->counters.gaps++;
        }
        /* written by the rotate schedule's one prediction below, read by no other schedule */
        nte_rk3_result_t shared;
        if (c.rotate) {
            /* one prediction, with every identified parameter's sensitivity, serves all three */
            const uint8_t* ids = NULL;
            const size_t n_ids = identified_ids(self, &ids);
            nte_model_rk3(&shared, &self->th, c.z_prev, c.l_prev, c.l, dt, self->cfg.substeps, ids,
                          dynamic_count(ids, n_ids), c.stage);
        }
        nte_real_t z_post = c.z_prev;
        for (size_t i = 0U; i < NTE_FILTER_COUNT; i++) {
            filter_out_t fo;
            const nte_real_t u_delta = self->u[nte_param_delta];
            const uint32_t filter_status = run_filter(self, &c, i, &shared, &fo);
            status |= filter_status;
            out->filter_status[i] = filter_status & NTE_STATUS_FILTER_BITS;
            if ((i == 1U) && identifies_delta(self)) {
                /* the direction state of this sample follows filter 2's update of delta */
                c.s = direction_update(&c, self->u[nte_param_delta] - u_delta);
            }
            if (fo.active || (self->cfg.predict_only && (i == 0U))) {
                z_post = fo.z_post;
                if (c.rotate || (i == 0U)) {
                    innovation0 = fo.innovation;
                    nis0 = fo.nis;
                }
            }
        }
        if (c.tear && !self->frozen) {
            /* the model scaled to the force after the drop (held parameters stay held) */
            z_post = tear_rescale(self, &c, z_post);
        }
        self->z = c.surface ? NTE_C(0.0) : z_post;
    }
    /* posterior output with the final shared model */
    nte_depth_terms_t d;
    nte_output_terms_t o;
    sample_depth_terms(self, &c, &d);
    if (first) {
        /* z starts at its steady state, as after a gap (0 out of tissue): a record or a
         * restarted node that begins inside the tissue does not start from a z the force
         * contradicts */
        const nte_real_t z_ss = nte_model_steady_state_z(&self->th, &d);
        self->z = nte_isfinite(z_ss) ? z_ss : NTE_C(0.0);
    }
    nte_model_output(&o, &self->th, &d, self->z, c.s);
    nte_real_t force = o.h;
    /* Model III: the branches take their share off the elastic force o.h; mp holds the
     * memories for the elastic force finally published (committed below) */
    nte_real_t g[2];
    nte_real_t mp[2] = {NTE_C(0.0), NTE_C(0.0)};
    if (nr > 0U) {
        force = o.h - relax_terms(self, &c, nr, o.h, g, mp);
    }
    nte_real_t limit = self->cfg.force_max_n * self->unit;
    if (!self->cfg.predict_only) {
        /* the data's bound (bank.py DATA_BOUND): the largest |force| of this insertion so far,
         * this sample's included; after a sample out of tissue it starts again */
        const nte_real_t ay = nte_abs(y);
        const nte_real_t y_max = (ay > self->y_max) ? ay : self->y_max;
        self->y_max = c.surface ? NTE_C(0.0) : y_max;
        const nte_real_t noise_sd = nte_sqrt(self->cfg.r_n2);
        const nte_real_t base = (y_max > noise_sd) ? y_max : noise_sd;
        const nte_real_t bound = NTE_K_BANK_DATA_BOUND * base;
        limit = (bound < limit) ? bound : limit;
    }
    if (!(in_range(self, &d, self->z, force) && (nte_abs(force) <= limit))) {
        /* never publish a force or z outside their range (nor beyond the data's bound): z to
         * its steady state, and if the parameters still put the force out of range, the force
         * saturated at the limit (NaN: 0) */
        const nte_real_t z_ss = nte_model_steady_state_z(&self->th, &d);
        self->z = nte_isfinite(z_ss) ? z_ss : NTE_C(0.0);
        nte_model_output(&o, &self->th, &d, self->z, c.s);
        const nte_real_t fmax = limit;
        force = o.h;
        if (nr > 0U) {
            force = o.h - relax_terms(self, &c, nr, o.h, g, mp);
        }
        if (!(nte_abs(force) <= fmax)) {
            force = (force > fmax) ? fmax : ((force < -fmax) ? -fmax : NTE_C(0.0));
        }
        status |= NTE_STATUS_DIVERGED;
        self->counters.diverged++;
    }
    if (nr > 0U) {
        /* commit the memories with the posterior elastic force (0 out of tissue and at the
         * first sample, like z) */
        for (size_t k = 0U; k < nr; k++) {
            self->mrel[k] = (first || c.surface) ? NTE_C(0.0) : mp[k];
        }
    }
    if (m3) {
        self->sdir = c.s;
        self->sdir_du = c.s_du;
        self->turned = c.turned;
    }
    out->force_hat_n = force;
    out->z = self->z;
    out->innovation_n = first ? (y - force) : innovation0;
    out->nis = first ? NTE_C(0.0) : nis0;
    out->status = status;
}

size_t nte_bank_params(const nte_t* self, nte_param_estimate_t* out, const size_t capacity)
{
    const size_t mi = model_index(self);
    const size_t nr = relax_count(self);
    const uint8_t* ids = NULL;
    const size_t count = identified_ids(self, &ids);
    nte_real_t g[2] = {NTE_C(0.0), NTE_C(0.0)};
    if (nr > 0U) {
        relax_fractions(self, nr, g);
    }
    for (size_t j = 0U; (j < count) && (j < capacity) && (out != NULL); j++) {
        const uint8_t id = ids[j];
        out[j].id = (nte_param_id_t)id;
        out[j].value = NTE_C(0.0);
        out[j].sd = NTE_C(0.0);
        if (!self->initialised) {
            continue;
        }
        /* the filter that owns the parameter, and its index in that filter's state */
        for (size_t i = 0U; i < NTE_FILTER_COUNT; i++) {
            for (size_t a = 0U; a < subset_count(self, i); a++) {
                if (subsets[mi][i][a] == id) {
#if NTE_DOUBLE
                    const nte_real_t sd_u = sqrt(self->P[i][a + 1U][a + 1U]);
#else
                    const nte_real_t sd_u = sqrtf(self->P[i][a + 1U][a + 1U]);
#endif
                    if ((id == (uint8_t)nte_param_g_fast) || (id == (uint8_t)nte_param_g_slow)) {
                        /* g = G / (1 + sum G): dg_k/du_k = g_k (1 - g_k) */
                        const nte_real_t gk = g[id - (uint8_t)nte_param_g_fast];
                        out[j].value = gk;
                        out[j].sd = nte_abs(gk * (NTE_C(1.0) - gk)) * sd_u;
                        continue;
                    }
                    const nte_real_t dth = (id == (uint8_t)nte_param_f1) ? self->th.ex
                                                                         : self->th.v[id];
                    out[j].value = self->th.v[id];
                    out[j].sd = nte_abs(dth) * sd_u;
                    if ((id == (uint8_t)nte_param_beta) || (id == (uint8_t)nte_param_sigma2)) {
                        /* force scales: from the bank's unit back to N (nte_bank_set_unit) */
                        out[j].value = out[j].value / self->unit;
                        out[j].sd = out[j].sd / self->unit;
                    }
                }
            }
        }
    }
    return count;
}

void nte_bank_set_unit(nte_t* self, const nte_real_t unit)
{
    if (!((unit < self->unit) || (unit > self->unit))) {
        return; /* unchanged (bank.py: k != kf; never NaN) */
    }
    /* z, beta and sigma2 scaled by r scale the whole model (nte_bank.c tear_rescale); the
     * nominal beta and sigma2 are left as configured (bank.py _scale_to_sensor says why) */
    const nte_real_t r = unit / self->unit;
    self->z = self->z * r;
    self->mrel[0] = self->mrel[0] * r;
    self->mrel[1] = self->mrel[1] * r;
    self->y_max = self->y_max * r;
    self->unit = unit;
}

void nte_bank_unscale(const nte_t* self, nte_output_t* out)
{
    out->force_hat_n = out->force_hat_n / self->unit;
    out->z = out->z / self->unit;
    out->innovation_n = out->innovation_n / self->unit;
}
