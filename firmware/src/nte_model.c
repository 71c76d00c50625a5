/*
 * The force model and its RK3 step: reference_py/model.py and reference_py/rk3.py in C.
 * Every expression keeps the reference's parenthesisation; do not "simplify" any of them, the
 * bits would change.  Derivations of every partial derivative: reference_py/JACOBIANS.md.
 */
#include "nte_model.h"

void nte_model_theta(nte_theta_t* th, const nte_real_t nominal[NTE_PARAM_COUNT],
                     const nte_real_t ex_nominal, const nte_real_t kappa,
                     const nte_real_t u[NTE_PARAM_COUNT])
{
    for (uint8_t i = 0U; i < NTE_PARAM_COUNT; i++) {
        if (i != (uint8_t)nte_param_f1) {
            th->v[i] = nominal[i] * nte_exp(u[i]);
        }
    }
    th->ex = ex_nominal * nte_exp(u[nte_param_f1]);
    th->mkf2 = -(kappa * th->v[nte_param_f2]);
    th->v[nte_param_f1] = th->mkf2 + th->ex;
}

void nte_model_refresh(nte_theta_t* th, const nte_real_t nominal[NTE_PARAM_COUNT],
                       const nte_real_t ex_nominal, const nte_real_t kappa,
                       const nte_real_t u[NTE_PARAM_COUNT], const uint8_t* ids, const size_t count)
{
    bool f1 = false;
    bool f2 = false;
    for (size_t a = 0U; a < count; a++) {
        const uint8_t i = ids[a];
        if (i == (uint8_t)nte_param_f1) {
            f1 = true;
            continue;
        }
        if (i == (uint8_t)nte_param_f2) {
            f2 = true;
        }
        th->v[i] = nominal[i] * nte_exp(u[i]);
    }
    if (f1) {
        th->ex = ex_nominal * nte_exp(u[nte_param_f1]);
    }
    if (f1 || f2) {
        th->mkf2 = -(kappa * th->v[nte_param_f2]);
        th->v[nte_param_f1] = th->mkf2 + th->ex;
    }
}

nte_real_t nte_model_clamp_depth(const nte_real_t l) { return (l > NTE_C(0.0)) ? l : NTE_C(0.0); }

/* The depth terms from e = exp(-alpha l); inlined into both entries below, so the bank's and
 * the refinement's hot paths call one function, not two. */
NTE_SPECIALISE void terms_from_e(nte_depth_terms_t* d, const nte_theta_t* th, const nte_real_t l,
                                 const nte_real_t e)
{
    d->l = l;
    d->e = e;
    d->g = th->v[nte_param_f1] + (th->v[nte_param_f2] * d->e);
    d->inv_g = NTE_C(1.0) / d->g;
    d->b = th->v[nte_param_sigma0] * d->inv_g;
    d->dg_dalpha = -(th->v[nte_param_f2] * (l * d->e));
}

void nte_model_depth_terms(nte_depth_terms_t* d, const nte_theta_t* th, const nte_real_t l)
{
    terms_from_e(d, th, l, nte_exp(-(th->v[nte_param_alpha] * l)));
}

void nte_model_depth_terms_e(nte_depth_terms_t* d, const nte_theta_t* th, const nte_real_t l,
                             const nte_real_t e)
{
    terms_from_e(d, th, l, e);
}

nte_real_t nte_model_rate(const nte_theta_t* th, const nte_depth_terms_t* d, const nte_real_t z)
{
    return d->l * (th->v[nte_param_beta] - (d->b * z));
}

nte_real_t nte_model_rate_dz(const nte_depth_terms_t* d) { return -(d->l * d->b); }

nte_real_t nte_model_rate_du(const nte_theta_t* th, const nte_depth_terms_t* d, const nte_real_t z,
                             const uint8_t id, bool* present)
{
    *present = true;
    switch (id) {
    case nte_param_sigma1:
    case nte_param_sigma2: *present = false; return NTE_C(0.0);
    case nte_param_sigma0: return (-(d->l * (z * d->inv_g))) * th->v[nte_param_sigma0];
    case nte_param_beta: return d->l * th->v[nte_param_beta];
    default: break;
    }
    /* every other parameter acts through g: d(rate)/dg = l b z / g */
    const nte_real_t rate_g = d->l * ((d->b * z) * d->inv_g);
    if (id == (uint8_t)nte_param_f1) {
        return rate_g * th->ex;
    }
    if (id == (uint8_t)nte_param_f2) {
        /* d g / d u_f2 = e f2 (direct) + mkf2 (f1 follows f2) */
        return ((rate_g * d->e) * th->v[nte_param_f2]) + (rate_g * th->mkf2);
    }
    return (rate_g * d->dg_dalpha) * th->v[nte_param_alpha];
}

