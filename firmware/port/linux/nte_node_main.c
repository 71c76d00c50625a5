/*
 * nte-node: the estimator as a CAN node on Linux SocketCAN.
 *
 *   nte-node --iface vcan0 [--base-id 0x200] [--model 1|2|3] [--preset NAME] [--config FILE]
 *            [--depth-timeout-ms MS] [--heartbeat-ms MS] [--params-per-step N]
 *            [--resync-gap-ms MS] [--no-kernel-filter] [--ready FILE] [--stats FILE]
 *            [--record OUT.log] [--received IN.log]
 *   nte-node --replay IN.log [--record OUT.log] [same options; --iface names the output]
 *
 * Runs the node loop (firmware/node) until SIGINT or SIGTERM, then prints its counters on
 * stderr, writes them as JSON to --stats FILE (also on SIGUSR1) and exits 0.  With --replay the
 * node reads its frames from a candump -L log instead of a CAN interface (the log's timestamps
 * are its clock), writes what it sends to --record (candump -L; default stdout) and stops at the
 * end of the log: deterministic, no CAN needed.  On an interface, --record and --received log
 * every frame the node sends / receives (candump -L, port clock): exact bookkeeping on a shared
 * bus, where other senders may use the node's ids.
 * Exit status: 0 clean stop, 2 bad arguments, 3 AF_CAN unavailable in this kernel,
 * 4 no such CAN interface, 1 other failure.
 */
#include "nte_config_file.h"
#include "nte_node.h"
#include "nte_port_log.h"
#include "nte_port_socketcan.h"
#include "nte_presets.h"
#include "nte_preset_config.h"
#include "nte_settings_file.h"

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define PROG "nte-node"
#define EXIT_USAGE 2
#define EXIT_NO_AF_CAN 3
#define EXIT_NO_IFACE 4

static volatile sig_atomic_t g_stop = 0;
static volatile sig_atomic_t g_dump = 0;

static void on_stop(int sig)
{
    (void)sig;
    g_stop = 1;
}

static void on_dump(int sig)
{
    (void)sig;
    g_dump = 1;
}

typedef struct args_t {
    const char* iface;
    const char* preset;
    const char* ready;
    const char* stats;
    const char* replay;
    const char* record;
    const char* received;
    unsigned long base_id;
    unsigned long resync_gap_ms;
    int model;
    const char* config; /* --config FILE.json (firmware/config_json): model, params, r_n2 */
    int given_model;
    int given_preset;
    unsigned long timeout_ms;
    unsigned long heartbeat_ms;
    unsigned long params_per_step;
    int kernel_filter;
} args_t;

static int usage(const char* err)
{
    fprintf(stderr,
            "usage: " PROG " --iface IFACE [--base-id 0x200] [--model 1|2|3] [--preset NAME]\n"
            "       [--config FILE.json (default: none; its model 1|2|3, params as the nominal\n"
            "       values unless --preset, r_n2; Model III's presliding_mm, tau_fast_s,\n"
            "       tau_slow_s, relax_branches, relaxation, direction_memory, strengths, layer\n"
            "       sets, and a single surface_mm as a known surface, applied as a Setting\n"
            "       transfer of the file is; flags given override it)]\n"
            "       [--depth-timeout-ms 50] [--heartbeat-ms 100] [--params-per-step 1]\n"
            "       [--resync-gap-ms 20] [--no-kernel-filter] [--ready FILE] [--stats FILE]\n"
            "       [--record OUT.log] [--received IN.log]\n"
            "       " PROG " --replay IN.log [--record OUT.log] [the options above]\n"
            "The needle-tissue force estimator as a CAN node (frames: firmware/can/nte.dbc).\n"
            "--model (default 2): 1 Model I, 2 Model II, 3 Model III (Model II + direction\n"
            "memory + relaxation, g_fast and g_slow published as Params 7 and 8) with the\n"
            "contact front end as in nte-run: Depth frames carry the stage position, the tare\n"
            "is learned in the air and the surface found from the force onset, published in\n"
            "the Contact frame (on change and every 100 ms of sensor time).\n"
            "Stops on SIGINT/SIGTERM; SIGUSR1 rewrites --stats. --replay reads the frames of a\n"
            "candump -L log (its timestamps are the clock) instead of an interface, writes the\n"
            "frames sent to --record (candump -L, default stdout) and stops at its end. On an\n"
            "interface, --record/--received log the frames the node sends/receives.\n"
            "Exit status: 0 stopped, 2 bad arguments, 3 no AF_CAN in this kernel, 4 no such CAN\n"
            "interface, 1 other error.\n");
    if (err != NULL) {
        fprintf(stderr, PROG ": error: %s\n", err);
    }
    return EXIT_USAGE;
}

