/*
 * The public API of nte.h: nte_init, nte_reset, nte_step (sample validation and dispatch to
 * the estimator), nte_set_predict_only, nte_predict_only, nte_set_frozen, nte_frozen,
 * nte_get_params, nte_param_name.  The reference composes the same way: FilterBank.step
 * validates the sample, passes it through the contact front end when it is on (nte_contact.c:
 * stage -> tissue depth, force -> force - tare) and advances the bank (nte_bank.c; in Model
 * III its filter 1's prior innovation feeds the layer index, nte_layers.c, before the
 * updates, so that a tear's sample is treated as one); RobustEstimator.step runs the bank's
 * step, then its own (nte_robust.c) on what the bank was given.  This file uses the four
 * components; of the others the bank knows only the layers.
 */
#include "nte_bank.h"
#include "nte_contact.h"
#include "nte_layers.h"
#include "nte_robust.h"

static const char* const param_names[NTE_PARAM_COUNT] = {
    "sigma0", "sigma1", "sigma2", "f1", "f2", "alpha", "beta", "g_fast", "g_slow", "delta"};

const char* nte_param_name(const nte_param_id_t id)
{
    const int i = (int)id;
    return ((i >= 0) && (i < NTE_PARAM_COUNT)) ? param_names[i] : "?";
}

/* The contact front end's published fields: its state, or zeros when it is off. */
static void publish_contact(nte_t* self)
{
    if (self->cfg.contact.enabled) {
        nte_contact_publish(self, &self->last);
    } else {
        self->last.surface_mm = NTE_C(0.0);
        self->last.tare_n = NTE_C(0.0);
        self->last.contact = nte_contact_air;
    }
}

static void start(nte_t* self)
{
    nte_bank_start(self);
    nte_contact_start(self);
    publish_contact(self);
    nte_layers_start(self);
    self->last.layer = 0U;
#if NTE_ROBUST_BUFFER_LEN > 0
    nte_robust_start(self);
#endif
}

nte_err_t nte_init(nte_t* self, const nte_config_t* cfg)
{
    if (self == NULL) {
        return nte_err_null_argument;
    }
    const nte_err_t err = nte_config_check(cfg);
    if (err != nte_err_ok) {
        return err;
    }
    self->cfg = *cfg;
    self->gate2 = cfg->gate_sigma * cfg->gate_sigma;
    for (size_t j = 0U; j < NTE_PARAM_COUNT; j++) {
        self->q_u[j] = (cfg->q_u[j] < NTE_C(0.0)) ? cfg->q_u_default : cfg->q_u[j];
    }
    self->frozen = false;
    start(self);
    return nte_err_ok;
}

nte_err_t nte_reset(nte_t* self)
{
    if (self == NULL) {
        return nte_err_null_argument;
    }
    start(self);
    return nte_err_ok;
}

