/*
 * nte_switch_replay -- drives the library through a record with predict-only and the held
 * parameters switched on and off between samples (nte_set_predict_only, nte_set_frozen), for
 * tests/python/test_predict_only.py and test_frozen.py, which run reference_py's FilterBank /
 * RobustEstimator on the same lines and compare the bits.
 *
 *   nte_switch_replay MODEL SCHEDULE CONTACT ROBUST SURFACE_MM < lines > outputs
 *
 * MODEL 1..3; SCHEDULE all|rotate; CONTACT 0|1 (the contact front end, defaults otherwise);
 * ROBUST 0|1 (the robust estimator); SURFACE_MM a known surface (hex or decimal) or nan.
 * The configuration is nte_config_default's.  Each input line: "t_us depth velocity force
 * mode" with the reals in C99 hex (%a) and mode's bits from this sample on: 1 predict-only,
 * 2 the parameters held.  Each output line: force_hat z innovation nis confidence tare surface
 * (%a), status contact layer and the three filters' filter_status (decimal), then value and sd
 * of every identified parameter (%a).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nte.h"

static void put(double x) { (void)printf(" %a", x); }

int main(int argc, char** argv)
{
    if (argc != 6) {
        (void)fprintf(stderr, "usage: %s MODEL all|rotate CONTACT ROBUST SURFACE_MM\n", argv[0]);
        return 2;
    }
    nte_config_t cfg;
    const int model = atoi(argv[1]);
    const nte_schedule_t sch = (strcmp(argv[2], "rotate") == 0) ? nte_schedule_rotate
                                                                : nte_schedule_all;
    nte_config_default(&cfg, model, sch);
    cfg.contact.enabled = atoi(argv[3]) != 0;
    cfg.contact.surface_mm = (nte_real_t)strtod(argv[5], NULL);
    if (atoi(argv[4]) != 0) {
        cfg.estimator = nte_estimator_robust;
    }
    static nte_t est;
    const nte_err_t err = nte_init(&est, &cfg);
    if (err != nte_err_ok) {
        (void)fprintf(stderr, "nte_init: %d\n", (int)err);
        return 1;
    }
    char line[512];
    while (fgets(line, (int)sizeof line, stdin) != NULL) {
        char* p = line;
        nte_sample_t s;
        s.t_us = (int64_t)strtoll(p, &p, 10);
        s.depth_mm = (nte_real_t)strtod(p, &p);
        s.velocity_mm_s = (nte_real_t)strtod(p, &p);
        s.force_n = (nte_real_t)strtod(p, &p);
        const long mode = strtol(p, &p, 10);
        if ((nte_set_predict_only(&est, (mode & 1L) != 0) != nte_err_ok) ||
            (nte_set_frozen(&est, (mode & 2L) != 0) != nte_err_ok)) {
            return 1;
        }
        nte_output_t o;
        (void)nte_step(&est, &s, &o);
        (void)printf("%a", (double)o.force_hat_n);
        put((double)o.z);
        put((double)o.innovation_n);
        put((double)o.nis);
        put((double)o.confidence);
        put((double)o.tare_n);
        put((double)o.surface_mm);
        (void)printf(" %lu %d %lu", (unsigned long)o.status, (int)o.contact,
                     (unsigned long)o.layer);
        for (size_t i = 0U; i < (size_t)NTE_FILTER_COUNT; i++) {
            (void)printf(" %lu", (unsigned long)o.filter_status[i]);
        }
        nte_param_estimate_t pe[NTE_IDENTIFIED_MAX];
        const size_t n = nte_get_params(&est, pe, NTE_IDENTIFIED_MAX);
        for (size_t k = 0U; (k < n) && (k < (size_t)NTE_IDENTIFIED_MAX); k++) {
            put((double)pe[k].value);
            put((double)pe[k].sd);
        }
        (void)printf("\n");
    }
    return 0;
}