static int parse_ulong(const char* s, unsigned long* out)
{
    char* end = NULL;
    errno = 0;
    *out = strtoul(s, &end, 0);
    return ((end == s) || (*end != '\0') || (errno != 0) || (s[0] == '-')) ? -1 : 0;
}

static int parse_args(int argc, char** argv, args_t* a)
{
    char msg[256];
    memset(a, 0, sizeof *a);
    a->preset = NTE_PRESET_DEFAULT;
    a->base_id = NTE_FRAMES_BASE_ID_DEFAULT;
    /* the node's defaults (nte_node.h), in the options' units */
    a->model = NTE_NODE_DEFAULT_MODEL;
    a->timeout_ms = NTE_NODE_DEFAULT_DEPTH_TIMEOUT_US / 1000u;
    a->heartbeat_ms = NTE_NODE_DEFAULT_HEARTBEAT_PERIOD_US / 1000u;
    a->params_per_step = NTE_NODE_DEFAULT_PARAMS_PER_STEP;
    a->resync_gap_ms = NTE_NODE_DEFAULT_RESYNC_GAP_US / 1000u;
    a->kernel_filter = 1;
    for (int i = 1; i < argc; i++) {
        const char* o = argv[i];
        if ((strcmp(o, "-h") == 0) || (strcmp(o, "--help") == 0)) {
            (void)usage(NULL);
            exit(0);
        }
        if (strcmp(o, "--no-kernel-filter") == 0) {
            a->kernel_filter = 0;
            continue;
        }
        if ((i + 1) >= argc) {
            (void)snprintf(msg, sizeof msg, "argument %s: expected one argument", o);
            return usage(msg);
        }
        const char* v = argv[++i];
        unsigned long u = 0u;
        if (strcmp(o, "--iface") == 0) {
            a->iface = v;
        } else if (strcmp(o, "--preset") == 0) {
            a->preset = v;
            a->given_preset = 1;
        } else if (strcmp(o, "--config") == 0) {
            a->config = v;
        } else if (strcmp(o, "--ready") == 0) {
            a->ready = v;
        } else if (strcmp(o, "--stats") == 0) {
            a->stats = v;
        } else if (strcmp(o, "--replay") == 0) {
            a->replay = v;
        } else if (strcmp(o, "--record") == 0) {
            a->record = v;
        } else if (strcmp(o, "--received") == 0) {
            a->received = v;
        } else if (strcmp(o, "--model") == 0) {
            if ((strcmp(v, "1") != 0) && (strcmp(v, "2") != 0) && (strcmp(v, "3") != 0)) {
                (void)snprintf(msg, sizeof msg,
                               "argument --model: invalid choice: '%s' "
                               "(choose from 1, 2, 3)",
                               v);
                return usage(msg);
            }
            a->model = v[0] - '0';
            a->given_model = 1;
        } else if ((strcmp(o, "--base-id") == 0) && (parse_ulong(v, &u) == 0)) {
            a->base_id = u;
        } else if ((strcmp(o, "--depth-timeout-ms") == 0) && (parse_ulong(v, &u) == 0)) {
            a->timeout_ms = u;
        } else if ((strcmp(o, "--heartbeat-ms") == 0) && (parse_ulong(v, &u) == 0)) {
            a->heartbeat_ms = u;
        } else if ((strcmp(o, "--params-per-step") == 0) && (parse_ulong(v, &u) == 0)) {
            a->params_per_step = u;
        } else if ((strcmp(o, "--resync-gap-ms") == 0) && (parse_ulong(v, &u) == 0)) {
            a->resync_gap_ms = u;
        } else {
            (void)snprintf(msg, sizeof msg, "bad argument: %s %s", o, v);
            return usage(msg);
        }
    }
    if ((a->iface == NULL) && (a->replay == NULL)) {
        return usage("the following argument is required: --iface (or --replay)");
    }
    if ((a->received != NULL) && (a->replay != NULL)) {
        return usage("argument --received: not with --replay (the input is the log)");
    }
    return 0;
}

