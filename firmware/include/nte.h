/*
 * nte — needle-tissue axial force estimator.
 *
 * WHAT IT DOES
 *   Estimates, sample by sample, the axial force on a needle inserted into soft tissue and the
 *   parameters of the force model of Asadian, Kermani and Patel, "A Novel Force Modeling Scheme
 *   for Needle Insertion Using Multiple Kalman Filters", IEEE Trans. Instrum. Meas. 61(2), 2012:
 *
 *       dz/dt = l (beta - sigma0 z / g(l)),          g(l) = f1 + f2 exp(-alpha l)
 *       f     = sigma0 z l + s(v) l (sigma1 exp(-alpha l) (beta - sigma0 z / g(l)) + sigma2)
 *
 *   with depth l in mm, velocity v in mm/s, force f in N, z dimensionless and the smooth sign
 *   s(v) = tanh(v / eps).  Each sample feeds the paper's bank of three joint state-parameter
 *   extended Kalman filters in switching mode (Models I and II, paper Table I; Model III
 *   below).
 *
 *   Model III (cfg.model = 3; reference_py/MODEL.md §3b) is Model II plus three parts, each
 *   switchable (cfg.direction_memory, cfg.relaxation, cfg.layers), usually run behind the
 *   contact front end (cfg.contact: THE CONTACT FRONT END).  (1) A direction state s driven
 *   by the travelled depth (Dahl: ds/dl = (1 - s sign(dl)) / delta, integrated exactly per
 *   sample) replaces tanh(v/eps), so the friction holds in a dwell and turns over within a
 *   few mm at a reversal; the turn-over length delta (starting at presliding_mm) is
 *   identified by filter 2 with f1 and sigma1, from the samples after the motion first goes
 *   against s (JACOBIANS.md §8).  (2) One or two relaxation branches (time constants
 *   tau_fast_s, tau_slow_s) keep memories m_i <- a_i m_i + (1 - a_i) f_e of the elastic force
 *   f_e, a_i = exp(-dt / tau_i), and publish f = f_e - sum g_i m_i: a held force decays by
 *   sum g_i and recovers after an unloading.  The strengths g_fast, g_slow are identified (as
 *   odds, g_i = G_i / (1 + sum G) < 1) by filter 1 with sigma0; the memories are treated as
 *   known inputs (JACOBIANS.md §7).  (3) The layer index (THE LAYER INDEX): a tear's sample
 *   restarts the filters' covariances, moves z alone, and a drop scales z, beta and sigma2
 *   (the whole model) to the force measured after it.  Parameters are identified in log
 *   form relative to nominal values, theta = nominal exp(u), so every state stays O(1) in
 *   float32.  The derivations of the Jacobians are in reference_py/JACOBIANS.md; the model
 *   reading (sign of the velocity, z reset at the surface) in the project's model notes.
 *
 * THE SPECIFICATION IS THE PYTHON REFERENCE
 *   reference_py/ (numpy) is the executable specification.  This library performs the same
 *   IEEE-754 operations in the same order, so its float build reproduces the float32 reference
 *   and its double build the float64 reference BIT FOR BIT.  exp and tanh are computed by the
 *   library itself from + - * / (libm's differ between C libraries).  Build every file with
 *   floating-point contraction off (-ffp-contract=off) and never with -ffast-math, or the bits
 *   change (fused multiply-adds round differently).
 *
 * PRECISION
 *   nte_real_t is float unless NTE_DOUBLE is defined to 1 (CMake option NTE_DOUBLE), then double.
 *   The float build contains no double arithmetic at all (a build check enforces it).
 *
 * INTEGRATION
 *   Copy firmware/include/nte.h and firmware/src/ (*.c, *.h) into your project, compile the .c
 *   files as C99 with -ffp-contract=off, link with libm (sqrtf/sqrt in nte_get_params only).
 *   No other dependency, no configuration header.
 *
 * FILES AND THEIR PYTHON TWINS (reference_py/, numpy; the twin is the specification)
 *   include/nte.h       the API (this file)       config.py, bank.py, robust.py (public parts)
 *   src/nte.c           init, step: validation    bank.py FilterBank.step, robust.py
 *                       and dispatch              RobustEstimator.step
 *   src/nte_bank.c/.h   the bank of three EKFs:   bank.py FilterBank (_advance; _predict,
 *                       predict, measure,         _measure, _update_and_guard, _guard;
 *                       update_and_guard, guard;  Model III: _direction; relax.py
 *                       Model III's direction     (relax_terms, relax_output,
 *                       state, relaxation, tear   relax_fractions, relax_odds); layers.py
 *                                                 RuptureDetector.watch, tear_prior,
 *                                                 tear_rescale, LayerSets; identified.py
 *                                                 the subsets)
 *   src/nte_layers.c/.h the layer index           layers.py RuptureDetector
 *   src/nte_robust.c/.h the robust estimator      robust.py RobustEstimator, ldlt_solve
 *   src/nte_contact.c/.h the surface and tare     contact.py ContactFrontEnd
 *                       front end
 *   src/nte_model.c/.h  the model, its partials   model.py, rk3.py
 *                       and the RK3 step
 *   src/nte_ekf.c/.h    covariance prediction,    ekf.py
 *                       Joseph update
 *   src/nte_config.c    profiles and validation   config.py (ranges: INT_RANGES, ...)
 *   src/nte_real.h      precision, exp, tanh      fmath.py
 *   src/nte_constants.h generated constants and   firmware/tools/gen_constants.py
 *                       configuration ranges
 *   Layers: nte.c uses nte_bank.h, nte_contact.h, nte_layers.h and nte_robust.h;
 *   nte_robust.c uses nte_bank.h; the bank uses nte_model.h, nte_ekf.h and nte_layers.h (the
 *   rupture detector, which uses nte_contact.h for the noise); everything uses nte_real.h.
 *   No circle.
 *
 * MEMORY MODEL
 *   The caller owns every instance (static, stack or pool).  sizeof(nte_t) on x86-64 (gcc):
 *   920 bytes (float) / 1712 (double) with NTE_ROBUST_BUFFER_LEN = 0 (the bank and the
 *   contact front end: its state 52 / 88 bytes, its configuration 36 / 64); with the default
 *   96: 3232 (float, +2312) / 6280 (double, +4568), of which the buffer of
 *   96 x 4 reals is 1536 / 3072, the LM workspace (J^T J and J^T r at the current and the
 *   trial point, both parameter vectors) 384 / 768 and the sliced refinement's state 192 /
 *   344 (the simulation's model, kept from its start, 48 / 96 of it).  The refinement's
 *   deepest stack path (nte_step -> nte_robust_step -> a slice -> rk3) adds about 0.8 KiB
 *   (float) / 1.2 KiB (double) below nte_step's own frame (x86-64 gcc -O2 -fstack-usage;
 *   1.2 / 1.9 KiB while the refinement ran in one call).
 *   The library never allocates, has no global or static mutable state and no recursion; all
 *   working memory is the instance plus a fixed, small stack frame (measure it with
 *   -fstack-usage).  Several instances may coexist.
 *   Model III's share of these sizes: NTE_STATE_MAX = 4 (three 4 x 4 covariances instead of
 *   3 x 3: +84 / +168 bytes), ten parameters instead of seven in the config and the model,
 *   its config fields, the direction state with its sensitivity to delta and its flag, and two
 *   memories (the turn-over length identified since this header's last count: +32 / +64 of
 *   the totals above); the LM workspace stays sized for NTE_MODEL_PARAM_COUNT = 7.
 *
 * THREAD SAFETY
 *   None.  An instance must not be used from two contexts at once; different instances are
 *   independent and may be used concurrently.
 *
 * COST (float build, one sample; n = substeps, default 1)
 *   Schedule "all": 2n+1 exp of the RK3 stage depths, shared by the filters (every filter's
 *   prediction steps between the same depths with the same alpha) + 3 filters x (RK3 with
 *   sensitivities: 2n+1 depth-term divisions, whose last one the filter's measurement
 *   reuses, 3x3 covariance prediction, scalar Joseph update: 1 div per state) + the output's
 *   depth terms (their exp shared too unless Model I's filter 3 moved alpha) + up to 3 exp
 *   to refresh parameters; roughly 700 flops and 9 exp for n = 1 (Model II; README: the
 *   cycle model).
 *   Schedule "rotate" costs about half.  Bounded: no loop depends on the data.
 *   Model III: filter 1's covariance is 4 x 4 (prediction and Joseph update about 2.4x those
 *   of Model II's 2 x 2 filter 1), plus per sample 1 exp and 1 div for the direction state
 *   (instead of tanh), 1 exp and 1 div per relaxation branch, and per filter about 10 flops
 *   and 1 div for the memories and the Jacobian's scaling, up to 2 exp more to refresh the
 *   strengths; with two branches roughly 1.3x Model II's flops and 13 exp.
 *
 * THE ROBUST ESTIMATOR (cfg.estimator = nte_estimator_robust; reference_py/robust.py)
 *   The bank above, plus a batch output-error refinement once per insertion.  While the needle
 *   is in the tissue every D-th accepted sample (t, l, v, f) is kept in a buffer of
 *   cfg.robust.buffer_len entries that starts with the last sample at the surface; when the
 *   buffer is full every other entry is dropped and D doubles.  When the depth returns to 0
 *   with at least min_entries entries, a Levenberg-Marquardt fit of the identified
 *   log-parameters (Model I: 6, Model II: 5 = n_p) minimises the squared output error over the
 *   buffer from two starts (the bank's current estimate and the previous refinement, at first
 *   the nominal), keeps the better, and restarts the bank from it (u = 0 around the refined
 *   values, var(u) = restart_p0_u, z and the time line carry on).
 *   The fit is sliced across samples: the nte_step call of the sample that leaves the tissue
 *   and the ones after it each simulate at most cfg.robust.slice_entries buffer entries of it
 *   (on a copy of the bank's estimate of that sample and on the buffer as it was), while the
 *   bank goes on publishing, and the sample whose slice finishes it adopts the result:
 *   NTE_STATUS_REFINED there, NTE_STATUS_REFINING on every sample a slice ran,
 *   nte_output_t.confidence the fit's confidence from then on.  Default: one buffer entry a
 *   sample, so no nte_step exceeds 20 000 cycles on a Cortex-M4F (17 521 at worst, README:
 *   the cycle model) and the fit is adopted 1 710 samples after the insertion ends (8.55 s at
 *   200 Hz, 1.7 s at 1 kHz); 96 entries a sample take 18 samples at up to 0.39 M cycles each;
 *   slice_entries 0 fits within the step that ends the insertion.  An insertion that begins
 *   before the fit is adopted is neither recorded nor refined (the buffer still holds the
 *   last one: one buffer of RAM; a snapshot would need 1 536 B more, which the board's 8 KiB
 *   do not have); a fit that ends while the parameters are held (nte_set_frozen) or in
 *   predict-only mode is dropped, so neither ever moves a parameter.  Reference: robust.py
 *   fits at once and adopts at the same sample (RobustConfig.slices), bit for bit.
 *   Model III: refused (nte_init returns nte_err_bad_estimator).  The refinement's batch fit
 *   simulates Models I and II only; Model III would need the direction state and both
 *   relaxation memories in that simulation, their sensitivities to the nine-parameter fit
 *   (g_fast, g_slow as odds) and a 7 x 7 normal-equation solve.
 *   Cost on top of the bank, per sample: buffer bookkeeping only (a few integer operations,
 *   one int64 -> real conversion and one division; a compaction of buffer_len/2 x 4 copies
 *   at most once per buffer_len/2 kept samples).  Cost of one refinement (at the sample that
 *   leaves the tissue; bounded, independent of the data):
 *     2 starts x (fit_iterations + 1) simulations, each of (buffer_len - 1) entries x
 *     fit_substeps RK3 sub-steps with the sensitivities to n_p parameters (per sub-step 2 exp
 *     and 2 div of depth terms + 6 + ~8 n_p flops), plus per entry the output's depth terms
 *     (the RK3 step's end, reused when its depth has the same bits, else 1 exp), 1 tanh,
 *     the output and its n_p derivatives and the n_p (n_p + 3) / 2 products of J^T J and
 *     J^T r; plus per LM iteration one n_p x n_p LDL^T solve (n_p divisions, ~n_p^3/3 flops).
 *     Defaults (96 entries, 2 sub-steps, 8 iterations, Model II, n_p = 5): 18 simulations
 *     x 95 entries x 2 sub-steps = 3420 RK3 sub-steps with 5 sensitivities and 18 x 95 =
 *     1710 output evaluations, spread over the slices (per sample at most slice_entries
 *     entries and the LDL^T solves of the simulations finished on the way); a slice of one
 *     entry adds about 4 000 cycles to the step on a Cortex-M4 (6 600 at worst: the last
 *     entry of a simulation, its solve and the next one's start), one of 96 entries about
 *     0.37 M (README, the cycle model); the simulation's model (the parameters'
 *     exponentials) is taken once at its start, not at every slice.
 *
 * THE CONTACT FRONT END (cfg.contact.enabled; reference_py/contact.py)
 *   Records as measured start with the needle in the air: the depth column is the STAGE
 *   position (its origin anywhere, the tissue touched somewhere along the stroke) and the
 *   force carries a small tare and noise.  With the front end on, sample.depth_mm is that
 *   stage position (accepted within +-depth_max_mm: the air gap is not an error and
 *   depth_min_mm is not used) and sample.force_n the raw force; before the bank sees a sample
 *   the front end turns them into the depth below the surface, max(0, stage - surface), 0 in
 *   the air, and the force less the tare.  Off (the default, Models I and II), nothing
 *   changes: depth_mm is the tissue depth and the outputs are bit for bit those without it.
 *   In the air it learns the tare (running mean of the force, weight 1/min(n, tare_samples))
 *   and the noise sigma (running RMS about the tare, never below sqrt(r_n2)); a one-sided
 *   CUSUM of (f - tare)/sigma less cusum_drift_sigma pauses that learning while it is above
 *   learn_gate_sigma, so a slow onset is not learned as tare or noise.
 *   Contact: after learn_samples learned samples, f - tare above max(k_sigma sigma, floor_n)
 *   for run_samples consecutive samples while the stage moves inward (velocity >
 *   v_still_mm_s).  The surface is back-extrapolated: a straight line is fitted (least
 *   squares) to the force over stage position along the onset segment, the inward samples
 *   above the tare that end at the detection, and the surface is where it crosses the tare
 *   (kept within one segment length before the segment and not deeper than the detection;
 *   the segment's start if the fit does not rise).  On the phantom (held-out seeds, 1-3
 *   mm/s, 75-200 Hz): 0.01-0.03 mm from the truth at the median, 0.26 mm at worst
 *   (tests/python/test_contact.py prints the figures).
 *   In contact the tare and noise are held.  Contact ends at a sample with the stage back at
 *   or above the surface and |f - tare| within the threshold; everything is re-armed then
 *   (a new tare learned in the air, a new surface found at the next insertion).
 *   A known surface (cfg.contact.surface_mm finite) replaces the detection: contact while
 *   the stage is beyond it.  Published in nte_output_t: surface_mm, tare_n, contact.
 *   Model III works in units of its sensor's noise: where the noise learned in the air is
 *   below NTE_K_CON_UNIT_REF (8 mN, the quietest sensor the defaults were chosen on), the
 *   bank takes the force times unit = 8 mN / noise (at most 1000 per N; 1 otherwise, in
 *   predict-only mode and before anything was learned), its floors (r_n2, floor_n) and the
 *   rupture detector's noise are in that unit, and every published force, z, innovation and
 *   beta, sigma2 (with their sd) is divided back to N.  The nominal values are not converted.
 *   A sensor of 8 mN or more and Models I and II run bit for bit as without it.
 *   Limits: a record must start in the air with at least learn_samples samples before the
 *   tissue (what it learns first is taken as the tare); contact is looked for only while the
 *   stage moves inward; a record whose stage never comes back to the surface stays in
 *   contact.
 *   Cost per sample: about 30 flops, 1 sqrt and 2 divisions (4 more at the sample that
 *   finds the surface); memory: nte_contact_t in the instance.
 *
 * THE LAYER INDEX (Model III with cfg.layers; reference_py/layers.py)
 *   A membrane tears and the force drops by 0.5-3 N within a few samples, far below the
 *   one-step prediction.  A one-sided CUSUM of filter 1's innovation in units of the sensor
 *   noise (nu = innovation / sigma, sigma the contact front end's noise learned in the air, or
 *   sqrt(r_n2) with it off), g <- max(0, g - nu - NTE_K_LAYER_DRIFT_SIGMA), counts a
 *   rupture when g exceeds NTE_K_LAYER_THRESHOLD_SIGMA (20 noise standard deviations) and
 *   advances nte_output_t.layer (at most NTE_LAYER_MAX - 1; NTE_STATUS_RUPTURE at that
 *   sample).  It watches only while the needle moves in (velocity > v_still_mm_s) deeper than
 *   NTE_K_LAYER_HOLDOFF_MM (1.5 mm) below the surface and the previous rupture (the contact
 *   onset and the bank's re-adaptation after a drop make negative innovations too); out of the
 *   tissue the index returns to 0.  Inside that hold-off, a drop past the alarm in a single
 *   sample (-nu - drift > threshold) is a second tear of the same layer: the bank treats it
 *   as a tear below, the index stays, NTE_STATUS_DROP marks it (mostly a tear's second and
 *   third samples: the force falls over 2-3 samples at 100 Hz).  Measured on held-out
 *   phantom records by tests/python/test_layers.py (README).  The detector runs inside the
 *   bank's step, on filter 1's prior innovation before any update, and a rupture's (or a
 *   drop's) sample is a tear: every filter's covariance restarts at its initial value (the
 *   torn layer's estimates start the next layer) and the sample updates z alone, so the drop
 *   drives no parameter to its clip; then, for a drop, z, beta and sigma2 are scaled by
 *   r = force / prior force (at least NTE_K_LAYER_TEAR_RATIO_MIN, 0.05), which scales the
 *   whole model exactly: the published force is the measured one after the drop
 *   (reference_py/MODEL.md §3b part 3).
 *   Cost per sample: 1 sqrt, 1 division, 3 flops; memory: nte_layers_t in the instance.
 *
 * THE PREDICT-ONLY MODE (sensorless prediction; cfg.predict_only, nte_set_predict_only)
 *   For a force sensor that fails (or is taken away) mid-insertion: the estimate goes on from
 *   the model alone with the parameters identified so far.  In the mode, per sample: every
 *   filter of the bank predicts and none updates (no Joseph update, no gate, innovation_n and
 *   nis 0); the parameters (every u, hence every identified value nte_get_params reports)
 *   stay where the last update left them; z and Model III's direction state and relaxation
 *   memories propagate with the depth and time as usual; the covariances keep their
 *   prediction F P F^T + Q (their uncertainty grows while nothing is measured, so the
 *   filters re-converge at once when the mode ends).  Which parameters drive the prediction:
 *   the bank's one shared model, into which each filter writes its own subset (Table I) at
 *   its update -- so after a switch every parameter keeps the value of the filter that owns
 *   it, as published by the last sample; z is filter 1's prediction (guarded, like every
 *   prior: out of range it restarts at its steady state).  The published force_hat_n is that
 *   model's output; status carries NTE_STATUS_PREDICT_ONLY.
 *   sample.force_n is not read in the mode (taken as 0: a NaN or out-of-range force from a
 *   broken sensor does not reject the sample; the first sample's innovation_n, y - force_hat,
 *   is then -force_hat).  The contact front end (cfg.contact) does not look at the force
 *   either: the tare and the noise are held (no learning), no new contact is looked for
 *   unless the surface is known (cfg.contact.surface_mm: contact while the stage is beyond
 *   it), and a contact ends when the stage is back at the surface (the force condition is
 *   dropped).  Without a known surface a predict-only needle that is in the air stays there
 *   (force 0): the surface cannot be found without a force.  The robust estimator records
 *   no sample of an insertion during which the mode was on at any time, and does not refine
 *   at its end (its record would be incomplete); the next insertion is recorded again.
 *   Switching off at a sample makes that sample an ordinary update step from the predicted
 *   state (the gate may refuse the first innovations if the model drifted; it reopens after
 *   gate_reopen_after of them).  Cost in the mode: the bank's predictions without the
 *   updates, less than a normal step.
 *
 * HELD PARAMETERS (nte_set_frozen: the Command frame's AdaptCmd freeze / resume)
 *   For a phase whose data should not teach the model (a known disturbance, a tool change,
 *   a parameter set the user trusts): the parameters stay where they are while the force
 *   is still read and the state still tracked.  Frozen, every filter's Joseph update runs
 *   with the parameter rows of its gain set to 0 -- z takes its update, K[0] = (P h')[0] / S
 *   as usual, every u stays bit for bit -- and the Joseph form, which is right for any gain,
 *   keeps the covariance consistent with that (P_zz shrinks, the parameters' variances keep
 *   their prediction F P F' + Q, so the filters re-adapt at once when the freeze ends).  The
 *   gate, the guard, the layer index and the contact front end run as usual; a tear still
 *   restarts the covariances.  The robust estimator neither records nor refines an insertion
 *   during which the parameters were held (as for predict-only).  status carries
 *   NTE_STATUS_FROZEN.  The freeze lasts until nte_set_frozen(false) or nte_init; nte_reset
 *   keeps it.  reference_py FilterBank.set_frozen is its twin.  Cost: none.
 *
 * THE LAYER SETS (Model III, cfg.layer_sets; reference_py/layers.py LayerSets.enter)
 *   A single parameter set averages over the layers a needle crosses; sensorless prediction
 *   needs each layer's own.  cfg.layer_set[k] holds the layer below the first that begins
 *   start_mm below the surface, with its own sigma0, f1, beta and sigma2 -- what sets a
 *   layer's force-depth curve (sigma1, the strengths and delta shape dwells and reversals,
 *   which a record shows at one depth only).  In predict-only mode, at every sample in the
 *   tissue, the deepest set whose start the tip has reached since it entered replaces those
 *   four nominal values, their u restart at 0 (so the model runs with the set's values) and
 *   nte_output_t.layer publishes the set's index; out of the tissue, in any mode, the
 *   configured nominal values return (u 0 again).  Nothing else changes: z, s and the
 *   memories carry on through a switch, the covariances are kept.  Outside predict-only mode
 *   the sets are not entered: the filters identify from the configured start, and a set
 *   entered before the mode was switched off stays the start of the filters' identification
 *   until the tip leaves the tissue.  --export-config writes the sets (the depths of the
 *   tears the rupture detector found in the record's first insertion, the values fitted to
 *   the record's replay with those depths moved by -1, 0 and +1 mm: the next trial does not
 *   tear at the same depth).  Cost: cfg.layer_sets compares per sample; at a switch 4 exp.
 *
 * THE DATA'S BOUND (reference_py/bank.py DATA_BOUND)
 *   The published force_hat_n never exceeds NTE_K_BANK_DATA_BOUND (10) times the largest
 *   |force| accepted in the current insertion, this sample's included (at least the noise sd
 *   sqrt(r_n2); the count starts again after a sample out of tissue), nor force_max_n.  Beyond
 *   it the output is handled as out of range: z set to its steady state, the force limited to
 *   the bound, NTE_STATUS_DIVERGED and counters.diverged.  Why: a model that cannot describe
 *   its data (a force sensor mounted the other way round, a start several times off)
 *   published up to 70 times the largest force it had been given, within force_max_n and
 *   unflagged (nte-ref plausible).  Not in predict-only mode (no force is read there).  Cost:
 *   1 sqrt, 2 compares.
 */
