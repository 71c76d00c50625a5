/*
 * nte-run: the C twin of `nte-ref estimate` (reference_py/tools/cli.py).  Runs the library over a
 * CSV of t_s, depth_mm, force_n (velocity_mm_s optional) and writes one estimate row per
 * sample (the robust estimator adds a last column, confidence).  Built twice: nte-run (float) and nte-run-double (NTE_DOUBLE=1).
 *
 *   nte-run FILE.csv --model 1|2|3 [--estimator bank|robust] [--preset NAME]
 *           [--profile default|paper] [--init-seed K] [--init-factor F] [--schedule all|rotate]
 *           [--precision P] [--presliding-mm MM] [--tau-fast S] [--tau-slow S]
 *           [--relax-branches 1|2] [--no-relaxation] [--no-direction-memory] [--no-layers]
 *           [--no-layer-sets]
 *           [--contact on|off] [--surface MM] [--config FILE.json] [--predict-only]
 *           [--start NAME=VALUE,...] [--noise N] [--export-config FILE.json]
 *           [--force-unit N|mN|gf|kgf|lbf|kN] [--time-unit s|ms|us|ns]
 *           [--depth-unit mm|m|um|cm|in]
 *           [--force-sign +1|-1] [--depth-sign +1|-1] [--depth-offset MM] [--no-units-check]
 *           [--columns t=NAME,depth=NAME,force=NAME[,velocity=NAME]] --out EST.csv
 *
 * The input is converted from its units and signs to N, s and mm and, unless
 * --no-units-check, refused when implausible (units_check.h: a file in ms, m or mN, a negated
 * depth or force, a force a thousand times the range, most samples out of range), with the
 * reference's message naming the likely unit and the option that converts it.  --columns
 * reads a logger's file under its own column names (column_map.h; with --time-unit us for
 * time stamps in microseconds).
 *
 * --start sets the starting (nominal) value of parameters by name over --preset's or
 * --config's (start_flag.h); --noise N (newtons) sets the measurement noise variance
 * r_n2 = N^2 over the profile's and --config's.  The last line on stdout is the verdict
 * (verdict.h): the innovation RMS in tissue against the sensor's noise (--noise N, else
 * measured at rest before the stage moves).
 *
 * -h/--help lists every flag and its default.  Exit status 0 on success, 2 on bad input: one
 * line on stderr ("FILE:LINE: column 'NAME': reason" or "argument --flag: why").
 */
#include "column_map.h"
#include "config_file.h"
#include "export_select.h"
#include "csv_in.h"
#include "nte.h"
#include "nte_constants.h"
#include "nte_presets.h"
#include "nte_units.h"
#include "start_flag.h"
#include "nte_preset_config.h"
#include "starts.h"
#include "units_check.h"
#include "units_row.h"
#include "verdict.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#if NTE_DOUBLE
#define PROG "nte-run-double"
#define PRECISION "float64"
#define REAL_FMT "%.17g"
#else
#define PROG "nte-run"
#define PRECISION "float32"
#define REAL_FMT "%.9g"
#endif

#define EXIT_BAD_INPUT 2

typedef struct args_t {
    const char* csv;
    const char* out;
    const char* preset;
    const char* profile;
    const char* schedule;
    const char* precision;
    int model;
    int robust;
    long long seed;
    double factor;
    /* Model III (nte_config_t; ignored by Models I and II) */
    double presliding_mm;
    double tau_fast_s;
    double tau_slow_s;
    int relax_branches;
    int relaxation;
    int layers;
    int layer_sets; /* --export-config writes layer sets (--no-layer-sets: 0) */
    int direction_memory;
    int contact;    /* the contact front end: -1 not asked, 0 off, 1 on */
    double surface; /* --surface MM, NaN: find it */
    /* --config: a flag given overrides the file, one not given does not */
    const char* config;
    const char* export_config;
    int predict_only;
    int given_preset;
    int given_presliding;
    int given_tau_fast;
    int given_tau_slow;
    int given_relax_branches;
    nte_units_t units;      /* the input's units and signs (--force-unit ... --no-units-check) */
    const char* columns;    /* --columns MAP (parsed when the file is read), NULL: standard */
    double noise;           /* --noise N: the sensor's noise sd, N; NaN: not given */
    nte_start_flag_t start; /* --start NAME=VALUE,...: starting values over preset/config */
} args_t;

/* A refusal: one line on stderr, exit status 2 (the Python tools' form). */
static int usage(const char* msg)
{
    fprintf(stderr, PROG ": error: %s (see " PROG " --help)\n", msg);
    return EXIT_BAD_INPUT;
}

/* The unit tables (nte_units.h, generated from reference_py/tools/csvio.py). */
static const nte_unit_t force_units[NTE_FORCE_UNIT_COUNT] = NTE_FORCE_UNITS;
static const nte_unit_t time_units[NTE_TIME_UNIT_COUNT] = NTE_TIME_UNITS;
static const nte_unit_t depth_units[NTE_DEPTH_UNIT_COUNT] = NTE_DEPTH_UNITS;

/* The names of a unit table joined by `sep` ("N|mN"). */
static void unit_names(const nte_unit_t* table, size_t count, const char* sep, char* buf,
                       size_t cap)
{
    size_t o = 0U;
    buf[0] = '\0';
    for (size_t i = 0U; (i < count) && (o < cap); i++) {
        o += (size_t)snprintf(buf + o, cap - o, "%s%s", (i > 0U) ? sep : "", table[i].name);
    }
}

