/*
 * The two tuning profiles of reference_py/config.py and the validation nte_init applies.
 * Every default comes from nte_constants.h, generated from the reference, so each field holds
 * exactly the reference's value rounded to nte_real_t.
 */
#include "nte_model.h"
#include "nte_real.h"

static void set_common(nte_config_t* cfg, const int32_t model, const nte_schedule_t schedule)
{
    cfg->model = model;
    cfg->schedule = schedule;
    cfg->substeps = 1;
    /* Model III reopens its gate after one refused update: what it still refuses in tissue is
     * a tear or a turn-over that lasts (reference_py/config.py GATE_REOPEN_AFTER) */
    cfg->gate_reopen_after = (model == 3) ? 1 : 10;
    cfg->sign_inflation = true;
    cfg->predict_only = false;
    cfg->eps_mm_s = NTE_K_DEF_EPS_MM_S;
    cfg->beta0 = NTE_K_DEF_BETA0;
    cfg->r_n2 = NTE_K_DEF_R_N2;
    cfg->q_z = NTE_K_DEF_Q_Z;
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        cfg->q_u[j] = (nte_real_t)NTE_Q_U_USE_DEFAULT;
    }
    cfg->q_u_default = NTE_K_DEF_Q_U_DEFAULT;
    cfg->p0_z = NTE_K_DEF_P0_Z;
    cfg->p0_u = NTE_K_DEF_P0_U;
    cfg->gate_sigma = NTE_K_DEF_GATE_SIGMA;
    cfg->u_max = NTE_K_DEF_U_MAX;
    /* Model III bounds each update's step in u (reference_py/config.py U_STEP_MAX) */
    cfg->u_step_max = (model == 3) ? NTE_K_M3_U_STEP_MAX : NTE_C(0.0);
    cfg->var_floor_z = NTE_K_DEF_VAR_FLOOR_Z;
    cfg->var_floor_u = NTE_K_DEF_VAR_FLOOR_U;
    cfg->v_still_mm_s = NTE_K_DEF_V_STILL_MM_S;
    cfg->dt_max_s = NTE_K_DEF_DT_MAX_S;
    cfg->depth_min_mm = NTE_K_DEF_DEPTH_MIN_MM;
    cfg->depth_max_mm = NTE_K_DEF_DEPTH_MAX_MM;
    cfg->speed_max_mm_s = NTE_K_DEF_SPEED_MAX_MM_S;
    cfg->force_max_n = NTE_K_DEF_FORCE_MAX_N;
    cfg->direction_memory = true;
    cfg->layers = true;
    cfg->relaxation = true;
    cfg->relax_branches = 2;
    cfg->presliding_mm = NTE_K_DEF_PRESLIDING_MM;
    cfg->tau_fast_s = NTE_K_DEF_TAU_FAST_S;
    cfg->tau_slow_s = NTE_K_DEF_TAU_SLOW_S;
    cfg->layer_sets = 0U;
    for (size_t k = 0U; k < NTE_LAYER_SETS_MAX; k++) {
        cfg->layer_set[k].start_mm = NTE_C(0.0);
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            cfg->layer_set[k].values[j] = NTE_C(0.0);
        }
    }
    cfg->nominal[nte_param_sigma0] = NTE_K_NOMINAL_SIGMA0;
    cfg->nominal[nte_param_sigma1] = NTE_K_NOMINAL_SIGMA1;
    cfg->nominal[nte_param_sigma2] = NTE_K_NOMINAL_SIGMA2;
    cfg->nominal[nte_param_f1] = NTE_K_NOMINAL_F1;
    cfg->nominal[nte_param_f2] = NTE_K_NOMINAL_F2;
    cfg->nominal[nte_param_alpha] = NTE_K_NOMINAL_ALPHA;
    cfg->nominal[nte_param_beta] = NTE_K_NOMINAL_BETA;
    cfg->nominal[nte_param_g_fast] = NTE_K_NOMINAL_G_FAST;
    cfg->nominal[nte_param_g_slow] = NTE_K_NOMINAL_G_SLOW;
    /* not read: Model III's turn-over length starts at presliding_mm (nte_bank set_nominal) */
    cfg->nominal[nte_param_delta] = NTE_K_DEF_PRESLIDING_MM;
    cfg->f1_excess = NTE_K_NOMINAL_F1_EXCESS;
    cfg->estimator = nte_estimator_bank;
    cfg->robust.buffer_len = 96;
    cfg->robust.fit_substeps = 2;
    cfg->robust.fit_iterations = 8;
    cfg->robust.min_entries = 24;
    cfg->robust.slice_entries = 1;
    cfg->robust.restart_p0_u = NTE_K_ROB_RESTART_P0_U;
    cfg->robust.lm_lambda0 = NTE_K_ROB_LM_LAMBDA0;
    cfg->robust.converged_confidence = NTE_K_ROB_CONVERGED_CONFIDENCE;
    cfg->robust.converged_change = NTE_K_ROB_CONVERGED_CHANGE;
    cfg->contact.enabled = false;
    cfg->contact.surface_mm = (nte_real_t)NAN; /* detect the surface */
    cfg->contact.k_sigma = NTE_K_CON_K_SIGMA;
    cfg->contact.floor_n = NTE_K_CON_FLOOR_N;
    cfg->contact.run_samples = NTE_CON_DEF_RUN_SAMPLES;
    cfg->contact.tare_samples = NTE_CON_DEF_TARE_SAMPLES;
    cfg->contact.learn_samples = NTE_CON_DEF_LEARN_SAMPLES;
    cfg->contact.learn_gate_sigma = NTE_K_CON_LEARN_GATE_SIGMA;
    cfg->contact.cusum_drift_sigma = NTE_K_CON_CUSUM_DRIFT_SIGMA;
}

