/*
 * The force model (paper eqs. 1-4), its partial derivatives and the RK3 step with forward
 * sensitivities: the C twin of reference_py/model.py and reference_py/rk3.py, expression by
 * expression.  Derivations: reference_py/JACOBIANS.md.  Internal header.
 */
#ifndef NTE_MODEL_H
#define NTE_MODEL_H

#include "nte_constants.h"
#include "nte_real.h"

/** Depth-dependent terms shared by rate and output (reference DepthTerms). */
typedef struct nte_depth_terms_t {
    nte_real_t l;         /**< depth, mm, clamped at 0 */
    nte_real_t e;         /**< exp(-alpha l) */
    nte_real_t g;         /**< f1 + f2 e */
    nte_real_t inv_g;     /**< 1 / g */
    nte_real_t b;         /**< sigma0 / g */
    nte_real_t dg_dalpha; /**< -f2 l e */
} nte_depth_terms_t;

/** Output terms (reference OutputTerms). */
typedef struct nte_output_terms_t {
    nte_real_t m;  /**< beta - b z */
    nte_real_t fr; /**< sigma1 e m + sigma2, N/mm */
    nte_real_t sl; /**< s(v) l */
    nte_real_t h;  /**< the force, N */
} nte_output_terms_t;

/** Sensitivities wanted from one RK3 step: up to NTE_MODEL_PARAM_COUNT parameter indices. */
typedef struct nte_rk3_result_t {
    nte_real_t z;
    nte_real_t dz_dz0;
    nte_real_t dz_du[NTE_PARAM_COUNT]; /**< indexed by nte_param_id_t; only requested ones set */
    /** the depth terms at the step's end, clamp(l_a + (l_b - l_a)), with the step's theta:
     *  the bank's own at l_b when the two depths are the same bits (nte_bank.c) */
    nte_depth_terms_t end;
} nte_rk3_result_t;

/** f1's split, written once (reference_py/params.py f1_kappa, f1_excess): kappa = 1 when
 *  f2 < 0, else 0 -- with f2 < 0, f1 follows f2 (d f1 / d u_f2 = -kappa f2) so that
 *  g(0) = f1 + f2 stays positive -- and the identified part of f1, its excess over kappa (-f2),
 *  which must be > 0.  kappa is the configured f2's: a log-parametrised f2 keeps its sign. */
static inline nte_real_t nte_model_f1_kappa(nte_real_t f2)
{
    return (f2 < NTE_C(0.0)) ? NTE_C(1.0) : NTE_C(0.0);
}

static inline nte_real_t nte_model_f1_excess(nte_real_t f1, nte_real_t f2, nte_real_t kappa)
{
    return f1 - (kappa * (-f2));
}

/** theta from the seven log-ratios (ScaledParams.theta). */
void nte_model_theta(nte_theta_t* th, const nte_real_t nominal[NTE_PARAM_COUNT],
                     nte_real_t ex_nominal, nte_real_t kappa, const nte_real_t u[NTE_PARAM_COUNT]);

/** theta after the parameters in ids[0..count) changed (ScaledParams.refresh). */
void nte_model_refresh(nte_theta_t* th, const nte_real_t nominal[NTE_PARAM_COUNT],
                       nte_real_t ex_nominal, nte_real_t kappa, const nte_real_t u[NTE_PARAM_COUNT],
                       const uint8_t* ids, size_t count);

nte_real_t nte_model_clamp_depth(nte_real_t l);
void nte_model_depth_terms(nte_depth_terms_t* d, const nte_theta_t* th, nte_real_t l);
/** The same, given e = exp(-alpha l) computed before with the same alpha and l (the bank's
 *  stage exponentials below): the same bits without the exp. */
void nte_model_depth_terms_e(nte_depth_terms_t* d, const nte_theta_t* th, nte_real_t l,
                             nte_real_t e);

/** Stage depths of one RK3 step of n sub-steps: 2n + 1, at most this many. */
#define NTE_MODEL_STAGES_MAX ((2 * NTE_RANGE_SUBSTEPS_MAX) + 1)

/** exp(-alpha l) at one sample's RK3 stage depths, shared by the filters that step from the
 *  same depths with the same alpha: every filter's prediction of a sample (a filter that
 *  identifies alpha, Model I's third, changes it only with its update, after its prediction),
 *  so the three filters' 3 (2n + 1) exponentials are 2n + 1.  The first nte_model_rk3 given it
 *  with ready false fills it (e[2j]: the start of sub-step j, e[2j + 1]: its middle, e[2n]:
 *  the end, at depth l_end, mm, all with this alpha, 1/mm) and sets ready; the next ones read
 *  it. */
typedef struct nte_stage_exps_t {
    nte_real_t e[NTE_MODEL_STAGES_MAX];
    nte_real_t l_end;
    nte_real_t alpha;
    bool ready;
} nte_stage_exps_t;

nte_real_t nte_model_rate(const nte_theta_t* th, const nte_depth_terms_t* d, nte_real_t z);
nte_real_t nte_model_rate_dz(const nte_depth_terms_t* d);
/** d(dz/dt)/du_id; *present = false when the rate does not depend on it (sigma1, sigma2). */
nte_real_t nte_model_rate_du(const nte_theta_t* th, const nte_depth_terms_t* d, nte_real_t z,
                             uint8_t id, bool* present);
void nte_model_output(nte_output_terms_t* o, const nte_theta_t* th, const nte_depth_terms_t* d,
                      nte_real_t z, nte_real_t s);
nte_real_t nte_model_output_dz(const nte_theta_t* th, const nte_depth_terms_t* d,
                               const nte_output_terms_t* o);
nte_real_t nte_model_output_du(const nte_theta_t* th, const nte_depth_terms_t* d, nte_real_t z,
                               const nte_output_terms_t* o, uint8_t id);
nte_real_t nte_model_steady_state_z(const nte_theta_t* th, const nte_depth_terms_t* d);
nte_real_t nte_model_smooth_sign(nte_real_t v, nte_real_t eps);

/** The exponential step's partials d lambda/du_id and d zq/du_id (decay rate lambda = l b,
 *  quasi-steady state zq = beta / b; model.py decay_du); false for sigma1, sigma2. */
bool nte_model_decay_du(const nte_theta_t* th, const nte_depth_terms_t* d, uint8_t id,
                        nte_real_t* lam_u, nte_real_t* zq_u);

/** One sample on `substeps` sub-steps, each Kutta's RK3 where h max(lambda) <= 1, else the
 *  exponential midpoint step, from depth l_a to l_b over dt seconds,
 *  with dz/dz0 and dz/du_id for every id in ids[0..count) (rk3.py rk3_step).  shared: the
 *  sample's stage exponentials with th's alpha (filled here when not ready), or NULL. */
void nte_model_rk3(nte_rk3_result_t* res, const nte_theta_t* th, nte_real_t z, nte_real_t l_a,
                   nte_real_t l_b, nte_real_t dt, int32_t substeps, const uint8_t* ids,
                   size_t count, nte_stage_exps_t* shared);

#endif /* NTE_MODEL_H */
