/*
 * Model III's layer index (reference_py/layers.py RuptureDetector, statement for statement).
 */
#include "nte_layers.h"

#include "nte_constants.h"
#include "nte_contact.h"

void nte_layers_start(nte_t* self)
{
    self->layers.g = NTE_C(0.0);
    self->layers.last_mm = NTE_C(0.0);
    self->layers.layer = 0U;
}

uint32_t nte_layers_watch(nte_t* self, nte_real_t depth_mm, nte_real_t velocity_mm_s,
                          nte_real_t innovation_n)
{
    nte_layers_t* st = &self->layers;
    const nte_real_t zero = NTE_C(0.0);
    const bool inside = depth_mm > zero;
    /* the reference's `run` is true here: the bank calls this on running samples only */
    const bool moving_in = inside && (velocity_mm_s > self->cfg.v_still_mm_s);
    const bool beyond = (depth_mm - st->last_mm) > NTE_K_LAYER_HOLDOFF_MM;
    const bool may = moving_in && beyond;
    /* the innovation in units of the sensor noise (the front end's, or sqrt(r_n2)) */
    const nte_real_t sigma = self->cfg.contact.enabled ? nte_contact_noise_sigma(self, true)
                                                       : nte_sqrt(self->cfg.r_n2);
    const nte_real_t nu = innovation_n / sigma;
    nte_real_t g = (st->g - nu) - NTE_K_LAYER_DRIFT_SIGMA;
    /* inside the hold-off, a drop past the alarm in one sample is a tear of the same layer */
    const bool drop = moving_in && !beyond &&
                      (((zero - nu) - NTE_K_LAYER_DRIFT_SIGMA) > NTE_K_LAYER_THRESHOLD_SIGMA);
    g = (may && (g > zero)) ? g : zero;
    const bool rupture = may && (g > NTE_K_LAYER_THRESHOLD_SIGMA);
    if (rupture) {
        st->layer = (st->layer + 1U < NTE_LAYER_MAX) ? (st->layer + 1U) : (NTE_LAYER_MAX - 1U);
        st->last_mm = depth_mm;
        g = zero;
    }
    if (!inside) { /* out of the tissue: the next insertion starts in the first layer */
        st->layer = 0U;
        st->last_mm = zero;
    }
    st->g = g;
    return rupture ? NTE_STATUS_RUPTURE : (drop ? NTE_STATUS_DROP : 0U);
}