/* --help: every flag and its default, on stdout. */
static void help(void)
{
    char fu[64];
    char tu[64];
    char du[64];
    unit_names(force_units, NTE_FORCE_UNIT_COUNT, "|", fu, sizeof fu);
    unit_names(time_units, NTE_TIME_UNIT_COUNT, "|", tu, sizeof tu);
    unit_names(depth_units, NTE_DEPTH_UNIT_COUNT, "|", du, sizeof du);
    printf("usage: " PROG " FILE.csv --model 1|2|3 [--estimator bank|robust] [--preset NAME]\n"
           "       [--profile default|paper] [--init-seed K] [--init-factor F]\n"
           "       [--schedule all|rotate] [--precision " PRECISION "]\n"
           "       [--presliding-mm MM] [--tau-fast S] [--tau-slow S] [--relax-branches 1|2]\n"
           "       [--no-relaxation] [--no-direction-memory] [--no-layers] [--no-layer-sets]\n"
           "       [--contact on|off]\n"
           "       [--surface MM] [--config FILE.json] [--predict-only]\n"
           "       [--start NAME=VALUE,...] [--noise N]\n"
           "       [--export-config FILE.json] [--force-unit %s] [--time-unit %s]\n"
           "       [--depth-unit %s] [--force-sign +1|-1] [--depth-sign +1|-1]\n"
           "       [--depth-offset MM] [--no-units-check] [--columns MAP] --out EST.csv\n"
           "\n"
           "Run the estimator (C library, " PRECISION ") over a CSV of t_s, depth_mm, force_n\n"
           "(velocity_mm_s optional, else central differences of depth) and write one row per\n"
           "sample: t_s, force_hat_n, z, innovation_n, status, every identified parameter and\n"
           "its sd (the robust estimator adds confidence). The C twin of nte-ref estimate.\n"
           "\n"
           "  FILE.csv               the insertion (no default)\n"
           "  --model 1|2|3          force model (no default: this flag or --config's);\n"
           "                         3: Model II with direction memory and relaxation\n"
           "  --estimator bank|robust  (default: bank)\n"
           "  --preset NAME          starting parameters (default: %s)\n"
           "                         with --config: the file's params unless given\n"
           "  --start NAME=VALUE,... starting (nominal) values of named parameters, on top of\n"
           "                         --preset's or --config's: sigma0, sigma1, sigma2, f1, f2,\n"
           "                         alpha, beta, and Model III's strengths g_fast, g_slow\n"
           "                         (default: none)\n"
           "  --noise N              the force sensor's noise sd, N (0 < N < 1): the filters'\n"
           "                         measurement noise (r_n2 = N^2, over --config's) and the\n"
           "                         verdict's yardstick (default: r_n2 of the profile or\n"
           "                         --config; the verdict measures the noise at rest before\n"
           "                         the stage moves)\n"
           "  --profile default|paper  tuning (default: default)\n"
           "  --init-seed K          0: start at the preset; K > 0: factors drawn with seed K,\n"
           "                         0..9223372036854775807 (default: 0)\n"
           "  --init-factor F        spread of the starting factors, 1..100 (default: 5)\n"
           "  --schedule all|rotate  filters per sample (default: all)\n"
           "  --precision " PRECISION "    the only precision of this binary\n"
           "                         (default: " PRECISION ")\n",
           fu, tu, du, NTE_PRESET_DEFAULT);
    printf("  --presliding-mm MM     Model III: turn-over length of the direction state,\n"
           "                         > 0 and <= 1000 (default: 2.5, or --config's)\n"
           "  --tau-fast S           Model III: fast relaxation time constant, s,\n"
           "                         > 0 and <= 3600 (default: 0.3, or --config's)\n"
           "  --tau-slow S           Model III: slow relaxation time constant, s,\n"
           "                         > 0 and <= 3600 (default: 3, or --config's)\n"
           "  --relax-branches 1|2   Model III: relaxation branches (default: 2, or\n"
           "                         --config's)\n"
           "  --no-relaxation        Model III: no relaxation branches (default: on)\n"
           "  --no-direction-memory  Model III: tanh(v/eps) instead of the direction state\n"
           "                         (default: on)\n"
           "  --no-layers            Model III: no layer index (default: on: a rupture\n"
           "                         detector on the innovations; adds the column layer)\n"
           "  --no-layer-sets        --export-config writes one parameter set, no layer sets\n"
           "                         (default: a set at each tear of the first insertion)\n"
           "  --contact on|off       the surface and tare front end (default: on for --model 3\n"
           "                         unless --predict-only, off for 1 and 2): depth is\n"
           "                         the stage position, the needle starts in the air; adds\n"
           "                         the columns surface_mm, tare_n, contact (0 air, 1 tissue)\n"
           "  --surface MM           a known surface (stage position, -500..500 mm) instead of\n"
           "                         finding it; turns the front end on\n"
           "  --config FILE.json     an estimator configuration (nte-estimator-config/1: the\n"
           "                         discrepancy workflow's or --export-config's): model,\n"
           "                         nominal parameters, r_n2, Model III's constants, the\n"
           "                         surface; flags given override it (default: none)\n"
           "  --predict-only         with --config: the model alone on the depth, parameters\n"
           "                         held, no filter update, the force ignored (default: off)\n"
           "  --export-config FILE.json  also write what was identified as a configuration\n"
           "                         (default: none)\n");
    printf("units and signs of the input CSV (converted by the reader; implausible values are\n"
           "refused naming the likely option):\n"
           "  --force-unit %s\n"
           "                         unit of the force_n column (default: N)\n"
           "  --time-unit %-10s unit of the t_s column (default: s)\n"
           "  --depth-unit %s\n"
           "                         unit of the depth_mm (and velocity_mm_s, per time unit)\n"
           "                         column (default: mm)\n"
           "  --force-sign +1|-1     -1: the sensor reads the insertion force as negative\n"
           "                         (default: 1)\n"
           "  --depth-sign +1|-1     -1: the depth column grows out of the tissue (default: 1)\n"
           "  --depth-offset MM      added to the depth after --depth-unit and --depth-sign: a\n"
           "                         stage that counts from an origin beyond the tissue (e.g.\n"
           "                         down from 120 mm: --depth-sign -1 --depth-offset 120)\n"
           "                         reads from 0 (default: 0)\n"
           "  --no-units-check       do not refuse implausible units or signs (default: check)\n"
           "  --columns MAP          the file's own column names, as t=NAME,depth=NAME,\n"
           "                         force=NAME[,velocity=NAME]: a logger's CSV read as it is\n"
           "                         (e.g. t=time_us,depth=pz,force=fz with --time-unit us);\n"
           "                         the velocity is computed from the depth unless the map\n"
           "                         names it (default: t_s, depth_mm, force_n and\n"
           "                         velocity_mm_s if present)\n"
           "  --out EST.csv          the estimates to write (no default)\n"
           "  -h, --help             this help\n"
           "\n"
           "The last line on stdout is the verdict: the innovation RMS in tissue against the\n"
           "noise, and whether the model follows this file.\n"
           "\n"
           "Exit status: 0 success, 2 bad input (one line on stderr naming the flag or\n"
           "FILE:LINE: column 'NAME': reason).\n",
           fu, tu, du);
}

/* --force-unit, --time-unit, --depth-unit, --force-sign, --depth-sign, --depth-offset
 * (tools/arguments.py add_unit_arguments).  Returns 0 when `name` is none of them; else 1,
 * with msg empty when the value was taken, the refusal (argparse's words) when not. */