static const nte_preset_t* find_preset(const char* name)
{
    for (size_t i = 0u; i < (size_t)NTE_PRESET_COUNT; i++) {
        if (strcmp(nte_presets[i].name, name) == 0) {
            return &nte_presets[i];
        }
    }
    return NULL;
}

/* The estimator configuration nte-run uses: default profile, schedule all, nominal = preset
 * (nte_preset_nominal, nte-run's: each value rounded once, f1's excess in double), Model I's
 * beta0 = the preset's beta. */
static int estimator_config(nte_config_t* cfg, int32_t model, const double values[7])
{
    nte_config_default(cfg, model, nte_schedule_all);
    cfg->beta0 = (nte_real_t)values[6];
    return nte_preset_nominal(cfg, values);
}

static void write_stats(const nte_node_t* n, const nte_port_socketcan_t* port, FILE* f)
{
    const nte_node_counters_t* c = &n->counters;
    fprintf(f, "{\"events\": {");
    for (uint32_t e = 0u; e < (uint32_t)NTE_NODE_EVENT_COUNT; e++) {
        fprintf(f, "%s\"%s\": %u", (e > 0u) ? ", " : "", nte_node_event_name(e),
                (unsigned)c->events[e]);
    }
    fprintf(f,
            "}, \"frames_lost\": %u, \"rx_accepted\": {\"depth\": %u, \"force\": %u, "
            "\"command\": %u, \"setting\": %u}, \"tx\": {\"estimate\": %u, \"params\": %u, "
            "\"heartbeat\": %u, "
            "\"contact\": %u, \"health\": %u}, "
            "\"steps\": %u, \"commands_applied\": %u, \"predict_on\": %u, "
            "\"predict_off\": %u, \"predict_depth_steps\": %u, \"settings_applied\": %u, "
            "\"model\": %d, "
            "\"state\": %d, \"send_enobufs\": %u, \"last_errno\": %d}\n",
            (unsigned)c->frames_lost, (unsigned)c->rx_accepted[0], (unsigned)c->rx_accepted[1],
            (unsigned)c->rx_accepted[2], (unsigned)c->rx_accepted[3], (unsigned)c->tx[0],
            (unsigned)c->tx[1], (unsigned)c->tx[2], (unsigned)c->tx[3], (unsigned)c->tx[4],
            (unsigned)c->steps, (unsigned)c->commands_applied, (unsigned)c->predict_on,
            (unsigned)c->predict_off, (unsigned)c->predict_depth_steps,
            (unsigned)c->settings_applied, (int)nte_node_model(n), (int)nte_node_state(n),
            (unsigned)port->send_errors_enobufs, port->last_errno);
}

static void dump_stats(const char* path, const nte_node_t* n, const nte_port_socketcan_t* port)
{
    char tmp[4096];
    if (path == NULL) {
        return;
    }
    (void)snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE* f = fopen(tmp, "w");
    if (f == NULL) {
        fprintf(stderr, PROG ": cannot write %s: %s\n", tmp, strerror(errno));
        return;
    }
    write_stats(n, port, f);
    if ((fclose(f) != 0) || (rename(tmp, path) != 0)) {
        fprintf(stderr, PROG ": cannot write %s: %s\n", path, strerror(errno));
    }
}