#ifndef NTE_H
#define NTE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#ifndef NTE_DOUBLE
#define NTE_DOUBLE 0
#endif
#if NTE_DOUBLE != 0 && NTE_DOUBLE != 1
#error "NTE_DOUBLE must be 0 (float) or 1 (double)"
#endif

#if NTE_DOUBLE
typedef double nte_real_t;
#else
typedef float nte_real_t;
#endif

/**
 * Capacity of the robust estimator's insertion buffer, entries (4 reals each), fixed at compile
 * time; the runtime cfg.robust.buffer_len may be any even value 2..NTE_ROBUST_BUFFER_LEN.
 * Define it to 0 to leave the robust estimator out (nte_init then refuses
 * nte_estimator_robust with nte_err_bad_estimator and nte_t shrinks to the bank alone).
 */
#ifndef NTE_ROBUST_BUFFER_LEN
#define NTE_ROBUST_BUFFER_LEN 96
#endif
#if (NTE_ROBUST_BUFFER_LEN != 0) &&                                   \
    ((NTE_ROBUST_BUFFER_LEN < 2) || (NTE_ROBUST_BUFFER_LEN > 4096) || \
     ((NTE_ROBUST_BUFFER_LEN % 2) != 0))
#error "NTE_ROBUST_BUFFER_LEN must be 0 (no robust estimator) or even in 2..4096"
#endif