void nte_config_default(nte_config_t* cfg, const int32_t model, const nte_schedule_t schedule)
{
    if (cfg != NULL) {
        set_common(cfg, model, schedule);
    }
}

void nte_config_paper(nte_config_t* cfg, const int32_t model, const nte_schedule_t schedule)
{
    if (cfg == NULL) {
        return;
    }
    set_common(cfg, model, schedule);
    cfg->r_n2 = NTE_K_PAPER_R_N2;
    cfg->p0_u = NTE_K_PAPER_P0_U;
    if (model == 1) {
        cfg->q_u[nte_param_f2] = NTE_K_PAPER_Q_M1_F2;
        cfg->q_u[nte_param_sigma0] = NTE_K_PAPER_Q_M1_SIGMA0;
        cfg->q_u[nte_param_f1] = NTE_K_PAPER_Q_M1_F1;
        cfg->q_u[nte_param_sigma1] = NTE_K_PAPER_Q_M1_SIGMA1;
        cfg->q_u[nte_param_alpha] = NTE_K_PAPER_Q_M1_ALPHA;
        cfg->q_u[nte_param_sigma2] = NTE_K_PAPER_Q_M1_SIGMA2;
    } else if ((model == 2) || (model == 3)) {
        /* Model III: Model II's Table I (the relaxation strengths take q_u_default) */
        cfg->q_u[nte_param_sigma0] = NTE_K_PAPER_Q_M2_SIGMA0;
        cfg->q_u[nte_param_f1] = NTE_K_PAPER_Q_M2_F1;
        cfg->q_u[nte_param_sigma1] = NTE_K_PAPER_Q_M2_SIGMA1;
        cfg->q_u[nte_param_beta] = NTE_K_PAPER_Q_M2_BETA;
        cfg->q_u[nte_param_sigma2] = NTE_K_PAPER_Q_M2_SIGMA2;
    } else {
        /* an invalid model keeps the default q_u; nte_init refuses it */
    }
}

static nte_err_t check_positive(const nte_real_t v)
{
    if (!nte_isfinite(v)) {
        return nte_err_not_finite;
    }
    return (v > NTE_C(0.0)) ? nte_err_ok : nte_err_not_positive;
}

