/*
 * The surface and tare front end: reference_py/contact.py ContactFrontEnd, operation for
 * operation (the reference's module docstring derives the rule; nte.h's top comment is the
 * user's account).  The reference runs a batch with np.where where this file branches; every
 * value that reaches a state or an output is computed with the same operations in the same
 * order.
 */
#include "nte_contact.h"

/* seg_n saturates here (contact.py SEG_MAX): no overflow however long an onset lasts */
#define SEG_MAX 1073741824

void nte_contact_start(nte_t* self)
{
    nte_contact_t* c = &self->contact;
    c->in_contact = false;
    c->n = 0;
    c->run = 0;
    c->seg_n = 0;
    c->tare = NTE_C(0.0);
    c->ms = NTE_C(0.0);
    c->cusum = NTE_C(0.0);
    c->x0 = NTE_C(0.0);
    c->sh = NTE_C(0.0);
    c->se = NTE_C(0.0);
    c->shh = NTE_C(0.0);
    c->she = NTE_C(0.0);
    c->surface = (nte_real_t)NAN;
}

/* ContactFrontEnd._extrapolate: where the line fitted to the onset segment crosses the tare,
 * within [x0 - (x - x0), x]; the segment's start when the fit gives no rising line. */
static nte_real_t extrapolate(const nte_contact_t* c, const nte_real_t x)
{
    const nte_real_t nn = (nte_real_t)c->seg_n;
    const nte_real_t det = (nn * c->shh) - (c->sh * c->sh);
    if (!(det > NTE_C(0.0))) {
        return c->x0;
    }
    const nte_real_t b1 = ((nn * c->she) - (c->sh * c->se)) / det;
    if (!(b1 > NTE_C(0.0))) {
        return c->x0;
    }
    const nte_real_t b0 = (c->se - (b1 * c->sh)) / nn;
    nte_real_t s = c->x0 - (b0 / b1);
    const nte_real_t lo = c->x0 - (x - c->x0);
    s = (s < lo) ? lo : ((s > x) ? x : s);
    return nte_isfinite(s) ? s : c->x0;
}

nte_real_t nte_contact_unit(const nte_t* self)
{
    if ((self->cfg.model != 3) || self->cfg.predict_only) {
        return NTE_C(1.0); /* predict-only: no force read, no noise learned */
    }
    /* Model III works in units of the sensor's own noise (contact.py NOISE_REF_N): a sensor
     * quieter than the 8 mN the defaults were chosen on is read as that noisy */
    const nte_real_t lo = NTE_K_CON_UNIT_FLOOR * NTE_K_CON_UNIT_FLOOR;
    const nte_real_t ms = self->contact.ms;
    const nte_real_t k = NTE_K_CON_UNIT_REF / nte_sqrt((ms > lo) ? ms : lo);
    /* nothing learned yet (a record that starts in the tissue): unit 1 */
    return ((k > NTE_C(1.0)) && (self->contact.n > 0)) ? k : NTE_C(1.0);
}

nte_real_t nte_contact_noise_sigma(const nte_t* self, const bool in_unit)
{
    /* the noise is never taken below the bank's own measurement noise, in the bank's unit */
    const nte_real_t u = nte_contact_unit(self);
    const nte_real_t ms = self->contact.ms * (u * u);
    const nte_real_t sigma = nte_sqrt((ms > self->cfg.r_n2) ? ms : self->cfg.r_n2);
    return in_unit ? sigma : (sigma / u);
}

void nte_contact_step(nte_t* self, const nte_real_t x, const nte_real_t v, const nte_real_t f,
                      nte_real_t* depth, nte_real_t* force)
{
    const nte_contact_config_t* cc = &self->cfg.contact;
    nte_contact_t* c = &self->contact;
    const nte_real_t zero = NTE_C(0.0);
    const nte_real_t sigma = nte_contact_noise_sigma(self, false);
    const nte_real_t kt = cc->k_sigma * sigma;
    /* the threshold's floor is in the bank's unit too */
    const nte_real_t floor = cc->floor_n / nte_contact_unit(self);
    const nte_real_t thr = (kt > floor) ? kt : floor;
    const nte_real_t e = f - c->tare;
    /* predict-only: the force is not looked at (nte.h THE PREDICT-ONLY MODE): nothing is
     * learned or detected in the air */
    const bool po = self->cfg.predict_only;
    const bool air = !c->in_contact && !po;
    const bool known = nte_isfinite(cc->surface_mm);
    bool enter = false;
    bool learn = false;
    bool leave = false;
    if (known) {
        const bool below = x > cc->surface_mm;
        enter = !c->in_contact && below;
        learn = air && !below;
        leave = c->in_contact && !below;
    } else {
        if (air) {
            const bool inward = v > self->cfg.v_still_mm_s;
            const bool armed = c->n >= cc->learn_samples;
            /* the onset segment: inward samples above the tare, up to this one */
            if (inward && (e > zero)) {
                if (c->seg_n == 0) {
                    c->x0 = x;
                    c->sh = zero;
                    c->se = zero;
                    c->shh = zero;
                    c->she = zero;
                }
                const nte_real_t h = x - c->x0;
                c->seg_n = (c->seg_n < SEG_MAX) ? (c->seg_n + 1) : SEG_MAX;
                c->sh = c->sh + h;
                c->se = c->se + e;
                c->shh = c->shh + (h * h);
                c->she = c->she + (h * e);
            } else {
                c->seg_n = 0;
            }
            /* learning pauses while the CUSUM before this sample is above the gate: a slow
             * onset is not averaged into the tare and the noise */
            learn = !(armed && (c->cusum > cc->learn_gate_sigma));
            nte_real_t s = (c->cusum + (e / sigma)) - cc->cusum_drift_sigma;
            s = (s > zero) ? s : zero;
            c->cusum = armed ? s : zero;
            const bool above = armed && inward && (e > thr);
            c->run = above ? (c->run + 1) : 0;
            enter = c->run >= cc->run_samples;
        }
        leave = c->in_contact && !(x > c->surface) && (po || (nte_abs(e) <= thr));
    }
    if (learn) {
        /* a plain mean of the first tare_samples samples, then an exponential average */
        const int32_t n_new = (c->n < cc->tare_samples) ? (c->n + 1) : cc->tare_samples;
        c->n = n_new;
        const nte_real_t w = NTE_C(1.0) / (nte_real_t)n_new;
        const nte_real_t tare_new = c->tare + (w * e);
        c->ms = c->ms + (w * ((e * (f - tare_new)) - c->ms));
        c->tare = tare_new;
    }
    if (enter) {
        c->surface = known ? cc->surface_mm : extrapolate(c, x);
    }
    c->in_contact = (c->in_contact || enter) && !leave;
    if (leave) {
        /* re-armed: the next insertion learns its own tare and finds its own surface */
        c->n = 0;
        c->run = 0;
        c->seg_n = 0;
        c->cusum = zero;
    }
    const nte_real_t d = x - c->surface;
    *depth = (c->in_contact && (d > zero)) ? d : zero;
    *force = f - c->tare;
}

void nte_contact_publish(const nte_t* self, nte_output_t* out)
{
    out->surface_mm = self->contact.surface;
    out->tare_n = self->contact.tare;
    out->contact = self->contact.in_contact ? nte_contact_tissue : nte_contact_air;
}