void nte_model_output(nte_output_terms_t* o, const nte_theta_t* th, const nte_depth_terms_t* d,
                      const nte_real_t z, const nte_real_t s)
{
    o->m = th->v[nte_param_beta] - (d->b * z);
    o->fr = ((th->v[nte_param_sigma1] * d->e) * o->m) + th->v[nte_param_sigma2];
    o->sl = s * d->l;
    o->h = ((th->v[nte_param_sigma0] * z) * d->l) + (o->sl * o->fr);
}

nte_real_t nte_model_output_dz(const nte_theta_t* th, const nte_depth_terms_t* d,
                               const nte_output_terms_t* o)
{
    return (th->v[nte_param_sigma0] * d->l) - (o->sl * ((th->v[nte_param_sigma1] * d->e) * d->b));
}

nte_real_t nte_model_output_du(const nte_theta_t* th, const nte_depth_terms_t* d,
                               const nte_real_t z, const nte_output_terms_t* o, const uint8_t id)
{
    const nte_real_t s1e = th->v[nte_param_sigma1] * d->e;
    switch (id) {
    case nte_param_sigma0:
        return ((z * d->l) - (o->sl * (s1e * (z * d->inv_g)))) * th->v[nte_param_sigma0];
    case nte_param_sigma1: return (o->sl * (d->e * o->m)) * th->v[nte_param_sigma1];
    case nte_param_sigma2: return o->sl * th->v[nte_param_sigma2];
    case nte_param_beta: return (o->sl * s1e) * th->v[nte_param_beta];
    default: break;
    }
    const nte_real_t h_g = o->sl * (s1e * ((d->b * z) * d->inv_g));
    if (id == (uint8_t)nte_param_f1) {
        return h_g * th->ex;
    }
    if (id == (uint8_t)nte_param_f2) {
        return ((h_g * d->e) * th->v[nte_param_f2]) + (h_g * th->mkf2);
    }
    const nte_real_t direct = o->sl * ((th->v[nte_param_sigma1] * o->m) * (-(d->l * d->e)));
    return (direct + (h_g * d->dg_dalpha)) * th->v[nte_param_alpha];
}

nte_real_t nte_model_steady_state_z(const nte_theta_t* th, const nte_depth_terms_t* d)
{
    const nte_real_t zss = (th->v[nte_param_beta] * d->g) / th->v[nte_param_sigma0];
    return (d->l > NTE_C(0.0)) ? zss : NTE_C(0.0);
}

nte_real_t nte_model_smooth_sign(const nte_real_t v, const nte_real_t eps)
{
    return nte_tanh(v / eps);
}

/* The depth terms at stage k of the sample's RK3 step: from the shared exponential when
 * another filter's step took it, else with its own exp, kept for the next filter. */
static void stage_terms(nte_depth_terms_t* d, const nte_theta_t* th, const nte_real_t l,
                        nte_stage_exps_t* shared, const int32_t k)
{
    if ((shared != NULL) && shared->ready) {
        nte_model_depth_terms_e(d, th, l, shared->e[k]);
    } else {
        nte_model_depth_terms(d, th, l);
        if (shared != NULL) {
            shared->e[k] = d->e;
        }
    }
}