/* ---------------------------------------------------------------------------------------- */
/* Parameters                                                                                */
/* ---------------------------------------------------------------------------------------- */

/** Index of each model parameter (the reference's PARAM_NAMES order). */
typedef enum nte_param_id_t {
    nte_param_sigma0 = 0, /**< bristle stiffness, N/mm^2 */
    nte_param_sigma1 = 1, /**< bristle damping factor */
    nte_param_sigma2 = 2, /**< viscous friction per unit depth, N/mm */
    nte_param_f1 = 3,     /**< g(l) constant part */
    nte_param_f2 = 4,     /**< g(l) exponential part */
    nte_param_alpha = 5,  /**< decay rate of the exponential, 1/mm */
    nte_param_beta = 6,   /**< normalising constant (Model I: fixed beta0) */
    nte_param_g_fast = 7, /**< Model III: strength of the fast relaxation branch, the
                               fraction of the elastic force it takes once relaxed */
    nte_param_g_slow = 8, /**< Model III: strength of the slow branch (g_fast + g_slow < 1) */
    nte_param_delta = 9   /**< Model III: turn-over length of the direction state, mm; starts
                               at presliding_mm (nominal[nte_param_delta] is not read) */
} nte_param_id_t;

/** Every parameter: the seven of the force model (Models I, II), Model III's two relaxation
 *  strengths and its turn-over length. */