static int unit_flag(const char* name, const char* val, nte_units_t* u, char* msg, size_t cap)
{
    const nte_unit_t* table = NULL;
    size_t count = 0U;
    const char** unit = NULL;
    double* factor = NULL;
    int* sign = NULL;
    msg[0] = '\0';
    if (strcmp(name, "--force-unit") == 0) {
        table = force_units;
        count = NTE_FORCE_UNIT_COUNT;
        unit = &u->force;
        factor = &u->force_factor;
    } else if (strcmp(name, "--time-unit") == 0) {
        table = time_units;
        count = NTE_TIME_UNIT_COUNT;
        unit = &u->time;
        factor = &u->time_factor;
    } else if (strcmp(name, "--depth-unit") == 0) {
        table = depth_units;
        count = NTE_DEPTH_UNIT_COUNT;
        unit = &u->depth;
        factor = &u->depth_factor;
    } else if (strcmp(name, "--force-sign") == 0) {
        sign = &u->force_sign;
    } else if (strcmp(name, "--depth-sign") == 0) {
        sign = &u->depth_sign;
    } else if (strcmp(name, "--depth-offset") == 0) {
        /* bounded(-DEPTH_OFFSET_MAX_MM, DEPTH_OFFSET_MAX_MM, " mm") of the reference's CLI */
        const double omax = NTE_UNITS_DEPTH_OFFSET_MAX_MM;
        char* end = NULL;
        const double x = strtod(val, &end);
        if ((end == val) || (*end != '\0')) {
            (void)snprintf(msg, cap, "argument %s: not a number: '%s'", name, val);
        } else if (!((x >= -omax) && (x <= omax))) { /* also NaN and infinities */
            (void)snprintf(msg, cap, "argument %s: must be >= %g and <= %g mm (got %s)", name,
                           -omax, omax, val);
        } else {
            u->depth_offset_mm = x;
        }
        return 1;
    } else {
        return 0;
    }
    if (sign != NULL) {
        if ((strcmp(val, "1") != 0) && (strcmp(val, "+1") != 0) && (strcmp(val, "-1") != 0)) {
            (void)snprintf(msg, cap, "argument %s: must be +1 or -1 (got '%s')", name, val);
        } else {
            *sign = (strcmp(val, "-1") == 0) ? -1 : 1;
        }
        return 1;
    }
    for (size_t i = 0U; i < count; i++) {
        if (strcmp(table[i].name, val) == 0) {
            *unit = table[i].name;
            *factor = table[i].factor;
            return 1;
        }
    }
    size_t o = (size_t)snprintf(msg, cap, "argument %s: invalid choice: '%s' (choose from ", name,
                                val);
    for (size_t i = 0U; (i < count) && (o < cap); i++) {
        o += (size_t)snprintf(msg + o, cap - o, "%s'%s'", (i > 0U) ? ", " : "", table[i].name);
    }
    if (o < cap) {
        (void)snprintf(msg + o, cap - o, ")");
    }
    return 1;
}