nte_err_t nte_step(nte_t* self, const nte_sample_t* sample, nte_output_t* out)
{
    if ((self == NULL) || (sample == NULL)) {
        return nte_err_null_argument;
    }
    /* FilterBank.step: validation at the door */
    const nte_config_t* cfg = &self->cfg;
    const nte_real_t l_in = sample->depth_mm;
    const nte_real_t v = sample->velocity_mm_s;
    /* predict-only: the force is not read (a broken sensor's value rejects nothing) */
    const nte_real_t y = cfg->predict_only ? NTE_C(0.0) : sample->force_n;
    const bool finite = nte_isfinite(l_in) && nte_isfinite(v) && nte_isfinite(y);
    /* with the contact front end the depth is the stage position: its origin is arbitrary and
     * the air gap is no error, so it is accepted within +-depth_max_mm */
    const nte_real_t l_min = cfg->contact.enabled ? -cfg->depth_max_mm : cfg->depth_min_mm;
    const bool in_range = (l_in >= l_min) && (l_in <= cfg->depth_max_mm) &&
                          (nte_abs(v) <= cfg->speed_max_mm_s) && (nte_abs(y) <= cfg->force_max_n);
    nte_sample_t fed = *sample; /* what the bank (and the robust estimator) is given */
    fed.force_n = y;
    const bool later = (!self->initialised) || (sample->t_us > self->t_prev_us);
    const bool valid = finite && in_range && later;
    if (!finite) {
        self->counters.rejected[NTE_REJECT_NONFINITE]++;
    } else if (!in_range) {
        self->counters.rejected[NTE_REJECT_RANGE]++;
    } else if (!later) {
        self->counters.rejected[NTE_REJECT_TIME]++;
    } else {
        const bool first = !self->initialised;
        const int64_t dt_us = first ? 1 : (sample->t_us - self->t_prev_us);
        const nte_real_t dt = nte_real_from_i64(dt_us) / NTE_C(1.0e6);
        if (cfg->contact.enabled) {
            /* stage and raw force -> tissue depth and tare-free force */
            nte_contact_step(self, l_in, v, y, &fed.depth_mm, &fed.force_n);
        }
        /* Model III works in units of its sensor's noise (THE CONTACT FRONT END) */
        const bool in_unit = cfg->contact.enabled && (cfg->model == 3);
        if (in_unit) {
            if (self->contact.in_contact) {
                nte_bank_set_unit(self, nte_contact_unit(self));
            }
            fed.force_n = fed.force_n * self->unit;
        }
        nte_bank_advance(self, first, dt, fed.depth_mm, v, fed.force_n, &self->last);
        if (in_unit) {
            nte_bank_unscale(self, &self->last);
        }
        /* the bank ran the rupture detector (nte_layers.c) on this sample before its updates */
        if ((cfg->model == 3) && cfg->predict_only && (cfg->layer_sets > 0U)) {
            self->last.layer = self->set_layer; /* the layer of the set in use */
        } else {
            self->last.layer = ((cfg->model == 3) && cfg->layers) ? self->layers.layer : 0U;
        }
        if (first) {
            self->last.status |= NTE_STATUS_INIT;
        } else {
            self->k_mod3 = (uint8_t)((self->k_mod3 + 1U) % (unsigned)NTE_FILTER_COUNT);
        }
        self->t_prev_us = sample->t_us;
        self->l_prev = fed.depth_mm;
        self->initialised = true;
    }
    if (!valid) {
        self->last.status = NTE_STATUS_REJECTED;
        for (size_t i = 0U; i < NTE_FILTER_COUNT; i++) {
            self->last.filter_status[i] = 0U; /* no filter ran */
        }
    }
    self->last.status |= cfg->predict_only ? NTE_STATUS_PREDICT_ONLY : 0U;
    self->last.status |= self->frozen ? NTE_STATUS_FROZEN : 0U;
    publish_contact(self);
#if NTE_ROBUST_BUFFER_LEN > 0
    if (cfg->estimator == nte_estimator_robust) {
        /* RobustEstimator.step: after the bank's step of the same sample */
        self->last.status |= nte_robust_step(self, &fed, valid);
        self->last.confidence = self->robust.confidence;
    }
#endif
    if (out != NULL) {
        *out = self->last;
    }
    return nte_err_ok;
}

nte_err_t nte_set_predict_only(nte_t* self, const bool on)
{
    if (self == NULL) {
        return nte_err_null_argument;
    }
    self->cfg.predict_only = on;
    return nte_err_ok;
}

bool nte_predict_only(const nte_t* self) { return (self != NULL) && self->cfg.predict_only; }

nte_err_t nte_set_frozen(nte_t* self, const bool on)
{
    if (self == NULL) {
        return nte_err_null_argument;
    }
    self->frozen = on;
    return nte_err_ok;
}

bool nte_frozen(const nte_t* self) { return (self != NULL) && self->frozen; }

size_t nte_get_params(const nte_t* self, nte_param_estimate_t* out, const size_t capacity)
{
    if (self == NULL) {
        return 0U;
    }
    return nte_bank_params(self, out, capacity);
}