#define NTE_PARAM_COUNT 10
/** Layers the index counts, 0..NTE_LAYER_MAX - 1 (reference_py/layers.py LAYER_MAX). */
#define NTE_LAYER_MAX 4U
/** The values of one layer set (THE LAYER SETS; reference_py/params.py LAYER_SET_NAMES):
 *  its stiffness sigma0, its cutting level through f1 and beta, its friction slope sigma2;
 *  index of each in nte_layer_set_t.values. */
typedef enum nte_layer_value_t {
    nte_layer_sigma0 = 0, /**< as nte_param_sigma0 */
    nte_layer_f1 = 1,     /**< as nte_param_f1 */
    nte_layer_beta = 2,   /**< as nte_param_beta */
    nte_layer_sigma2 = 3  /**< as nte_param_sigma2 */
} nte_layer_value_t;
#define NTE_LAYER_SET_VALUES 4U
/**
 * Capacity of cfg.layer_set (THE LAYER SETS), sets, fixed at compile time: 1..NTE_LAYER_MAX - 1
 * (the default: a set for every layer below the first).  Each costs NTE_LAYER_SET_VALUES + 1
 * reals in every nte_config_t; the board image, which receives no sets yet (there is no
 * configuration file on the board and no frame carries them), builds with 1.
 */
#ifndef NTE_LAYER_SETS_MAX
#define NTE_LAYER_SETS_MAX (NTE_LAYER_MAX - 1U)
#endif
#if (NTE_LAYER_SETS_MAX < 1) || (NTE_LAYER_SETS_MAX > (NTE_LAYER_MAX - 1U))
#error "NTE_LAYER_SETS_MAX must be in 1..NTE_LAYER_MAX - 1"
#endif
/** At most this many parameters are identified (Model I: six, Model II: five, Model III:
 *  eight). */
#define NTE_IDENTIFIED_MAX 8
/** The force model's own parameters (sigma0 .. beta): the most the RK3 step differentiates
 *  and the robust fit (Models I and II) identifies; Model III's strengths and delta act on
 *  the output only. */
#define NTE_MODEL_PARAM_COUNT 7
#define NTE_FILTER_COUNT 3
/** Largest state of one filter of the bank (z and its parameters): 4 for Model III's filter 1
 *  (z, sigma0, g_fast, g_slow); Models I and II need 3.  Each covariance is
 *  NTE_STATE_MAX^2 reals. */
#ifndef NTE_STATE_MAX
#define NTE_STATE_MAX 4
#endif
#if (NTE_STATE_MAX != 3) && (NTE_STATE_MAX != 4)
#error "NTE_STATE_MAX must be 3 (Models I and II only) or 4"
#endif

/** One identified parameter: its physical estimate and standard deviation (delta method). */
typedef struct nte_param_estimate_t {
    nte_param_id_t id;
    nte_real_t value;
    nte_real_t sd;
} nte_param_estimate_t;

/* ---------------------------------------------------------------------------------------- */
/* Errors, status bits and counters                                                          */
/* ---------------------------------------------------------------------------------------- */

/** Result of nte_init / nte_step / nte_reset.  Zero is success, every error is negative. */
typedef enum nte_err_t {
    nte_err_ok = 0,
    nte_err_null_argument = -1,   /**< a pointer argument was NULL */
    nte_err_bad_model = -2,       /**< model is not 1, 2 or 3 (3 needs NTE_STATE_MAX 4 when
                                       the relaxation has two branches) */
    nte_err_bad_schedule = -3,    /**< schedule is not a nte_schedule_t value */
    nte_err_bad_substeps = -4,    /**< substeps outside 1..16 */
    nte_err_bad_gate_reopen = -5, /**< gate_reopen_after outside 1..1000 */
    nte_err_not_finite = -6,      /**< a real field is NaN or infinite */
    nte_err_not_positive = -7,    /**< a field that must be > 0 (or >= 0) is not */
    nte_err_bad_range = -8,       /**< depth_min_mm > depth_max_mm, or u_max > 10, p0_u > 100 */
    nte_err_bad_nominal = -9,     /**< a nominal parameter is NaN, infinite or |x| > 1000 */
    nte_err_bad_f1 = -10,         /**< nominal f1 does not exceed -f2 (g(0) must be > 0) */
    nte_err_bad_estimator = -11,  /**< estimator is not a nte_estimator_t value, or robust
                                       while NTE_ROBUST_BUFFER_LEN is 0, or robust with
                                       Model III (not supported) */
    nte_err_bad_robust = -12,     /**< a cfg.robust field is outside its range */
    nte_err_bad_contact = -13,    /**< a cfg.contact field is outside its range (checked
                                       when cfg.contact.enabled) */
    nte_err_bad_layer_sets = -14  /**< cfg.layer_sets > NTE_LAYER_SETS_MAX, given outside
                                       Model III, a start not above the previous one (> 0
                                       for the first) or beyond depth_max_mm, a value not
                                       finite, > 0 and <= 1000, or a set's f1 not above -f2 */
} nte_err_t;