static nte_err_t check_nonnegative(const nte_real_t v)
{
    if (!nte_isfinite(v)) {
        return nte_err_not_finite;
    }
    return (v >= NTE_C(0.0)) ? nte_err_ok : nte_err_not_positive;
}

#if NTE_ROBUST_BUFFER_LEN > 0
/* The robust estimator's fields (checked only when it is selected): RobustConfig.validate,
 * ranges generated from reference_py/config.py into nte_constants.h. */
static nte_err_t check_robust(const nte_robust_config_t* rc)
{
    /* an odd buffer_len cannot be compacted to every other entry (robust.py's _record needs
     * buffer_len // 2 == len(buf[0::2])) */
    if ((rc->buffer_len < NTE_RANGE_ROB_BUFFER_LEN_MIN) ||
        (rc->buffer_len > NTE_RANGE_ROB_BUFFER_LEN_MAX) ||
        (rc->buffer_len > NTE_ROBUST_BUFFER_LEN) || ((rc->buffer_len % 2) != 0)) {
        return nte_err_bad_robust;
    }
    if ((rc->fit_substeps < NTE_RANGE_ROB_FIT_SUBSTEPS_MIN) ||
        (rc->fit_substeps > NTE_RANGE_ROB_FIT_SUBSTEPS_MAX) ||
        (rc->fit_iterations < NTE_RANGE_ROB_FIT_ITERATIONS_MIN) ||
        (rc->fit_iterations > NTE_RANGE_ROB_FIT_ITERATIONS_MAX) ||
        (rc->min_entries < NTE_RANGE_ROB_MIN_ENTRIES_MIN) ||
        (rc->min_entries > NTE_RANGE_ROB_MIN_ENTRIES_MAX) || (rc->min_entries > rc->buffer_len) ||
        (rc->slice_entries < NTE_RANGE_ROB_SLICE_ENTRIES_MIN) ||
        (rc->slice_entries > NTE_RANGE_ROB_SLICE_ENTRIES_MAX)) {
        return nte_err_bad_robust;
    }
    const nte_real_t positive[] = {NTE_ROBUST_POSITIVE_FIELDS(rc)};
    for (size_t i = 0U; i < (sizeof positive / sizeof positive[0]); i++) {
        if (check_positive(positive[i]) != nte_err_ok) {
            return nte_err_bad_robust;
        }
    }
    if (rc->restart_p0_u > NTE_K_RANGE_RESTART_P0_U_MAX) {
        return nte_err_bad_robust;
    }
    return nte_err_ok;
}
#endif

/* The contact front end's fields (checked only when it is on): ContactConfig.validate, ranges
 * generated from reference_py/config.py into nte_constants.h. */
static nte_err_t check_contact(const nte_contact_config_t* cc, const nte_real_t depth_max_mm)
{
    /* NaN asks for detection; a known surface must be a stage position the range accepts */
    const nte_real_t s = cc->surface_mm;
    if (!isnan(s) && !(nte_isfinite(s) && (nte_abs(s) <= depth_max_mm))) {
        return nte_err_bad_contact;
    }
    if ((cc->run_samples < NTE_RANGE_CON_RUN_SAMPLES_MIN) ||
        (cc->run_samples > NTE_RANGE_CON_RUN_SAMPLES_MAX) ||
        (cc->tare_samples < NTE_RANGE_CON_TARE_SAMPLES_MIN) ||
        (cc->tare_samples > NTE_RANGE_CON_TARE_SAMPLES_MAX) ||
        (cc->learn_samples < NTE_RANGE_CON_LEARN_SAMPLES_MIN) ||
        (cc->learn_samples > NTE_RANGE_CON_LEARN_SAMPLES_MAX) ||
        (cc->learn_samples > cc->tare_samples)) {
        return nte_err_bad_contact;
    }
    const nte_real_t positive[] = {NTE_CONTACT_POSITIVE_FIELDS(cc)};
    const nte_real_t positive_max[] = {NTE_CONTACT_POSITIVE_MAX};
    for (size_t i = 0U; i < (sizeof positive / sizeof positive[0]); i++) {
        if ((check_positive(positive[i]) != nte_err_ok) || (positive[i] > positive_max[i])) {
            return nte_err_bad_contact;
        }
    }
    const nte_real_t nonnegative[] = {NTE_CONTACT_NONNEGATIVE_FIELDS(cc)};
    const nte_real_t nonnegative_max[] = {NTE_CONTACT_NONNEGATIVE_MAX};
    for (size_t i = 0U; i < (sizeof nonnegative / sizeof nonnegative[0]); i++) {
        if ((check_nonnegative(nonnegative[i]) != nte_err_ok) ||
            (nonnegative[i] > nonnegative_max[i])) {
            return nte_err_bad_contact;
        }
    }
    return nte_err_ok;
}