/* A port that logs every frame passing through another one (--record, --received). */
typedef struct tap_t {
    nte_node_port_t inner;
    FILE* sent;
    FILE* received;
} tap_t;

static void tap_write(FILE* f, uint64_t t_us, const nte_node_frame_t* fr)
{
    if (fr->extended) {
        fprintf(f, "(%llu.%06llu) can %08X#", (unsigned long long)(t_us / 1000000u),
                (unsigned long long)(t_us % 1000000u), (unsigned)fr->id);
    } else {
        fprintf(f, "(%llu.%06llu) can %03X#", (unsigned long long)(t_us / 1000000u),
                (unsigned long long)(t_us % 1000000u), (unsigned)fr->id);
    }
    if (fr->remote) {
        fputc('R', f);
    }
    for (uint32_t i = 0u; (i < fr->len) && (i < 8u) && !fr->remote; i++) {
        fprintf(f, "%02X", (unsigned)fr->data[i]);
    }
    fputc('\n', f);
}

static int tap_receive(void* ctx, nte_node_frame_t* frame)
{
    tap_t* t = (tap_t*)ctx;
    const int r = t->inner.receive(t->inner.ctx, frame);
    if ((r == 1) && (t->received != NULL)) {
        tap_write(t->received, t->inner.now_us(t->inner.ctx), frame);
    }
    return r;
}

static int tap_send(void* ctx, const nte_node_frame_t* frame)
{
    tap_t* t = (tap_t*)ctx;
    const int r = t->inner.send(t->inner.ctx, frame);
    if ((r >= 0) && (t->sent != NULL)) {
        tap_write(t->sent, t->inner.now_us(t->inner.ctx), frame);
    }
    return r;
}

static uint64_t tap_now(void* ctx)
{
    const tap_t* t = (const tap_t*)ctx;
    return t->inner.now_us(t->inner.ctx);
}

static FILE* open_log(const char* flag, const char* path)
{
    FILE* f = fopen(path, "w");
    if (f == NULL) {
        fprintf(stderr, PROG ": error: argument %s: cannot write %s: %s\n", flag, path,
                strerror(errno));
    }
    return f;
}

/* --replay: the node over log files, to the end of the input. */
static int run_replay(const args_t* a, const nte_node_config_t* cfg, nte_node_t* node)
{
    static nte_port_socketcan_t none;
    nte_port_log_t lp;
    memset(&lp, 0, sizeof lp);
    none.fd = -1;
    lp.iface = (a->iface != NULL) ? a->iface : "vcan0";
    lp.in = fopen(a->replay, "r");
    if (lp.in == NULL) {
        fprintf(stderr, PROG ": error: argument --replay: cannot read %s: %s\n", a->replay,
                strerror(errno));
        return EXIT_USAGE;
    }
    lp.out = stdout;
    if (a->record != NULL) {
        lp.out = fopen(a->record, "w");
        if (lp.out == NULL) {
            fprintf(stderr, PROG ": error: argument --record: cannot write %s: %s\n", a->record,
                    strerror(errno));
            (void)fclose(lp.in);
            return EXIT_USAGE;
        }
    }
    nte_node_port_t port = nte_port_log_port(&lp);
    int status = 0;
    if (nte_node_init(node, cfg, &port) != nte_node_ok) {
        status = 1;
    } else {
        while (lp.eof == 0) {
            (void)nte_node_poll(node);
        }
        dump_stats(a->stats, node, &none);
    }
    (void)fclose(lp.in);
    if ((lp.out != stdout) && (fclose(lp.out) != 0)) {
        fprintf(stderr, PROG ": error: cannot write %s: %s\n", a->record, strerror(errno));
        status = 1;
    } else if ((lp.out == stdout) && (fflush(stdout) != 0)) {
        status = 1;
    }
    if (lp.lines_bad > 0u) {
        fprintf(stderr, PROG ": %u line(s) of %s are not CAN frames: skipped\n",
                (unsigned)lp.lines_bad, a->replay);
    }
    return status;
}