/* Status bits of one sample (same values as reference_py/bank.py STATUS_*). */
/* a hand-aligned table: clang-format would split the #defines with multi-line comments */
/* clang-format off */
#define NTE_STATUS_INIT (1U << 0U)            /**< first sample after init/reset: no prediction */
#define NTE_STATUS_REJECTED (1U << 1U)        /**< sample invalid and ignored; outputs held */
#define NTE_STATUS_GATED (1U << 2U)           /**< a filter's innovation failed the gate */
#define NTE_STATUS_FILTER_RESET (1U << 3U)    /**< a filter's P or x went bad and was reset */
#define NTE_STATUS_GAP (1U << 4U)             /**< dt > dt_max_s: z restarted at steady state */
#define NTE_STATUS_OUT_OF_TISSUE (1U << 5U)   /**< depth <= 0: z held at 0 */
#define NTE_STATUS_CLIPPED (1U << 6U)         /**< a log-parameter hit |u| = u_max */
#define NTE_STATUS_FLOORED (1U << 7U)         /**< a variance was raised to its floor */
#define NTE_STATUS_SIGN_UNCERTAIN (1U << 8U)  /**< R inflated: smooth sign may be wrong */
/* Robust estimator only (same values as reference_py/robust.py STATUS_*). */
#define NTE_STATUS_REFINED (1U << 9U)   /**< a batch refinement ran at this sample and
                                             restarted the bank from its result */
#define NTE_STATUS_REFINING (1U << 15U) /**< a slice of a refinement ran at this sample
                                             (from the sample that ended the insertion to
                                             the one that adopted or dropped the result) */
#define NTE_STATUS_CONVERGED (1U << 10U) /**< the last refinement agreed with the data
                                              (confidence >= converged_confidence) and moved
                                              no parameter by more than converged_change
                                              (relative) since the previous one */
/* Bank and robust estimator. */
#define NTE_STATUS_DIVERGED (1U << 11U) /**< a predicted force h (N) or the dimensionless z
                                             left its physical range: |h| > force_max_n or
                                             |sigma0 z l| > force_max_n (N; l in mm).  That
                                             filter was reset (P to P0, z to its steady state
                                             beta g / sigma0), or, for the published output,
                                             z was set to its steady state and the force
                                             saturated at +-force_max_n (NaN: 0); the same
                                             for a published force beyond THE DATA'S
                                             BOUND (limited to it).  A published
                                             force_hat_n never leaves +-force_max_n. */
#define NTE_STATUS_RUPTURE (1U << 12U) /**< Model III: a layer's rupture was found at this
                                           sample (nte_output_t.layer advanced; THE LAYER
                                           INDEX below) */
#define NTE_STATUS_DROP (1U << 16U) /**< Model III: a drop past the rupture alarm in one
                                        sample, inside the hold-off: a tear of the same layer
                                        (treated as one, nte_output_t.layer kept; THE LAYER
                                        INDEX below) */
#define NTE_STATUS_PREDICT_ONLY (1U << 13U) /**< the sample was processed in predict-only
                                                mode (cfg.predict_only or
                                                nte_set_predict_only): the published force
                                                is the model's alone, no parameter moved,
                                                sample.force_n was not read (THE
                                                PREDICT-ONLY MODE above); set on rejected
                                                samples too while the mode is on */
#define NTE_STATUS_FROZEN (1U << 14U) /**< the parameters were held at this sample
                                          (nte_set_frozen; HELD PARAMETERS above): no u
                                          moved, z was updated; set on rejected samples too
                                          while they are held */
/** The bits one filter can raise (nte_output_t.filter_status): its gate, its reset, its
 *  diverged prior, a parameter at its clip, a variance at its floor, its inflated R. */
#define NTE_STATUS_FILTER_BITS (NTE_STATUS_GATED | NTE_STATUS_FILTER_RESET | \
                                NTE_STATUS_DIVERGED | NTE_STATUS_CLIPPED | \
                                NTE_STATUS_FLOORED | NTE_STATUS_SIGN_UNCERTAIN)
/* clang-format on */

/* Causes of a rejected sample (same values as reference_py/bank.py REJECT_*). */
#define NTE_REJECT_NONFINITE 0 /**< depth, velocity or force NaN or infinite */
#define NTE_REJECT_RANGE 1     /**< outside depth/speed/force limits of the config */
#define NTE_REJECT_TIME 2      /**< time not later than the previous accepted sample */
#define NTE_REJECT_CAUSES 3

/** Monotonic event counters (wrap modulo 2^32).  Cleared by nte_init and nte_reset; the
 *  application may also clear them itself at any time (plain fields). */
typedef struct nte_counters_t {
    uint32_t rejected[NTE_REJECT_CAUSES]; /**< rejected samples, by NTE_REJECT_* cause */
    uint32_t gated;                       /**< filter updates skipped by the innovation gate */
    uint32_t filter_resets;               /**< filter resets (covariance lost definiteness) */
    uint32_t gaps;                        /**< samples after a gap longer than dt_max_s */
    uint32_t diverged;                    /**< NTE_STATUS_DIVERGED events: filters and
                                                   outputs reset out of their range */
} nte_counters_t;

/* ---------------------------------------------------------------------------------------- */
/* Configuration                                                                             */
/* ---------------------------------------------------------------------------------------- */

typedef enum nte_schedule_t {
    nte_schedule_all = 0,   /**< the three filters run in turn on every sample */
    nte_schedule_rotate = 1 /**< filter (k mod 3) alone updates at sample k; the others predict */
} nte_schedule_t;

typedef enum nte_estimator_t {
    nte_estimator_bank = 0,  /**< the paper's bank of three EKFs alone */
    nte_estimator_robust = 1 /**< the bank plus a refinement after each insertion (see top) */
} nte_estimator_t;

/** Tuning of the robust estimator (reference_py/robust.py RobustConfig; defaults in
 *  brackets, set by nte_config_default / nte_config_paper).  Checked by nte_init only when
 *  cfg.estimator is nte_estimator_robust. */
typedef struct nte_robust_config_t {
    int32_t buffer_len;              /**< [96] decimated samples kept per insertion, even,
                                          4..min(4096, NTE_ROBUST_BUFFER_LEN) */
    int32_t fit_substeps;            /**< [2] RK3 sub-steps between buffer entries, 1..16 */
    int32_t fit_iterations;          /**< [8] LM iterations per start, 1..200 */
    int32_t min_entries;             /**< [24] a shorter insertion is not refined, 2..buffer_len */
    nte_real_t restart_p0_u;         /**< [0.01] var(u) of the bank after a restart, log^2,
                                          > 0, <= 100 */
    nte_real_t lm_lambda0;           /**< [0.01] initial LM damping, > 0 */
    nte_real_t converged_confidence; /**< [0.75] CONVERGED needs confidence >= this, > 0 */
    nte_real_t converged_change;     /**< [0.05] and a relative change <= this, > 0 */
    int32_t slice_entries;           /**< [1] buffer entries the refinement simulates per
                                          nte_step, 0..4096; 0: the whole refinement in the
                                          step that ends the insertion (THE ROBUST
                                          ESTIMATOR above) */
} nte_robust_config_t;