static int parse_args(int argc, char** argv, args_t* a)
{
    char msg[4096];
    a->csv = NULL;
    a->out = NULL;
    a->preset = NTE_PRESET_DEFAULT;
    a->profile = "default";
    a->schedule = "all";
    a->precision = PRECISION;
    a->model = 0;
    a->robust = 0;
    a->seed = 0;
    a->factor = 5.0;
    a->presliding_mm = 2.5;
    a->tau_fast_s = 0.3;
    a->tau_slow_s = 3.0;
    a->relax_branches = 2;
    a->relaxation = 1;
    a->layers = 1;
    a->layer_sets = 1;
    a->direction_memory = 1;
    a->contact = -1;
    a->surface = (double)NAN; /* NAN is a float: said explicitly for -Wdouble-promotion */
    a->config = NULL;
    a->export_config = NULL;
    a->predict_only = 0;
    a->given_preset = 0;
    a->given_presliding = 0;
    a->given_tau_fast = 0;
    a->given_tau_slow = 0;
    a->given_relax_branches = 0;
    a->units.force = "N";
    a->units.time = "s";
    a->units.depth = "mm";
    a->units.force_factor = 1.0;
    a->units.time_factor = 1.0;
    a->units.depth_factor = 1.0;
    a->units.force_sign = 1;
    a->units.depth_sign = 1;
    a->units.depth_offset_mm = 0.0;
    a->units.check = 1;
    nte_columns_standard(&a->units.columns);
    a->columns = NULL;
    a->noise = (double)NAN;
    (void)memset(&a->start, 0, sizeof a->start);
    for (int i = 1; i < argc; i++) {
        if ((strcmp(argv[i], "--help") == 0) || (strcmp(argv[i], "-h") == 0)) {
            help();
            exit(0);
        }
    }
    for (int i = 1; i < argc; i++) {
        const char* opt = argv[i];
        if ((opt[0] == '-') && (opt[1] != '-') && (opt[1] != '\0')) {
            (void)snprintf(msg, sizeof msg, "unrecognized arguments: %s", opt);
            return usage(msg);
        }
        if (strcmp(opt, "--no-relaxation") == 0) {
            a->relaxation = 0;
            continue;
        }
        if (strcmp(opt, "--no-direction-memory") == 0) {
            a->direction_memory = 0;
            continue;
        }
        if (strcmp(opt, "--no-layers") == 0) {
            a->layers = 0;
            continue;
        }
        if (strcmp(opt, "--no-layer-sets") == 0) {
            a->layer_sets = 0;
            continue;
        }
        if (strcmp(opt, "--predict-only") == 0) {
            a->predict_only = 1;
            continue;
        }
        if (strcmp(opt, "--no-units-check") == 0) {
            a->units.check = 0;
            continue;
        }
        if (strncmp(opt, "--", 2) != 0) {
            if (a->csv != NULL) {
                (void)snprintf(msg, sizeof msg, "unrecognized arguments: %s (one input file)", opt);
                return usage(msg);
            }
            a->csv = opt;
            continue;
        }
        const char* eq = strchr(opt, '=');
        char name[64];
        const char* val = NULL;
        if (eq != NULL) {
            (void)snprintf(name, sizeof name, "%.*s", (int)(eq - opt), opt);
            val = eq + 1;
        } else {
            (void)snprintf(name, sizeof name, "%s", opt);
            if ((i + 1) < argc) {
                val = argv[++i];
            }
        }
        if (val == NULL) {
            (void)snprintf(msg, sizeof msg, "argument %s: expected one argument", name);
            return usage(msg);
        }
        char* end = NULL;
        if (strcmp(name, "--model") == 0) {
            if ((strcmp(val, "1") != 0) && (strcmp(val, "2") != 0) && (strcmp(val, "3") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --model: invalid choice: '%s'", val);
                return usage(msg);
            }
            a->model = atoi(val);
        } else if (strcmp(name, "--estimator") == 0) {
            if ((strcmp(val, "bank") != 0) && (strcmp(val, "robust") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --estimator: invalid choice: '%s'", val);
                return usage(msg);
            }
            a->robust = (strcmp(val, "robust") == 0) ? 1 : 0;
        } else if (strcmp(name, "--preset") == 0) {
            a->preset = val;
            a->given_preset = 1;
        } else if (strcmp(name, "--config") == 0) {
            a->config = val;
        } else if (strcmp(name, "--export-config") == 0) {
            a->export_config = val;
        } else if (strcmp(name, "--profile") == 0) {
            if ((strcmp(val, "default") != 0) && (strcmp(val, "paper") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --profile: invalid choice: '%s'", val);
                return usage(msg);
            }
            a->profile = val;
        } else if (strcmp(name, "--schedule") == 0) {
            if ((strcmp(val, "all") != 0) && (strcmp(val, "rotate") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --schedule: invalid choice: '%s'", val);
                return usage(msg);
            }
            a->schedule = val;
        } else if (strcmp(name, "--precision") == 0) {
            if (strcmp(val, PRECISION) != 0) {
                (void)snprintf(msg, sizeof msg,
                               "argument --precision: this binary computes in " PRECISION
                               " (got '%s'; use nte-run for float32, nte-run-double for "
                               "float64)",
                               val);
                return usage(msg);
            }
        } else if (strcmp(name, "--init-seed") == 0) {
            errno = 0;
            a->seed = strtoll(val, &end, 10);
            if ((end == val) || (*end != '\0') || (errno != 0) || (a->seed < 0)) {
                (void)snprintf(msg, sizeof msg,
                               "argument --init-seed: must be >= 0 and <= 9223372036854775807 "
                               "(got %s)",
                               val);
                return usage(msg);
            }
        } else if (strcmp(name, "--init-factor") == 0) {
            a->factor = strtod(val, &end);
            if ((end == val) || (*end != '\0')) {
                (void)snprintf(msg, sizeof msg, "argument --init-factor: not a number: '%s'", val);
                return usage(msg);
            }
            if (!((a->factor >= 1.0) && (a->factor <= 100.0))) { /* also NaN */
                (void)snprintf(msg, sizeof msg,
                               "argument --init-factor: must be >= 1 and <= 100 (got %s)", val);
                return usage(msg);
            }
        } else if ((strcmp(name, "--presliding-mm") == 0) || (strcmp(name, "--tau-fast") == 0) ||
                   (strcmp(name, "--tau-slow") == 0)) {
            /* bounded(0, hi, unit, lo_open=True) of the reference's CLI */
            const int mm = strcmp(name, "--presliding-mm") == 0;
            const double hi = mm ? 1000.0 : 3600.0;
            const double x = strtod(val, &end);
            if ((end == val) || (*end != '\0')) {
                (void)snprintf(msg, sizeof msg, "argument %s: not a number: '%s'", name, val);
                return usage(msg);
            }
            if (!((x > 0.0) && (x <= hi))) { /* also NaN */
                (void)snprintf(msg, sizeof msg, "argument %s: must be > 0 and <= %g %s (got %s)",
                               name, hi, mm ? "mm" : "s", val);
                return usage(msg);
            }
            if (mm) {
                a->presliding_mm = x;
                a->given_presliding = 1;
            } else if (strcmp(name, "--tau-fast") == 0) {
                a->tau_fast_s = x;
                a->given_tau_fast = 1;
            } else {
                a->tau_slow_s = x;
                a->given_tau_slow = 1;
            }
        } else if (strcmp(name, "--relax-branches") == 0) {
            if ((strcmp(val, "1") != 0) && (strcmp(val, "2") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --relax-branches: invalid choice: '%s'",
                               val);
                return usage(msg);
            }
            a->relax_branches = atoi(val);
            a->given_relax_branches = 1;
        } else if (strcmp(name, "--contact") == 0) {
            if ((strcmp(val, "on") != 0) && (strcmp(val, "off") != 0)) {
                (void)snprintf(msg, sizeof msg, "argument --contact: invalid choice: '%s'", val);
                return usage(msg);
            }
            a->contact = (strcmp(val, "on") == 0) ? 1 : 0;
        } else if (strcmp(name, "--surface") == 0) {
            /* a stage position: within the configuration's depth range (generated from
             * reference_py/config.py, the envelope's one source) */
            const double smax = (double)NTE_K_DEF_DEPTH_MAX_MM;
            a->surface = strtod(val, &end);
            if ((end == val) || (*end != '\0') ||
                !((a->surface >= -smax) && (a->surface <= smax))) { /* also NaN */
                (void)snprintf(msg, sizeof msg,
                               "argument --surface: must be a number >= %g and <= %g "
                               "(got %s)",
                               -smax, smax, val);
                return usage(msg);
            }
        } else if (unit_flag(name, val, &a->units, msg, sizeof msg) != 0) {
            if (msg[0] != '\0') {
                return usage(msg);
            }
        } else if (strcmp(name, "--noise") == 0) {
            /* tools/cli.py sensor_noise: a value of 1 or more is taken for millinewtons */
            a->noise = strtod(val, &end);
            if ((end == val) || (*end != '\0')) {
                (void)snprintf(msg, sizeof msg, "argument --noise: not a number: '%s'", val);
                return usage(msg);
            }
            if (isfinite(a->noise) && (a->noise >= 1.0)) {
                (void)snprintf(msg, sizeof msg,
                               "argument --noise: %s N is not a plausible "
                               "sensor noise: probably millinewtons, give it in N",
                               val);
                return usage(msg);
            }
            if (!(isfinite(a->noise) && (a->noise > 0.0))) {
                (void)snprintf(msg, sizeof msg,
                               "argument --noise: must be > 0 and < 1 N (got "
                               "%s)",
                               val);
                return usage(msg);
            }
        } else if (strcmp(name, "--start") == 0) {
            char why[3072];
            if (nte_start_flag_parse(val, &a->start, why, sizeof why) != 0) {
                (void)snprintf(msg, sizeof msg, "argument --start: %s", why);
                return usage(msg);
            }
        } else if (strcmp(name, "--columns") == 0) {
            a->columns = val;
        } else if (strcmp(name, "--out") == 0) {
            a->out = val;
        } else {
            (void)snprintf(msg, sizeof msg, "unrecognized arguments: %s", name);
            return usage(msg);
        }
    }
    if (a->csv == NULL) {
        return usage("the following arguments are required: FILE.csv");
    }
    if ((a->model == 0) && (a->config == NULL)) {
        return usage("the following arguments are required: --model (or --config)");
    }
    if (a->out == NULL) {
        return usage("the following arguments are required: --out");
    }
    if (!isnan(a->surface)) {
        if (a->contact == 0) {
            return usage("argument --surface: a known surface needs the front end "
                         "(--contact on)");
        }
        a->contact = 1;
    }
    return 0;
}

static const nte_preset_t* find_preset(const char* name)
{
    for (size_t i = 0U; i < NTE_PRESET_COUNT; i++) {
        if (strcmp(nte_presets[i].name, name) == 0) {
            return &nte_presets[i];
        }
    }
    return NULL;
}

static int bad(const char* msg)
{
    fprintf(stderr, PROG ": error: %s\n", msg);
    return EXIT_BAD_INPUT;
}

/* The output by the Python tools' writer rules (reference_py/tools/safe_write.py): a regular
 * file only (a directory, device or FIFO is refused, never replaced), a symbolic link written
 * through to its target, the mode of a replaced file kept, else 0666 minus the umask, no
 * parent directory created.  Fills target (the file to replace or create) and mode. */
typedef struct out_t {
    char target[4096];
    mode_t mode;
} out_t;

static int check_out(const char* flag, const char* path, out_t* o, char* msg, size_t cap)
{
    struct stat st;
    (void)snprintf(o->target, sizeof o->target, "%s", path);
    /* follow symbolic links to the file they name (relative to the link's directory) */
    for (int depth = 0; (lstat(o->target, &st) == 0) && S_ISLNK(st.st_mode); depth++) {
        char link[sizeof o->target];
        const ssize_t n = readlink(o->target, link, sizeof link - 1U);
        if ((n < 0) || (depth >= 40)) {
            (void)snprintf(msg, cap, "%s %s: cannot follow the symbolic link: %s", flag, path,
                           (n < 0) ? strerror(errno) : "too many levels");
            return -1;
        }
        link[n] = '\0';
        const char* slash = strrchr(o->target, '/');
        if ((link[0] == '/') || (slash == NULL)) {
            (void)snprintf(o->target, sizeof o->target, "%s", link);
        } else {
            char joined[(2U * sizeof o->target) + 2U];
            (void)snprintf(joined, sizeof joined, "%.*s/%s", (int)(slash - o->target), o->target,
                           link);
            const size_t len = strlen(joined);
            if (len >= sizeof o->target) {
                (void)snprintf(msg, cap,
                               "%s %s: the symbolic link's target path is too "
                               "long",
                               flag, path);
                return -1;
            }
            (void)memcpy(o->target, joined, len + 1U);
        }
    }
    if (stat(o->target, &st) == 0) {
        const char* kind = S_ISDIR(st.st_mode)    ? "a directory"
                           : S_ISCHR(st.st_mode)  ? "a character device"
                           : S_ISBLK(st.st_mode)  ? "a block device"
                           : S_ISFIFO(st.st_mode) ? "a FIFO"
                           : S_ISSOCK(st.st_mode) ? "a socket"
                                                  : NULL;
        if (kind != NULL) {
            (void)snprintf(msg, cap,
                           "%s %s: is %s, not a regular file; refusing to "
                           "replace it",
                           flag, path, kind);
            return -1;
        }
        o->mode = st.st_mode & 07777U;
        return 0;
    }
    const mode_t mask = umask(022);
    (void)umask(mask);
    o->mode = 0666U & ~mask;
    char dir[4096];
    const char* slash = strrchr(o->target, '/');
    if (slash == NULL) {
        return 0;
    }
    (void)snprintf(dir, sizeof dir, "%.*s", (slash == o->target) ? 1 : (int)(slash - o->target),
                   o->target);
    if (stat(dir, &st) != 0) {
        (void)snprintf(msg, cap, "%s %s: directory %s does not exist (it is not created)", flag,
                       path, dir);
        return -1;
    }
    if (!S_ISDIR(st.st_mode)) {
        (void)snprintf(msg, cap, "%s %s: %s is not a directory", flag, path, dir);
        return -1;
    }
    return 0;
}

typedef struct counts_t {
    size_t rejected;
    size_t gated;
    size_t clipped;
} counts_t;

/* Write every row to a temporary file beside the target, then rename it into place.
 * Returns 0, EXIT_BAD_INPUT (the place cannot be written) or 1 (a write failed). */
static int run(const args_t* a, const out_t* out, const nte_trial_t* tr, nte_t* est,
               counts_t* counts, nte_output_t* last, nte_export_snapshot_t* snaps,
               nte_export_layers_t* layers, nte_verdict_acc_t* verdict)
{
    char tmp[sizeof out->target + 16U];
    const char* slash = strrchr(out->target, '/');
    const int dir_len = (slash != NULL) ? (int)(slash - out->target + 1) : 0;
    (void)snprintf(tmp, sizeof tmp, "%.*s.%s.XXXXXX", dir_len, out->target,
                   (slash != NULL) ? (slash + 1) : out->target);
    const int fd = mkstemp(tmp);
    if (fd < 0) {
        fprintf(stderr, PROG ": error: --out %s: cannot write in its directory: %s\n", a->out,
                strerror(errno));
        return EXIT_BAD_INPUT;
    }
    FILE* fh = (fchmod(fd, out->mode) == 0) ? fdopen(fd, "w") : NULL;
    if (fh == NULL) {
        fprintf(stderr, PROG ": error: --out %s: cannot write: %s\n", a->out, strerror(errno));
        (void)close(fd);
        (void)unlink(tmp);
        return 1;
    }
    counts->rejected = 0U;
    counts->gated = 0U;
    counts->clipped = 0U;
    nte_param_estimate_t pe[NTE_IDENTIFIED_MAX];
    const size_t np = nte_get_params(est, pe, NTE_IDENTIFIED_MAX);
    fprintf(fh, "t_s,force_hat_n,z,innovation_n,status");
    for (size_t j = 0U; j < np; j++) {
        fprintf(fh, ",%s,%s_sd", nte_param_name(pe[j].id), nte_param_name(pe[j].id));
    }
    const int with_layer = (a->model == 3) && (a->layers != 0);
    fprintf(fh, "%s%s%s\n", (a->robust != 0) ? ",confidence" : "",
            (a->contact == 1) ? ",surface_mm,tare_n,contact" : "", with_layer ? ",layer" : "");
    for (size_t k = 0U; k < tr->n; k++) {
        nte_sample_t s;
        nte_output_t o;
        nte_trial_sample(tr, k, a->predict_only, &s);
        (void)nte_step(est, &s, &o);
        *last = o;
        counts->rejected += ((o.status & NTE_STATUS_REJECTED) != 0U) ? 1U : 0U;
        counts->gated += ((o.status & NTE_STATUS_GATED) != 0U) ? 1U : 0U;
        counts->clipped += ((o.status & NTE_STATUS_CLIPPED) != 0U) ? 1U : 0U;
        nte_verdict_add(verdict, tr->t_s[k], (double)o.innovation_n, o.status,
                        (double)o.confidence);
        (void)nte_get_params(est, pe, NTE_IDENTIFIED_MAX);
        if (snaps != NULL) { /* --export-config's candidates (export_select.h) */
            for (size_t c = 0U; c < NTE_EXPORT_CANDIDATES; c++) {
                if (nte_export_candidate_sample(c, tr->n) == k) {
                    snaps[c].sample = k;
                    snaps[c].t_s = tr->t_s[k];
                    snaps[c].np = np;
                    (void)memcpy(snaps[c].pe, pe, sizeof pe);
                }
            }
            nte_export_layers_add(layers, k, tr->depth_mm[k], a->contact == 1, with_layer, &o);
        }
        fprintf(fh, "%.17g," REAL_FMT "," REAL_FMT "," REAL_FMT ",%u", tr->t_s[k],
                (double)o.force_hat_n, (double)o.z, (double)o.innovation_n, (unsigned)o.status);
        for (size_t j = 0U; j < np; j++) {
            fprintf(fh, "," REAL_FMT "," REAL_FMT, (double)pe[j].value, (double)pe[j].sd);
        }
        if (a->robust != 0) {
            fprintf(fh, "," REAL_FMT, (double)o.confidence);
        }
        if (a->contact == 1) {
            fprintf(fh, "," REAL_FMT "," REAL_FMT ",%d", (double)o.surface_mm, (double)o.tare_n,
                    (int)o.contact);
        }
        if (with_layer) {
            fprintf(fh, ",%u", (unsigned)o.layer);
        }
        fprintf(fh, "\n");
    }
    if ((fclose(fh) != 0) || (rename(tmp, out->target) != 0)) {
        fprintf(stderr, PROG ": error: --out %s: cannot write: %s\n", a->out, strerror(errno));
        (void)unlink(tmp);
        return 1;
    }
    return 0;
}

/* --export-config: what was identified, as tools/estimate.py export_config writes it (the
 * double build writes the reference's bytes but for "source"): the snapshot that replays the
 * record best (export_select.h); temporary file, then rename */
static int export_config(const args_t* a, const out_t* out, const nte_export_snapshot_t* snap,
                         const nte_export_choice_t* choice, const nte_config_t* cfg, size_t samples,
                         const nte_output_t* last, double r_n2)
{
    nte_export_t e;
    (void)memset(&e, 0, sizeof e);
    e.source = "nte-run";
    e.model = a->model;
    (void)memcpy(e.params, choice->params, sizeof e.params);
    (void)memcpy(e.sd, choice->sd, sizeof e.sd);
    e.n_g = choice->n_g;
    for (size_t k = 0U; k < choice->n_g; k++) {
        e.g_name[k] = choice->g_name[k];
        e.g[k] = choice->g[k];
        e.g_sd[k] = choice->g_sd[k];
    }
    e.replay_t_s = snap->t_s;
    e.replay_candidates = NTE_EXPORT_CANDIDATES;
    e.replay_rmse_n = choice->rmse_n;
    e.replay_final_rmse_n = choice->final_rmse_n;
    e.replay_peak_n = choice->peak_n;
    e.fit_rmse_n = choice->fit_rmse_n;
    e.fit_passes = choice->fit_passes;
    e.r_n2 = r_n2;
    e.samples = samples;
    e.direction_memory = cfg->direction_memory ? 1 : 0;
    e.presliding_mm = choice->presliding_mm;
    e.relaxation = cfg->relaxation ? 1 : 0;
    e.relax_branches = a->relax_branches;
    e.tau_fast_s = a->tau_fast_s;
    e.tau_slow_s = a->tau_slow_s;
    e.n_sets = choice->n_sets;
    for (size_t k = 0U; k < choice->n_sets; k++) {
        e.set_start_mm[k] = choice->set_start_mm[k];
        for (size_t j = 0U; j < NTE_LAYER_SET_VALUES; j++) {
            e.set_values[k][j] = choice->set_values[k][j];
            e.set_sd[k][j] = choice->set_sd[k][j];
        }
    }
    e.contact = a->contact == 1;
    e.surface_mm = (double)last->surface_mm;
    e.tare_n = (double)last->tare_n;
    char text[8192];
    const int n = nte_config_file_export_text(&e, text, sizeof text);
    char tmp[sizeof out->target + 16U];
    const char* slash = strrchr(out->target, '/');
    const int dir_len = (slash != NULL) ? (int)(slash - out->target + 1) : 0;
    (void)snprintf(tmp, sizeof tmp, "%.*s.%s.XXXXXX", dir_len, out->target,
                   (slash != NULL) ? (slash + 1) : out->target);
    const int fd = (n > 0) ? mkstemp(tmp) : -1;
    FILE* fh = ((fd >= 0) && (fchmod(fd, out->mode) == 0)) ? fdopen(fd, "w") : NULL;
    if ((fh == NULL) || (fwrite(text, 1U, (size_t)n, fh) != (size_t)n) || (fclose(fh) != 0) ||
        (rename(tmp, out->target) != 0)) {
        fprintf(stderr, PROG ": error: --export-config %s: cannot write: %s\n", a->export_config,
                strerror(errno));
        if ((fh == NULL) && (fd >= 0)) {
            (void)close(fd);
        }
        (void)unlink(tmp);
        return 1;
    }
    return 0;
}

/* The lines about the export (tools/export_select.py replay_summary, replay_warning). */
static void print_replay(const nte_export_snapshot_t* snap, const nte_export_choice_t* ch)
{
    if (!isfinite(ch->rmse_n)) {
        printf("exported the final estimates: no surface was found, so they were not replayed "
               "from depth alone\n");
        return;
    }
    /* export_select.exported_rmse: the fitted values', else the snapshot's */
    const double rmse = isfinite(ch->fit_rmse_n) ? ch->fit_rmse_n : ch->rmse_n;
    const double frac = (ch->peak_n > 0.0) ? (rmse / ch->peak_n) : (double)INFINITY;
    printf("exported the estimates at t = %.3f s (best of %u) fitted to the record (%u passes",
           snap->t_s, (unsigned)NTE_EXPORT_CANDIDATES, ch->fit_passes);
    if (isfinite(ch->restart_from_rmse_n)) {
        printf("; run again from the record's first relaxation strengths after a first fit at "
               "%.4g N",
               ch->restart_from_rmse_n);
    }
    printf("): replayed from depth alone, RMSE %.4g N = %.1f %% of the peak %.4g N (the snapshot "
           "unfitted: %.4g N, the final estimates: %.4g N)\n",
           rmse, 100.0 * frac, ch->peak_n, ch->rmse_n, ch->final_rmse_n);
    if ((ch->peak_n > 0.0) && (frac > NTE_EXPORT_WARN_FRACTION)) {
        fprintf(stderr,
                "warning: the exported parameters replay their own record from depth alone at "
                "%.0f %% of its peak force (more than %.0f %%): a prediction from them will miss "
                "by about as much\n",
                100.0 * frac, 100.0 * NTE_EXPORT_WARN_FRACTION);
    }
}

/* The closing verdict (verdict.h), the last line on stdout; the start's warning on stderr.
 * The noise is measured on the force as read (converted; --predict-only does not zero it). */
static void print_verdict(const args_t* a, const nte_trial_t* tr, const nte_verdict_acc_t* acc)
{
    nte_verdict_opts_t vo;
    double sd = (double)NAN;
    vo.rest_n = isnan(a->noise) ? nte_verdict_rest_noise(tr->depth_mm, tr->force_n, tr->n, &sd)
                                : 0U;
    vo.noise_n = isnan(a->noise) ? sd : a->noise;
    vo.predict_only = a->predict_only;
    vo.robust = a->robust;
    char line[1024];
    char warning[512];
    if (nte_verdict_text(acc, &vo, line, sizeof line, warning, sizeof warning) == 0) {
        printf("%s\n", line);
        if (warning[0] != '\0') {
            fprintf(stderr, "%s\n", warning);
        }
    }
}

int main(int argc, char** argv)
{
    args_t a;
    char msg[8192];
    const int pr = parse_args(argc, argv, &a);
    if (pr != 0) {
        return pr;
    }
    /* --config: read and merged into the flags as nte-ref estimate does (tools/cli.py
     * _file_config, model3_overrides): defaults, then the file, then the flags given */
    nte_file_config_t fc;
    (void)memset(&fc, 0, sizeof fc);
    const int have_fc = a.config != NULL;
    if (have_fc && (nte_config_file_read(a.config, &fc, msg, sizeof msg) != 0)) {
        return bad(msg);
    }
    if (a.predict_only && !have_fc) {
        return bad("argument --predict-only: needs --config FILE (the parameters to predict "
                   "with)");
    }
    if (a.predict_only && (a.robust != 0)) {
        return bad("argument --predict-only: the bank only (the robust estimator's refinement "
                   "would move the parameters)");
    }
    if (have_fc) {
        a.model = (a.model == 0) ? fc.model : a.model;
        if (isnan(a.surface) && (a.contact != 0)) {
            if (fc.has_surface) {
                a.surface = fc.surface_mm;
                a.contact = 1;
            } else if (fc.surface_list) {
                if (a.predict_only) {
                    (void)snprintf(msg, sizeof msg,
                                   "%s: key 'surface_mm': per-trial surfaces "
                                   "give no surface to predict with; give --surface MM",
                                   a.config);
                    return bad(msg);
                }
                a.contact = 1;
            }
        }
        a.presliding_mm = (fc.has_presliding && !a.given_presliding) ? fc.presliding_mm
                                                                     : a.presliding_mm;
        a.tau_fast_s = (fc.has_tau_fast && !a.given_tau_fast) ? fc.tau_fast_s : a.tau_fast_s;
        a.tau_slow_s = (fc.has_tau_slow && !a.given_tau_slow) ? fc.tau_slow_s : a.tau_slow_s;
        a.relax_branches = (fc.has_relax_branches && !a.given_relax_branches) ? fc.relax_branches
                                                                              : a.relax_branches;
        /* the flags can only switch these off */
        a.relaxation = (fc.has_relaxation && a.relaxation) ? fc.relaxation : a.relaxation;
        a.direction_memory = (fc.has_direction_memory && a.direction_memory) ? fc.direction_memory
                                                                             : a.direction_memory;
    }
    if ((a.contact == -1) && isnan(a.surface) && (a.model == 3) && !a.predict_only) {
        /* the front end is part of Model III: a record as a rig writes it starts in the air */
        a.contact = 1;
    }
    if (a.predict_only && (a.contact == 1) && isnan(a.surface)) {
        return bad("argument --predict-only: the front end finds the surface from the force; "
                   "give --surface MM");
    }
    const nte_preset_t* preset = find_preset(a.preset);
    if (preset == NULL) {
        size_t o = (size_t)snprintf(msg, sizeof msg, "unknown preset '%s' (known: ", a.preset);
        for (size_t i = 0U; (i < NTE_PRESET_COUNT) && (o < sizeof msg); i++) {
            o += (size_t)snprintf(msg + o, sizeof msg - o, "%s%s", (i > 0U) ? ", " : "",
                                  nte_presets[i].name);
        }
        if (o < sizeof msg) {
            (void)snprintf(msg + o, sizeof msg - o, ")");
        }
        return bad(msg);
    }
    for (int j = (int)nte_param_g_fast; (j <= (int)nte_param_g_slow) && (a.model != 3); j++) {
        if (a.start.given[j] != 0) {
            (void)snprintf(msg, sizeof msg,
                           "argument --start: %s is a relaxation strength of "
                           "Model III (not of Model %s)",
                           nte_param_name((nte_param_id_t)j), (a.model == 1) ? "I" : "II");
            return bad(msg);
        }
    }
    out_t out;
    (void)memset(&out, 0, sizeof out);
    if (check_out("--out", a.out, &out, msg, sizeof msg) != 0) {
        return bad(msg);
    }
    out_t exp_out;
    (void)memset(&exp_out, 0, sizeof exp_out);
    if ((a.export_config != NULL) &&
        (check_out("--export-config", a.export_config, &exp_out, msg, sizeof msg) != 0)) {
        return bad(msg);
    }
    nte_config_t cfg;
    const nte_schedule_t sch = (strcmp(a.schedule, "rotate") == 0) ? nte_schedule_rotate
                                                                   : nte_schedule_all;
    if (strcmp(a.profile, "paper") == 0) {
        nte_config_paper(&cfg, a.model, sch);
    } else {
        nte_config_default(&cfg, a.model, sch);
    }
    if ((a.columns != NULL) &&
        (nte_column_map_parse(a.columns, a.predict_only, &a.units.columns, msg, sizeof msg) != 0)) {
        return bad(msg);
    }
    /* --predict-only reads no force: a file of depths alone is an input */
    a.units.columns.force_ignored = a.predict_only;
    nte_trial_t tr;
    if (nte_trial_read_columns(a.csv, &a.units.columns, &tr, msg, sizeof msg) != 0) {
        return bad(msg);
    }
    if ((tr.clock != 0) && (strcmp(a.units.time, "s") != 0)) {
        /* csvio.read_trial: a clock reads in seconds by its own writing */
        (void)snprintf(msg, sizeof msg,
                       "--time-unit %s: column '%s' holds clock times, read in "
                       "seconds",
                       a.units.time, a.units.columns.t);
        nte_trial_free(&tr);
        return bad(msg);
    }
    if ((tr.units_row_line > 0U) &&
        (nte_units_row_check(a.csv, &tr, &a.units, msg, sizeof msg) != 0)) {
        nte_trial_free(&tr);
        return bad(msg);
    }
    nte_trial_convert(&tr, &a.units);
    if (a.units.check != 0) {
        /* the configuration's accepted ranges (csvio.Limits.from_config); with the front end
         * on, the stage position may lie anywhere in +-depth_max_mm (the air gap is no error) */
        nte_limits_t lim;
        lim.depth_max_mm = (double)cfg.depth_max_mm;
        lim.depth_min_mm = (a.contact == 1) ? -lim.depth_max_mm : (double)cfg.depth_min_mm;
        lim.speed_max_mm_s = (double)cfg.speed_max_mm_s;
        lim.force_max_n = (double)cfg.force_max_n;
        lim.dt_max_s = (double)cfg.dt_max_s;
        if (nte_units_check(a.csv, &tr, &a.units, &lim, msg, sizeof msg) != 0) {
            nte_trial_free(&tr);
            return bad(msg);
        }
    }
    nte_trial_left_out_note(a.csv, &tr, &a.units.columns, msg, sizeof msg);
    if (msg[0] != '\0') {
        (void)fprintf(stderr, "%s\n", msg);
    }
    /* the config's params are the new nominal values unless --preset is given; --start's
     * on top of either */
    double values[7];
    (void)memcpy(values, (have_fc && !a.given_preset) ? fc.params : preset->values, sizeof values);
    for (size_t j = 0U; j < 7U; j++) {
        values[j] = (a.start.given[j] != 0) ? a.start.value[j] : values[j];
    }
    double start[7];
    if (nte_start_values(values, (uint64_t)a.seed, a.factor, a.model, start) != 0) {
        nte_trial_free(&tr);
        (void)snprintf(msg, sizeof msg, "init factor must be >= 1 (got %g)", a.factor);
        return bad(msg);
    }
    /* Model I's fixed beta0 is the preset's beta (reference_py/MODEL.md §2) */
    cfg.beta0 = (nte_real_t)values[6];
    /* the seven force-model parameters; Model III's relaxation strengths keep the
     * configuration's nominal values (the starts move only the seven) */
    if (nte_preset_nominal(&cfg, start) != 0) {
        nte_trial_free(&tr);
        return bad("nominal f1 must exceed -f2 (g(0) = f1 + f2 must be positive)");
    }
    if (have_fc && fc.has_strengths) {
        cfg.nominal[7] = (nte_real_t)fc.g[0];
        cfg.nominal[8] = (nte_real_t)fc.g[1];
    }
    for (size_t j = 7U; j < NTE_PARAM_COUNT; j++) {
        cfg.nominal[j] = (a.start.given[j] != 0) ? (nte_real_t)a.start.value[j] : cfg.nominal[j];
    }
    /* the measurement noise variance: the profile's, --config's, --noise's squared */
    const double r_n2 = isnan(a.noise) ? ((have_fc && fc.has_r_n2) ? fc.r_n2 : (double)cfg.r_n2)
                                       : (a.noise * a.noise);
    cfg.r_n2 = (nte_real_t)r_n2;
    cfg.predict_only = a.predict_only != 0;
    cfg.presliding_mm = (nte_real_t)a.presliding_mm;
    cfg.tau_fast_s = (nte_real_t)a.tau_fast_s;
    cfg.tau_slow_s = (nte_real_t)a.tau_slow_s;
    cfg.relax_branches = a.relax_branches;
    cfg.relaxation = a.relaxation != 0;
    cfg.layers = a.layers != 0;
    cfg.direction_memory = a.direction_memory != 0;
    if (have_fc && (a.model == 3)) {
        /* the layer sets are Model III's, as the rest of the file's Model III fields */
        nte_config_file_layer_sets(&fc, &cfg);
    }
    cfg.estimator = (a.robust != 0) ? nte_estimator_robust : nte_estimator_bank;
    cfg.contact.enabled = (a.contact == 1);
    cfg.contact.surface_mm = (nte_real_t)a.surface;
    static nte_t est;
    const nte_err_t err = nte_init(&est, &cfg);
    if (err != nte_err_ok) {
        nte_trial_free(&tr);
        if ((err == nte_err_bad_nominal) && (a.model == 3) && cfg.relaxation) {
            /* every nominal value was checked in range before: the strengths' sum */
            return bad("nominal relaxation strengths g_fast, g_slow must be > 0 with a sum < 1");
        }
        (void)snprintf(msg, sizeof msg, "invalid estimator configuration (nte_err %d)", (int)err);
        return bad(msg);
    }
    counts_t counts;
    nte_output_t last;
    (void)memset(&last, 0, sizeof last);
    last.surface_mm = (nte_real_t)NAN;
    static nte_export_snapshot_t snaps[NTE_EXPORT_CANDIDATES];
    nte_export_layers_t layers;
    nte_export_layers_start(&layers);
    nte_verdict_acc_t verdict;
    nte_verdict_start(&verdict);
    int rc = run(&a, &out, &tr, &est, &counts, &last, (a.export_config != NULL) ? snaps : NULL,
                 &layers, &verdict);
    nte_export_choice_t choice;
    (void)memset(&choice, 0, sizeof choice);
    if ((rc == 0) && (a.export_config != NULL)) {
        static nte_t scratch; /* the replays of the candidates */
        if (nte_export_choose(&cfg, &tr, snaps, (a.layer_sets != 0) ? &layers : NULL, values,
                              a.model, (double)last.surface_mm, (double)last.tare_n, &scratch,
                              &choice) != 0) {
            fprintf(stderr, PROG ": error: --export-config: a replay of the estimates was refused "
                                 "or memory ran out\n");
            rc = 1;
        } else {
            rc = export_config(&a, &exp_out, &snaps[choice.candidate], &choice, &cfg, tr.n, &last,
                               r_n2);
        }
    }
    if (rc == 0) {
        printf("%zu samples, Model %s, " PRECISION "; wrote %s\n", tr.n,
               (a.model == 1) ? "I" : ((a.model == 2) ? "II" : "III"), a.out);
        printf("samples: %zu; rejected %zu, gated %zu, clipped %zu\n", tr.n, counts.rejected,
               counts.gated, counts.clipped);
        if (a.export_config != NULL) {
            print_replay(&snaps[choice.candidate], &choice);
        }
        print_verdict(&a, &tr, &verdict);
    }
    nte_trial_free(&tr);
    return rc;
}
