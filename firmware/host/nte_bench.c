/*
 * nte-bench-c: samples per second of the library on one core (a program, not a test).
 * Runs a 10 000-sample synthetic insertion-dwell-retraction (200 Hz) through nte_step for both
 * schedules and prints the rate, sizeof(nte_t) and the precision.
 */
#include "nte.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#define N_SAMPLES 10000

static double now_s(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ((double)ts.tv_nsec * 1e-9);
}

static nte_sample_t samples[N_SAMPLES];

static void make_samples(void)
{
    /* 10 mm/s in to 50 mm, dwell, out, repeated; force a smooth stand-in with noise-like term */
    double depth = 0.0;
    for (int k = 0; k < N_SAMPLES; k++) {
        const int phase = (k / 200) % 12; /* 5 s in, 1 s dwell, 5 s out, 1 s rest */
        const double v = (phase < 5) ? 10.0 : ((phase == 5) ? 0.0 : ((phase < 11) ? -10.0 : 0.0));
        depth += v * 0.005;
        if (depth < 0.0) {
            depth = 0.0;
        }
        samples[k].t_us = (int64_t)k * 5000;
        samples[k].depth_mm = (nte_real_t)depth;
        samples[k].velocity_mm_s = (nte_real_t)v;
        samples[k].force_n = (nte_real_t)((0.004 * depth) + (0.002 * sin((double)k * 0.7)));
    }
}

#if NTE_DOUBLE
#define PROG "nte-bench-c-double"
#else
#define PROG "nte-bench-c"
#endif

int main(int argc, char** argv)
{
    static nte_t est;
    nte_config_t cfg;
    for (int i = 1; i < argc; i++) {
        if ((strcmp(argv[i], "-h") == 0) || (strcmp(argv[i], "--help") == 0)) {
            printf("usage: " PROG " [-h]\n\n"
                   "Samples per second of the library on one core: a %d-sample synthetic\n"
                   "insertion-dwell-retraction (200 Hz) through nte_step, Model I and II, both\n"
                   "schedules, best of 5 runs; prints the rate, sizeof(nte_t) and the precision.\n"
                   "No flags (nothing to default).\n\n"
                   "  -h, --help  this help\n\n"
                   "Exit status: 0 done, 1 the library refused its configuration, 2 bad "
                   "arguments.\n",
                   N_SAMPLES);
            return 0;
        }
    }
    if (argc > 1) {
        (void)fprintf(stderr, PROG ": error: unrecognized arguments: %s (see " PROG " --help)\n",
                      argv[1]);
        return 2;
    }
    make_samples();
    printf("precision: %s, sizeof(nte_t) = %zu bytes\n", NTE_DOUBLE ? "double" : "float",
           sizeof(nte_t));
    for (int model = 1; model <= 2; model++) {
        for (int sch = 0; sch < 2; sch++) {
            nte_config_default(&cfg, model, (nte_schedule_t)sch);
            if (nte_init(&est, &cfg) != nte_err_ok) {
                return 1;
            }
            double best = 1e30;
            double sink = 0.0;
            for (int rep = 0; rep < 5; rep++) {
                (void)nte_reset(&est);
                const double t0 = now_s();
                for (int k = 0; k < N_SAMPLES; k++) {
                    nte_output_t o;
                    (void)nte_step(&est, &samples[k], &o);
                    sink += (double)o.force_hat_n;
                }
                const double dt = now_s() - t0;
                best = (dt < best) ? dt : best;
            }
            printf("Model %s, schedule %-6s: %10.0f samples/s (%.2f us/sample) [checksum %.6g]\n",
                   (model == 1) ? "I " : "II", (sch == 0) ? "all" : "rotate",
                   (double)N_SAMPLES / best, best * 1e6 / (double)N_SAMPLES, sink);
        }
    }
    return 0;
}