/** The contact state published in nte_output_t.contact. */
typedef enum nte_contact_state_t {
    nte_contact_air = 0,   /**< out of contact (always, when the front end is off) */
    nte_contact_tissue = 1 /**< the needle touches the tissue */
} nte_contact_state_t;

/** Tuning of the surface and tare front end (reference_py/config.py ContactConfig; defaults in
 *  brackets; see THE CONTACT FRONT END at the top).  Checked by nte_init only when enabled. */
typedef struct nte_contact_config_t {
    bool enabled;                 /**< [false] on: sample.depth_mm is the stage position */
    nte_real_t surface_mm;        /**< [NaN] known surface, stage position in mm, finite with
                                       |x| <= depth_max_mm; NaN: find it from the force */
    nte_real_t k_sigma;           /**< [5] contact threshold, noise standard deviations,
                                       > 0, <= 100 */
    nte_real_t floor_n;           /**< [0.01] absolute floor of the threshold, N, 0..50 */
    int32_t run_samples;          /**< [5] consecutive samples above it, 1..1000 */
    int32_t tare_samples;         /**< [200] tare and noise averaging length, samples,
                                       1..100000 */
    int32_t learn_samples;        /**< [20] samples learned in the air before contact can be
                                       seen, 1..tare_samples */
    nte_real_t learn_gate_sigma;  /**< [2] learning pauses while the onset CUSUM is above
                                       this, noise standard deviations, > 0, <= 1000 */
    nte_real_t cusum_drift_sigma; /**< [0.5] the CUSUM's reference value, noise standard
                                       deviations, > 0, <= 100 */
} nte_contact_config_t;

/** One layer below the first (Model III, THE LAYER SETS; reference_py/config.py LayerSet). */
typedef struct nte_layer_set_t {
    nte_real_t start_mm;                     /**< depth below the surface where the layer
                                                  begins, mm, above the previous set's (> 0
                                                  for the first), <= depth_max_mm */
    nte_real_t values[NTE_LAYER_SET_VALUES]; /**< sigma0, f1, beta, sigma2 (units as
                                                  nte_param_id_t), finite, > 0, <= 1000;
                                                  f1 > -nominal f2 when that is < 0 */
} nte_layer_set_t;

/** q_u entry meaning "use q_u_default" (any negative value means the same). */
#define NTE_Q_U_USE_DEFAULT (-1)

/**
 * Every tuning field, with its default in brackets ("default" profile; the "paper" profile
 * differs in r_n2 [0.01], p0_u [1] and q_u [Table I]), its unit and valid range (checked by
 * nte_init; ranges generated from reference_py/config.py).  Fill it with
 * nte_config_default or nte_config_paper, then change what you need.  The fields mirror
 * reference_py/config.py EstimatorConfig; a value equals the reference's when it is the
 * reference's float64 value rounded to nte_real_t.
 */
typedef struct nte_config_t {
    int32_t model;             /**< [argument] 1 (Model I), 2 (Model II) or 3 (Model III) */
    nte_schedule_t schedule;   /**< [argument] nte_schedule_all or _rotate */
    int32_t substeps;          /**< [1] RK3 sub-steps per sample, 1..16 (cost linear) */
    int32_t gate_reopen_after; /**< [10; Model III 1] after this many gated updates in a row
                                    accept one, 1..1000 (Model III: a lasting change such as
                                    a tear passes after one refused sample) */
    bool sign_inflation;       /**< [true] inflate R where the smooth sign may be wrong */
    bool predict_only;         /**< [false] start in predict-only mode: the model alone
                                    (sensorless prediction, the paper's atlas) from the
                                    nominal values; every filter predicts, none updates,
                                    z and the memories propagate and sample.force_n is
                                    not read (THE PREDICT-ONLY MODE above; switch it at
                                    run time with nte_set_predict_only, which writes this
                                    field).  Sits in sign_inflation's padding: no size
                                    change */
    nte_real_t eps_mm_s;       /**< [0.5] smooth-sign width, s(v) = tanh(v/eps), mm/s, > 0 */
    nte_real_t beta0;          /**< [0.0255] Model I's fixed beta, > 0 (Model II ignores it) */
    nte_real_t r_n2;           /**< [4e-6] measurement noise variance, N^2, > 0 */
    nte_real_t q_z;            /**< [1e-8] process noise of z per sample, >= 0 */
    nte_real_t q_u[NTE_PARAM_COUNT]; /**< [NTE_Q_U_USE_DEFAULT] per-sample variance of
                                          each u, log^2, >= 0, or negative: q_u_default */
    nte_real_t q_u_default;          /**< [2e-7] variance of u for defaulted entries, >= 0 */
    nte_real_t p0_z;                 /**< [1e-6] initial variance of z, > 0 */
    nte_real_t p0_u;                 /**< [0.03] initial variance of every u, log^2, > 0, <= 100 */
    nte_real_t gate_sigma;           /**< [12] innovation gate in standard deviations, > 0; the gate
                                          compares NIS with gate_sigma^2 computed in nte_real_t */
    nte_real_t u_max;                /**< [3.9] |u| clip, log units (3.9 = factor 50), > 0, <= 10 */
    nte_real_t u_step_max;           /**< [0; Model III 0.3] the largest change of any u one
                                          update may make, log units, >= 0, <= 10: a larger
                                          update is scaled down whole, z's change
                                          with it; 0: no bound.  Keeps every update
                                          where e^u's linearisation holds (reference_py/
                                          config.py U_STEP_MAX).  Cost: one pass over the
                                          filter's parameters per update */
    nte_real_t var_floor_z;          /**< [1e-12] lower bound of var(z), > 0 */
    nte_real_t var_floor_u;          /**< [1e-10] lower bound of var(u), log^2, > 0 */
    nte_real_t v_still_mm_s;   /**< [1e-3] |v| below: a dwell (no sign inflation), mm/s, >= 0 */
    nte_real_t dt_max_s;       /**< [0.5] a longer gap restarts z at steady state, s, > 0 */
    nte_real_t depth_min_mm;   /**< [-1] accepted depth range, mm, finite, min <= max */
    nte_real_t depth_max_mm;   /**< [500] > 0 */
    nte_real_t speed_max_mm_s; /**< [500] accepted |velocity|, mm/s, > 0 */
    nte_real_t force_max_n;    /**< [50] accepted |force| and the physical range of every
                                    predicted and published force, N, > 0 */
    /* Model III (reference_py/MODEL.md §3b); Models I and II ignore these fields */
    bool layers;              /**< [true] Model III: the layer index (a rupture detector on
                                   filter 1's innovations; THE LAYER INDEX above) */
    bool direction_memory;    /**< [true] the direction state s (travelled distance, Dahl)
                                   replaces tanh(v/eps); no sign inflation of R then */
    bool relaxation;          /**< [true] relaxation branches take sum g_i m_i off the
                                   elastic force */
    int32_t relax_branches;   /**< [2] 1: the fast branch only; 2: fast and slow, 1..2 */
    nte_real_t presliding_mm; /**< [2.5] starting turn-over length delta of s, mm, > 0,
                                   <= 1000; with the direction memory on, filter 2
                                   identifies delta from the turn-overs */
    nte_real_t tau_fast_s;    /**< [0.3] time constant of the fast branch, s, > 0, <= 3600 */
    nte_real_t tau_slow_s;    /**< [3] time constant of the slow branch, s, > 0, <= 3600 */
    uint32_t layer_sets;      /**< [0] Model III: layer sets in use, 0..NTE_LAYER_SETS_MAX
                                   (THE LAYER SETS above; --export-config writes them) */
    nte_layer_set_t layer_set[NTE_LAYER_SETS_MAX]; /**< [none] the layers below the first,
                                                        in depth order */
    /** [preset paper-10mms; g_fast 0.15, g_slow 0.25] Nominal (starting) physical values,
     *  nte_param_id_t order, finite, |x| <= 1000.  Model II keeps f2 and alpha fixed at
     *  theirs; Model I ignores nominal beta and uses beta0.  Model III with relaxation: the
     *  strengths in use > 0 with a sum < 1 (else nte_err_bad_nominal). */
    nte_real_t nominal[NTE_PARAM_COUNT];
    /** [the preset's, computed in double] The identified part of nominal f1:
     *  f1 - kappa (-f2), kappa = 1 if f2 < 0 else 0; > 0.  0 means "compute it in nte_real_t
     *  from nominal f1 and f2".  Give it explicitly (computed in double, then rounded) to
     *  match a reference that starts from double values. */
    nte_real_t f1_excess;
    nte_estimator_t estimator;    /**< [nte_estimator_bank] or nte_estimator_robust */
    nte_robust_config_t robust;   /**< [see above] the robust estimator's tuning */
    nte_contact_config_t contact; /**< [see above; off] the surface and tare front end */
} nte_config_t;