int main(int argc, char** argv)
{
    static nte_node_t node;
    static nte_port_socketcan_t sock;
    args_t a;
    char msg[512];
    nte_node_config_t cfg;
    const int pr = parse_args(argc, argv, &a);
    if (pr != 0) {
        return pr;
    }
    const nte_preset_t* p = find_preset(a.preset);
    if (p == NULL) {
        (void)snprintf(msg, sizeof msg, "unknown preset '%s'", a.preset);
        return usage(msg);
    }
    /* --config: the same reader and rules as nte-run's (one line naming the key, exit 2) */
    nte_file_config_t fc;
    (void)memset(&fc, 0, sizeof fc);
    if ((a.config != NULL) && (nte_config_file_read(a.config, &fc, msg, sizeof msg) != 0)) {
        fprintf(stderr, PROG ": error: %s\n", msg);
        return EXIT_USAGE;
    }
    if ((a.config != NULL) && !a.given_model) {
        a.model = fc.model;
    }
    nte_node_config_default(&cfg, a.model);
    cfg.base_id = (uint32_t)((a.base_id <= 0x7FFu) ? a.base_id : 0x800u);
    cfg.depth_timeout_us = (uint32_t)((a.timeout_ms <= 3000u) ? a.timeout_ms * 1000u : 0u);
    cfg.heartbeat_period_us = (uint32_t)((a.heartbeat_ms <= 10000u) ? a.heartbeat_ms * 1000u : 0u);
    cfg.params_per_step = (uint32_t)((a.params_per_step <= 7u) ? a.params_per_step : 0u);
    cfg.resync_gap_us = (uint32_t)((a.resync_gap_ms <= 3000u) ? a.resync_gap_ms * 1000u : 0u);
    if (a.config == NULL) {
        if ((estimator_config(&cfg.estimator[0], 1, p->values) != 0) ||
            (estimator_config(&cfg.estimator[1], 2, p->values) != 0) ||
            (estimator_config(&cfg.estimator[2], 3, p->values) != 0)) {
            return usage("preset: f1 must exceed -f2");
        }
        /* Model III as nte-run runs it: the contact front end on, the surface found */
        cfg.estimator[2].contact.enabled = true;
    } else {
        /* --config: the file as the Setting items a transfer of it carries, written by the
         * node's own nte_node_setting_apply (nte_node.h SETTINGS): the file read here and the
         * file sent by nte-bench settings configure the node alike; --model and --preset
         * replace the file's model and parameters */
        nte_frames_setting_t items[NTE_SETTINGS_FILE_MAX];
        const size_t n = nte_settings_file_items(&fc, items);
        for (size_t i = 0u; i < n; i++) {
            const int j = (int)items[i].item - NTE_FRAMES_SETTING_PARAM0;
            if (items[i].item == (uint8_t)NTE_FRAMES_SETTING_MODEL) {
                items[i].value = (float)a.model;
            } else if (a.given_preset && (j >= 0) && (j < 7)) {
                items[i].value = (float)p->values[j];
            }
            if (nte_node_setting_apply(&cfg, items[i].item, items[i].value) != nte_node_ok) {
                (void)snprintf(msg, sizeof msg,
                               "%s: item %u of the configuration cannot be "
                               "applied to this node",
                               a.config, (unsigned)items[i].item);
                fprintf(stderr, PROG ": error: %s\n", msg);
                return EXIT_USAGE;
            }
        }
    }
    /* the port is needed for validation: check the node config with a stand-in first */
    uint32_t ids[4] = {(uint32_t)cfg.base_id + NTE_FRAMES_OFFSET_DEPTH,
                       (uint32_t)cfg.base_id + NTE_FRAMES_OFFSET_FORCE,
                       (uint32_t)cfg.base_id + NTE_FRAMES_OFFSET_COMMAND,
                       (uint32_t)cfg.base_id + NTE_FRAMES_OFFSET_SETTING};
    sock.fd = -1;
    {
        nte_node_port_t probe = nte_port_socketcan_port(&sock);
        const nte_node_err_t err = nte_node_init(&node, &cfg, &probe);
        if (err != nte_node_ok) {
            (void)snprintf(msg, sizeof msg,
                           "invalid node configuration (nte_node_err %d): base id <= 0x7EB, "
                           "depth timeout 1..3000 ms, heartbeat 1..10000 ms, params per step "
                           "1..7, resync gap 1..3000 ms",
                           (int)err);
            return usage(msg);
        }
    }
    if (a.replay != NULL) {
        return run_replay(&a, &cfg, &node);
    }
    const int rc = nte_port_socketcan_open(&sock, a.iface, ids, a.kernel_filter ? 4u : 0u, msg,
                                           sizeof msg);
    if (rc != nte_port_ok) {
        fprintf(stderr, PROG ": error: %s\n", msg);
        return (rc == nte_port_err_no_af_can)  ? EXIT_NO_AF_CAN
               : (rc == nte_port_err_no_iface) ? EXIT_NO_IFACE
                                               : 1;
    }
    static tap_t tap;
    tap.inner = nte_port_socketcan_port(&sock);
    tap.sent = (a.record != NULL) ? open_log("--record", a.record) : NULL;
    tap.received = (a.received != NULL) ? open_log("--received", a.received) : NULL;
    if (((a.record != NULL) && (tap.sent == NULL)) ||
        ((a.received != NULL) && (tap.received == NULL))) {
        nte_port_socketcan_close(&sock);
        return EXIT_USAGE;
    }
    nte_node_port_t port = {&tap, tap_receive, tap_send, tap_now};
    if (nte_node_init(&node, &cfg, &port) != nte_node_ok) {
        nte_port_socketcan_close(&sock);
        return 1;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_stop;
    (void)sigemptyset(&sa.sa_mask);
    (void)sigaction(SIGINT, &sa, NULL);
    (void)sigaction(SIGTERM, &sa, NULL);
    sa.sa_handler = on_dump;
    (void)sigaction(SIGUSR1, &sa, NULL);
    if (a.ready != NULL) {
        FILE* f = fopen(a.ready, "w");
        if (f != NULL) {
            fprintf(f, "%ld\n", (long)getpid());
            (void)fclose(f);
        }
    }
    fprintf(stderr, PROG ": %s, base 0x%03X, Model %s, preset %s, depth timeout %lu ms\n", a.iface,
            (unsigned)cfg.base_id, (a.model == 1) ? "I" : ((a.model == 2) ? "II" : "III"), a.preset,
            a.timeout_ms);
    while (g_stop == 0) {
        struct pollfd pfd;
        pfd.fd = sock.fd;
        pfd.events = POLLIN;
        pfd.revents = 0;
        const uint64_t now = port.now_us(port.ctx);
        const uint64_t due = nte_node_next_deadline_us(&node);
        const uint64_t wait_us = (due > now) ? (due - now) : 0u;
        const int timeout_ms = (int)((wait_us + 999u) / 1000u);
        const int pr2 = poll(&pfd, 1, timeout_ms);
        if ((pr2 < 0) && (errno != EINTR)) {
            fprintf(stderr, PROG ": poll: %s\n", strerror(errno));
            break;
        }
        while (nte_node_poll(&node) >= (int32_t)cfg.rx_budget) {
        }
        if (g_dump != 0) {
            g_dump = 0;
            dump_stats(a.stats, &node, &sock);
        }
    }
    dump_stats(a.stats, &node, &sock);
    write_stats(&node, &sock, stderr);
    nte_port_socketcan_close(&sock);
    int status = 0;
    if ((tap.sent != NULL) && (fclose(tap.sent) != 0)) {
        status = 1;
    }
    if ((tap.received != NULL) && (fclose(tap.received) != 0)) {
        status = 1;
    }
    return status;
}