void nte_model_rk3(nte_rk3_result_t* res, const nte_theta_t* th, nte_real_t z, const nte_real_t l_a,
                   const nte_real_t l_b, const nte_real_t dt, const int32_t substeps,
                   const uint8_t* ids, const size_t count, nte_stage_exps_t* shared)
{
    const nte_real_t n = (nte_real_t)substeps;
    const nte_real_t h = dt / n;
    const nte_real_t h2 = h * NTE_C(0.5);
    const nte_real_t h6 = h / NTE_C(6.0);
    const nte_real_t twoh = h * NTE_C(2.0);
    const nte_real_t four = NTE_C(4.0);
    const nte_real_t bound = NTE_K_EXP_STEP_BOUND;
    const nte_real_t dl = l_b - l_a;
    nte_real_t s_z = NTE_C(1.0);
    /* one sensitivity per requested parameter (at most NTE_MODEL_PARAM_COUNT) */
    nte_real_t s_u[NTE_MODEL_PARAM_COUNT] = {NTE_C(0.0)};
    /* the end of one sub-step is the start of the next: its depth terms are computed once */
    nte_depth_terms_t d1;
    /* tau = 0 / n, which is 0 for every n >= 1: no division */
    stage_terms(&d1, th, nte_model_clamp_depth(l_a + (dl * NTE_C(0.0))), shared, 0);
    for (int32_t j = 0; (j < substeps) && (j < NTE_RANGE_SUBSTEPS_MAX); j++) {
        const nte_real_t taum = (nte_real_t)((2 * j) + 1) / (n * NTE_C(2.0));
        const nte_real_t tau1 = (nte_real_t)(j + 1) / n;
        const nte_depth_terms_t d0 = d1;
        nte_depth_terms_t dm;
        stage_terms(&dm, th, nte_model_clamp_depth(l_a + (dl * taum)), shared, (2 * j) + 1);
        stage_terms(&d1, th, nte_model_clamp_depth(l_a + (dl * tau1)), shared, (2 * j) + 2);
        const nte_real_t fz0 = nte_model_rate_dz(&d0);
        const nte_real_t fzm = nte_model_rate_dz(&dm);
        const nte_real_t fz1 = nte_model_rate_dz(&d1);

        /* the largest decay rate -fz of the sub-step chooses the step (NaN compares false) */
        nte_real_t lo = (fzm < fz0) ? fzm : fz0;
        lo = (fz1 < lo) ? fz1 : lo;
        if ((h * (-lo)) > bound) {
            /* exponential midpoint: z1 = zq + E (z0 - zq), exact for frozen mid-depth terms */
            const nte_real_t lam = -fzm;
            const nte_real_t E = nte_exp(-(h * lam));
            const nte_real_t zq = th->v[nte_param_beta] / dm.b;
            const nte_real_t dz0 = z - zq;
            const nte_real_t one_e = NTE_C(1.0) - E;
            s_z = E * s_z;
            for (size_t p = 0U; (p < count) && (p < (size_t)NTE_MODEL_PARAM_COUNT); p++) {
                nte_real_t lam_u = NTE_C(0.0);
                nte_real_t zq_u = NTE_C(0.0);
                if (nte_model_decay_du(th, &dm, ids[p], &lam_u, &zq_u)) {
                    s_u[p] = ((E * s_u[p]) - ((dz0 * E) * (h * lam_u))) + (one_e * zq_u);
                } else {
                    s_u[p] = E * s_u[p];
                }
            }
            z = zq + (E * dz0);
            continue;
        }

        const nte_real_t k1 = nte_model_rate(th, &d0, z);
        const nte_real_t z2 = z + (h2 * k1);
        const nte_real_t k2 = nte_model_rate(th, &dm, z2);
        const nte_real_t z3 = (z - (h * k1)) + (twoh * k2);
        const nte_real_t k3 = nte_model_rate(th, &d1, z3);

        /* sensitivity of z: the same stages, differentiated (the rate is linear in z) */
        const nte_real_t a1 = fz0 * s_z;
        const nte_real_t a2 = fzm * (s_z + (h2 * a1));
        const nte_real_t a3 = fz1 * ((s_z - (h * a1)) + (twoh * a2));
        s_z = s_z + (h6 * ((a1 + (four * a2)) + a3));

        for (size_t p = 0U; (p < count) && (p < (size_t)NTE_MODEL_PARAM_COUNT); p++) {
            const nte_real_t s = s_u[p];
            bool present = false;
            nte_real_t q1 = fz0 * s;
            const nte_real_t r1 = nte_model_rate_du(th, &d0, z, ids[p], &present);
            if (present) {
                q1 = q1 + r1;
            }
            nte_real_t q2 = fzm * (s + (h2 * q1));
            const nte_real_t r2 = nte_model_rate_du(th, &dm, z2, ids[p], &present);
            if (present) {
                q2 = q2 + r2;
            }
            nte_real_t q3 = fz1 * ((s - (h * q1)) + (twoh * q2));
            const nte_real_t r3 = nte_model_rate_du(th, &d1, z3, ids[p], &present);
            if (present) {
                q3 = q3 + r3;
            }
            s_u[p] = s + (h6 * ((q1 + (four * q2)) + q3));
        }
        z = z + (h6 * ((k1 + (four * k2)) + k3));
    }
    res->z = z;
    res->dz_dz0 = s_z;
    res->end = d1;
    if (shared != NULL) {
        shared->l_end = d1.l;
        shared->alpha = th->v[nte_param_alpha];
        shared->ready = true;
    }
    for (size_t p = 0U; (p < count) && (p < (size_t)NTE_MODEL_PARAM_COUNT); p++) {
        res->dz_du[ids[p]] = s_u[p];
    }
}

bool nte_model_decay_du(const nte_theta_t* th, const nte_depth_terms_t* d, const uint8_t id,
                        nte_real_t* lam_u, nte_real_t* zq_u)
{
    const nte_real_t lam = d->l * d->b;
    const nte_real_t zq = th->v[nte_param_beta] / d->b;
    nte_real_t dg;
    switch (id) {
    case nte_param_sigma0:
        *lam_u = lam;
        *zq_u = -zq;
        return true;
    case nte_param_beta:
        *lam_u = lam - lam;
        *zq_u = zq;
        return true;
    case nte_param_f1: dg = th->ex; break;
    case nte_param_f2: dg = (d->e * th->v[nte_param_f2]) + th->mkf2; break;
    case nte_param_alpha: dg = d->dg_dalpha * th->v[nte_param_alpha]; break;
    default: return false; /* sigma1, sigma2 */
    }
    /* every other parameter acts through g: d lambda = -lambda dg/g, d zq = zq dg/g */
    const nte_real_t G = dg * d->inv_g;
    *lam_u = -(lam * G);
    *zq_u = zq * G;
    return true;
}