/** The project's tuning (reference "default" profile); nominal = preset paper-10mms.
 *  model 1 or 2 (other values are stored and refused by nte_init).  Cost: O(1). */
void nte_config_default(nte_config_t* cfg, int32_t model, nte_schedule_t schedule);

/** The paper's Table I mapped to the log parameters (reference "paper" profile). */
void nte_config_paper(nte_config_t* cfg, int32_t model, nte_schedule_t schedule);

/** Check a configuration without touching any instance.  Cost: O(1). */
nte_err_t nte_config_check(const nte_config_t* cfg);

/* ---------------------------------------------------------------------------------------- */
/* Samples and outputs                                                                       */
/* ---------------------------------------------------------------------------------------- */

/** One synchronous measurement. */
typedef struct nte_sample_t {
    int64_t t_us;             /**< time stamp, integer microseconds, strictly increasing */
    nte_real_t depth_mm;      /**< insertion depth, mm (<= 0: out of tissue); with
                                   cfg.contact.enabled the stage position, mm */
    nte_real_t velocity_mm_s; /**< insertion velocity, mm/s (negative while retracting) */
    nte_real_t force_n;       /**< measured axial force, N */
} nte_sample_t;

/** The estimate after one sample. */
typedef struct nte_output_t {
    nte_real_t force_hat_n;  /**< posterior force estimate, N */
    nte_real_t z;            /**< posterior internal state */
    nte_real_t innovation_n; /**< first filter's one-step-ahead innovation f - h(prior), N */
    nte_real_t nis;          /**< its normalised innovation squared */
    uint32_t status;         /**< NTE_STATUS_* bits */
    nte_real_t confidence;   /**< robust estimator: confidence of the last refinement,
                                  sqrt(r_n2) / max(rms residual, sqrt(r_n2)) in (0, 1];
                                  0 before the first refinement and for the bank */
    /* The contact front end (all 0 / nte_contact_air when cfg.contact.enabled is false). */
    nte_real_t surface_mm;       /**< the surface in use, stage position mm: the one found at
                                      the latest contact (or the known cfg.contact.surface_mm
                                      once touched); NaN until the first contact */
    nte_real_t tare_n;           /**< the tare subtracted from the force, N (learned in the
                                      air, held in contact) */
    nte_contact_state_t contact; /**< air or tissue */
    uint32_t layer;              /**< Model III with cfg.layers: the layer the tip is in,
                                      0..NTE_LAYER_MAX - 1 (0 from the surface to the first
                                      rupture; 0 again out of the tissue); in predict-only
                                      mode with layer sets, the set in use; 0 otherwise */
    /** The NTE_STATUS_FILTER_BITS each filter of the bank raised at this sample (filter i
     *  owns the subset i of the parameters); status holds their OR.  0 for a rejected
     *  sample and the first one.  A filter that did not update at this sample (the rotate
     *  schedule, predict-only mode) still runs its guard: DIVERGED, CLIPPED, FLOORED or
     *  FILTER_RESET, never GATED.  One fault word per filter, published on the bus as
     *  Health.Filter<i>Flags (firmware/can/nte.dbc). */
    uint32_t filter_status[NTE_FILTER_COUNT];
} nte_output_t;

/* ---------------------------------------------------------------------------------------- */
/* The instance                                                                              */
/* ---------------------------------------------------------------------------------------- */

/** Physical parameters and the factors d theta / d u (internal). */
typedef struct nte_theta_t {
    nte_real_t v[NTE_PARAM_COUNT]; /**< physical values, nte_param_id_t order */
    nte_real_t ex;                 /**< excess of f1 over kappa (-f2) = d f1 / d u_f1 */
    nte_real_t mkf2;               /**< -kappa f2 = d f1 / d u_f2 */
} nte_theta_t;

#if NTE_ROBUST_BUFFER_LEN > 0
/** The robust estimator's state and workspace (internal; see the top of this file). */
typedef struct nte_robust_t {
    nte_real_t buf[4][NTE_ROBUST_BUFFER_LEN]; /**< t - t0 s, depth mm, velocity mm/s, force N */
    int64_t t0_us;                            /**< time of the buffer's first entry */
    int64_t anchor_t_us;                      /**< the latest accepted sample at the surface ... */
    nte_real_t anchor[3];                     /**< ... its depth, velocity, force */
    uint32_t count;                           /**< entries in the buffer */
    uint32_t decim;                           /**< keep every decim-th sample */
    uint32_t phase;                           /**< samples seen since the buffer start */
    bool inside;                              /**< needle in the tissue */
    bool has_refined;
    bool converged;
    bool tainted; /**< predict-only mode was on during this insertion: not
                       recorded, no refinement at its end */
    nte_real_t confidence;
    nte_real_t prev_theta[NTE_PARAM_COUNT]; /**< start (b) of the next refinement */
    /* Levenberg-Marquardt workspace: J^T J and J^T r at the current and the trial point */
    nte_real_t A[NTE_MODEL_PARAM_COUNT][NTE_MODEL_PARAM_COUNT];
    nte_real_t g[NTE_MODEL_PARAM_COUNT];
    nte_real_t A_try[NTE_MODEL_PARAM_COUNT][NTE_MODEL_PARAM_COUNT];
    nte_real_t g_try[NTE_MODEL_PARAM_COUNT];
    nte_real_t v[NTE_MODEL_PARAM_COUNT];     /**< current log-parameters of the fit */
    nte_real_t v_try[NTE_MODEL_PARAM_COUNT]; /**< trial point */
    /* the refinement in progress, sliced across samples (THE ROBUST ESTIMATOR above) */
    bool refining;                         /**< a refinement is running */
    bool trial_ok;                         /**< the trial point's solve succeeded */
    uint8_t start;                         /**< the fit's start: 0 start_a, 1 prev_theta */
    int32_t iteration;                     /**< -1 the start's first simulation, else the
                                                   LM iteration whose trial is simulated */
    uint32_t entry;                        /**< next buffer entry of that simulation */
    uint32_t fit_count;                    /**< entries of the insertion being fitted */
    nte_real_t start_a[NTE_PARAM_COUNT];   /**< the bank's values as the insertion ended */
    nte_theta_t th;                        /**< the simulation's model (its start) ... */
    nte_real_t z;                          /**< ... its z ... */
    nte_real_t sz[NTE_MODEL_PARAM_COUNT];  /**< ... its sensitivities dz/dv ... */
    nte_real_t sim_cost;                   /**< ... and its squared error so far, N^2 */
    nte_real_t cost;                       /**< the current point's cost, N^2 */
    nte_real_t lam;                        /**< the LM damping */
    nte_real_t v_a[NTE_MODEL_PARAM_COUNT]; /**< start 0's fitted log-parameters ... */
    nte_real_t cost_a;                     /**< ... and cost, N^2 */
} nte_robust_t;
#endif