/* Model III's layer sets (config.py EstimatorConfig._validate_layer_sets; layers.py
 * LayerSets for f1, computed as the bank computes the set's excess) */
static nte_err_t check_layer_sets(const nte_config_t* cfg)
{
    if (cfg->layer_sets == 0U) {
        return nte_err_ok;
    }
    if ((cfg->model != 3) || (cfg->layer_sets > NTE_LAYER_SETS_MAX)) {
        return nte_err_bad_layer_sets;
    }
    const nte_real_t f2 = cfg->nominal[nte_param_f2];
    const nte_real_t kappa = nte_model_f1_kappa(f2);
    nte_real_t previous = NTE_C(0.0);
    for (size_t k = 0U; k < cfg->layer_sets; k++) {
        const nte_layer_set_t* ls = &cfg->layer_set[k];
        if (!nte_isfinite(ls->start_mm) || !(ls->start_mm > previous) ||
            (ls->start_mm > cfg->depth_max_mm)) {
            return nte_err_bad_layer_sets;
        }
        previous = ls->start_mm;
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            const nte_real_t v = ls->values[j];
            if (!nte_isfinite(v) || !(v > NTE_C(0.0)) || (v > NTE_K_RANGE_NOMINAL_ABS_MAX)) {
                return nte_err_bad_layer_sets;
            }
        }
        if (!(nte_model_f1_excess(ls->values[nte_layer_f1], f2, kappa) > NTE_C(0.0))) {
            return nte_err_bad_layer_sets;
        }
    }
    return nte_err_ok;
}

