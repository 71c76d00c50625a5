/*
 * The surface and tare front end (reference_py/contact.py ContactFrontEnd) for one run: turns
 * (stage position, velocity, raw force) into (tissue depth, tare-free force) before the bank
 * sees the sample.  See THE CONTACT FRONT END in nte.h.  Internal header; nte.c calls it at
 * the start of nte_step when cfg.contact.enabled.
 */
#ifndef NTE_CONTACT_H
#define NTE_CONTACT_H

#include "nte_real.h"

/** ContactFrontEnd.reset: in the air, nothing learned, no surface (NaN).  Cost: O(1). */
void nte_contact_start(nte_t* self);

/**
 * ContactFrontEnd.step for one accepted sample: stage x mm, velocity v mm/s, force f N.
 * Writes the tissue depth (mm, >= 0; 0 in the air) and the tare-free force (N).  Cost: about
 * 30 flops, 1 sqrt and 2 divisions; at the sample that finds the surface 4 more divisions.
 */
void nte_contact_step(nte_t* self, nte_real_t x, nte_real_t v, nte_real_t f, nte_real_t* depth,
                      nte_real_t* force);

/** ContactFrontEnd.unit: the force unit Model III's bank works in, units per N: 1, or for
 *  Model III NTE_K_CON_UNIT_REF over the noise learned so far (held in contact) where that is
 *  below it, at most NTE_K_CON_UNIT_REF / NTE_K_CON_UNIT_FLOOR.  Cost: 1 sqrt, 1 division. */
nte_real_t nte_contact_unit(const nte_t* self);

/** ContactFrontEnd.noise_sigma: the force noise's standard deviation learned in the air (held
 *  in contact), N, or with in_unit in the bank's unit (nte_contact_unit); never below
 *  sqrt(r_n2) in the bank's unit.  Cost: 2 sqrt, 2 divisions. */
nte_real_t nte_contact_noise_sigma(const nte_t* self, bool in_unit);

/** The published surface_mm, tare_n and contact state into *out (ContactFrontEnd.published). */
void nte_contact_publish(const nte_t* self, nte_output_t* out);

#endif /* NTE_CONTACT_H */