/** Model III's rupture detector (internal; reference_py/layers.py RuptureDetector). */
typedef struct nte_layers_t {
    nte_real_t g;       /**< one-sided CUSUM of -innovation/sigma, noise standard deviations */
    nte_real_t last_mm; /**< depth below the surface of the previous rupture (0: the surface) */
    uint32_t layer;     /**< 0..NTE_LAYER_MAX - 1 */
} nte_layers_t;

/** The contact front end's state (internal; reference_py/contact.py ContactFrontEnd). */
typedef struct nte_contact_t {
    bool in_contact;
    int32_t n;     /**< samples learned since the last re-arm (at most tare_samples) */
    int32_t run;   /**< consecutive samples above the threshold */
    int32_t seg_n; /**< samples in the onset segment */
    nte_real_t tare;
    nte_real_t ms;               /**< mean square of the force about the tare, N^2 */
    nte_real_t cusum;            /**< one-sided CUSUM, noise standard deviations */
    nte_real_t x0;               /**< the onset segment: its first stage position, mm ... */
    nte_real_t sh, se, shh, she; /**< ... and its sums of h, e, h^2, h e (h = x - x0) */
    nte_real_t surface;          /**< stage position, mm; NaN until found */
} nte_contact_t;

/**
 * One estimator.  Allocate it anywhere; initialise with nte_init.  Every field except
 * `counters` is private: read results through nte_step's output and nte_get_params.
 */
typedef struct nte_t {
    nte_config_t cfg;
    /* constants derived at init */
    nte_real_t gate2;
    nte_real_t q_u[NTE_PARAM_COUNT];
    nte_real_t nominal[NTE_PARAM_COUNT];
    nte_real_t ex_nominal;
    nte_real_t kappa;
    /* shared model */
    nte_real_t u[NTE_PARAM_COUNT];
    nte_theta_t th;
    nte_real_t z;
    /* one covariance per filter, dimension 1 + its parameter count (at most NTE_STATE_MAX) */
    nte_real_t P[NTE_FILTER_COUNT][NTE_STATE_MAX][NTE_STATE_MAX];
    /* Model III: the direction state s in [-1, 1], its sensitivity ds/du_delta, whether the
     * motion went against it since the surface (delta is learned from turn-overs only), and
     * the relaxation memories m_i, N */
    nte_real_t sdir;
    nte_real_t sdir_du;
    bool turned;
    nte_real_t mrel[2];
    uint32_t gated_run[NTE_FILTER_COUNT];
    /* time line */
    int64_t t_prev_us;
    nte_real_t l_prev;
    /* the largest |force| accepted in this insertion (0 out of tissue), N: the base of the
     * data's bound on the published force (THE DATA'S BOUND) */
    nte_real_t y_max;
    /* Model III with the contact front end: the bank's force unit, units per N (nte_contact.c
     * nte_contact_unit; 1 otherwise): y, z, the memories and y_max are in it, the outputs
     * are divided back */
    nte_real_t unit;
    bool initialised;
    uint8_t k_mod3;
    bool frozen; /* nte_set_frozen: the parameters held (HELD PARAMETERS) */
    nte_output_t last;
    /** Event counters: public, read and clear at will. */
    nte_counters_t counters;
#if NTE_ROBUST_BUFFER_LEN > 0
    nte_robust_t robust;
#endif
    nte_contact_t contact;
    nte_layers_t layers;
    uint32_t set_layer; /**< Model III: the layer set the model runs with (0: the nominal) */
} nte_t;

/**
 * Validate cfg, copy it into self and start from the nominal values (every u = 0, z = 0,
 * initial covariances).  On error self is left untouched.  Cost: O(1), 7 exp.
 */
nte_err_t nte_init(nte_t* self, const nte_config_t* cfg);

/** Back to the state right after nte_init (same config): the configured nominal values
 *  (undoing every robust restart), the robust buffer emptied; counters cleared.  Cost: 7 exp. */
nte_err_t nte_reset(nte_t* self);

/**
 * Process one sample and write the estimate to *out (out may be NULL).  Invalid samples
 * (non-finite, out of range, time not increasing) are counted, flagged NTE_STATUS_REJECTED and
 * leave the state unchanged; out then repeats the previous estimate.  Cost: see COST above;
 * constant for a given config, except that the robust estimator runs its refinement within
 * the call at the sample that ends an insertion.  Returns nte_err_ok or nte_err_null_argument.
 */
nte_err_t nte_step(nte_t* self, const nte_sample_t* sample, nte_output_t* out);

/**
 * Switch predict-only mode on (true) or off (false) at run time, between two nte_step calls
 * (THE PREDICT-ONLY MODE above): on, the next samples are predicted by the model alone with
 * the parameters identified so far and sample.force_n is not read; off, the filters update
 * again from the state reached.  Nothing else changes at the call: z, the memories, the
 * parameters and the covariances are kept, the time line carries on.  Writes
 * self->cfg.predict_only, so the mode persists across nte_reset.  Cost: O(1).  Returns
 * nte_err_ok or nte_err_null_argument.  reference_py FilterBank.set_predict_only (and
 * RobustEstimator.set_predict_only) is its twin: a switch at the same sample gives the same
 * bits.
 */
nte_err_t nte_set_predict_only(nte_t* self, bool on);

/** Whether predict-only mode is on (cfg.predict_only or the last nte_set_predict_only);
 *  false for NULL.  Cost: O(1). */
bool nte_predict_only(const nte_t* self);

/**
 * Hold the parameters (true) or let them adapt again (false) from the next nte_step (HELD
 * PARAMETERS above): the filters still update z from the force, no u moves.  Nothing else
 * changes at the call.  Kept by nte_reset, cleared by nte_init.  Cost: O(1).  Returns
 * nte_err_ok or nte_err_null_argument.  Twin: reference_py FilterBank.set_frozen (and
 * RobustEstimator.set_frozen); a switch at the same sample gives the same bits.
 */
nte_err_t nte_set_frozen(nte_t* self, bool on);

/** Whether the parameters are held (the last nte_set_frozen since nte_init); false for NULL.
 *  Cost: O(1). */
bool nte_frozen(const nte_t* self);

/**
 * The identified parameters (Model I: sigma0, sigma1, sigma2, f1, f2, alpha; Model II: sigma0,
 * sigma1, sigma2, f1, beta; Model III: Model II's, then g_fast and g_slow for the relaxation
 * branches in use — reference identified.identified_names order) with their standard deviations
 * (the strengths as fractions g, sd |g (1 - g)| sd(u)).
 * Writes at most `capacity` entries and returns how many the model identifies.  Before the
 * first accepted sample every value and sd is 0 (as the reference reports).  Cost: one sqrt
 * per parameter.
 */
size_t nte_get_params(const nte_t* self, nte_param_estimate_t* out, size_t capacity);

/** Name of a parameter ("sigma0", ...), or "?" . Cost: O(1). */
const char* nte_param_name(nte_param_id_t id);

#ifdef __cplusplus
}
#endif

#endif /* NTE_H */