nte_err_t nte_config_check(const nte_config_t* cfg)
{
    if (cfg == NULL) {
        return nte_err_null_argument;
    }
    if ((cfg->model < 1) || (cfg->model > 3)) {
        return nte_err_bad_model;
    }
    if ((cfg->schedule != nte_schedule_all) && (cfg->schedule != nte_schedule_rotate)) {
        return nte_err_bad_schedule;
    }
    if ((cfg->gate_reopen_after < NTE_RANGE_GATE_REOPEN_AFTER_MIN) ||
        (cfg->gate_reopen_after > NTE_RANGE_GATE_REOPEN_AFTER_MAX)) {
        return nte_err_bad_gate_reopen;
    }
    if ((cfg->substeps < NTE_RANGE_SUBSTEPS_MIN) || (cfg->substeps > NTE_RANGE_SUBSTEPS_MAX)) {
        return nte_err_bad_substeps;
    }
    if ((cfg->relax_branches < NTE_RANGE_RELAX_BRANCHES_MIN) ||
        (cfg->relax_branches > NTE_RANGE_RELAX_BRANCHES_MAX)) {
        return nte_err_bad_range;
    }
#if NTE_STATE_MAX < 4
    /* filter 1 of Model III with two branches carries z, sigma0, g_fast and g_slow */
    if ((cfg->model == 3) && cfg->relaxation && (cfg->relax_branches == 2)) {
        return nte_err_bad_model;
    }
#endif
    /* the validation of EstimatorConfig.validate, field lists generated from config.py */
    const nte_real_t positive[] = {NTE_CONFIG_POSITIVE_FIELDS(cfg)};
    for (size_t i = 0U; i < (sizeof positive / sizeof positive[0]); i++) {
        const nte_err_t e = check_positive(positive[i]);
        if (e != nte_err_ok) {
            return e;
        }
    }
    const nte_real_t nonnegative[] = {NTE_CONFIG_NONNEGATIVE_FIELDS(cfg)};
    for (size_t i = 0U; i < (sizeof nonnegative / sizeof nonnegative[0]); i++) {
        const nte_err_t e = check_nonnegative(nonnegative[i]);
        if (e != nte_err_ok) {
            return e;
        }
    }
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        if (!nte_isfinite(cfg->q_u[j])) {
            return nte_err_not_finite;
        }
    }
    if (!nte_isfinite(cfg->depth_min_mm)) {
        return nte_err_not_finite;
    }
    if (cfg->depth_min_mm > cfg->depth_max_mm) {
        return nte_err_bad_range;
    }
    /* upper bounds (config.py UPPER_BOUNDS): beyond them a published estimate or its standard
     * deviation can overflow */
    if ((cfg->u_max > NTE_K_RANGE_U_MAX_MAX) || (cfg->p0_u > NTE_K_RANGE_P0_U_MAX) ||
        (cfg->u_step_max > NTE_K_RANGE_U_STEP_MAX_MAX) ||
        (cfg->presliding_mm > NTE_K_RANGE_PRESLIDING_MM_MAX) ||
        (cfg->tau_fast_s > NTE_K_RANGE_TAU_FAST_S_MAX) ||
        (cfg->tau_slow_s > NTE_K_RANGE_TAU_SLOW_S_MAX)) {
        return nte_err_bad_range;
    }
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        if (!nte_isfinite(cfg->nominal[j]) ||
            (nte_abs(cfg->nominal[j]) > NTE_K_RANGE_NOMINAL_ABS_MAX)) {
            return nte_err_bad_nominal;
        }
    }
    if ((cfg->model == 3) && cfg->relaxation) {
        /* relax.relax_odds: the strengths in use > 0 with a sum < 1 */
        const nte_real_t g0 = cfg->nominal[nte_param_g_fast];
        const nte_real_t g1 = cfg->nominal[nte_param_g_slow];
        const bool two = cfg->relax_branches == 2;
        const nte_real_t den = NTE_C(1.0) - (two ? (g0 + g1) : g0);
        if (!(g0 > NTE_C(0.0)) || (two && !(g1 > NTE_C(0.0))) || !(den > NTE_C(0.0))) {
            return nte_err_bad_nominal;
        }
    }
    if (!nte_isfinite(cfg->f1_excess) || (cfg->f1_excess < NTE_C(0.0))) {
        return nte_err_bad_f1;
    }
    if (!(cfg->f1_excess > NTE_C(0.0))) {
        const nte_real_t f2 = cfg->nominal[nte_param_f2];
        const nte_real_t ex = nte_model_f1_excess(cfg->nominal[nte_param_f1], f2,
                                                  nte_model_f1_kappa(f2));
        if (!(ex > NTE_C(0.0))) {
            return nte_err_bad_f1;
        }
    }
    {
        const nte_err_t e = check_layer_sets(cfg);
        if (e != nte_err_ok) {
            return e;
        }
    }
    if ((cfg->estimator == nte_estimator_robust) && (cfg->model == 3)) {
        /* the refinement's batch fit simulates Models I and II only (nte.h, THE ROBUST
         * ESTIMATOR) */
        return nte_err_bad_estimator;
    }
    if (cfg->contact.enabled) {
        const nte_err_t e = check_contact(&cfg->contact, cfg->depth_max_mm);
        if (e != nte_err_ok) {
            return e;
        }
    }
    if (cfg->estimator == nte_estimator_robust) {
#if NTE_ROBUST_BUFFER_LEN > 0
        return check_robust(&cfg->robust);
#else
        return nte_err_bad_estimator;
#endif
    }
    if (cfg->estimator != nte_estimator_bank) {
        return nte_err_bad_estimator;
    }
    return nte_err_ok;
}
