/*
 * can_vectors -- line-oriented driver of the generated CAN code and of nte_e2e, for
 * tests/python/test_can_codec.py, which compares it with cantools and autosar-e2e.
 *
 * Commands on stdin, one per line; one answer line each on stdout:
 *   SIGNALS <Message>               -> OK <name> <name> ...      (signal order used below)
 *   ENC <Message> <v1> ... <vn>     -> OK <16 hex digits>        (each value through the
 *                                      generated <signal>_encode, then <message>_pack)
 *   DEC <Message> <16 hex digits>   -> OK <v1> ... <vn>          (<message>_unpack, then
 *                                      <signal>_decode; %.9g)
 *   IDS                             -> OK <Message>:<offset>:<data id> ... (nte_frames tables)
 *   CRC <data id> <hex frame>       -> OK <crc>                  (nte_e2e_frame_crc)
 *   PROTECT <data id> <n> <hex>     -> OK <hex> x n              (one nte_e2e_tx_t, n frames)
 *   CHECK <data id> <hex> ...       -> OK <result>:<lost> ...    (one fresh nte_e2e_rx_t)
 * Errors answer "ERR <text>". Numbers in decimal; data ids may be 0x-prefixed.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "generated/nte_can.h"
#include "nte_e2e.h"
#include "nte_frames.h"

typedef struct {
    const char* name;
    void (*set)(void* msg, float value);
    float (*get)(const void* msg);
} signal_t;

typedef struct {
    const char* name;
    nte_frames_kind_t kind;
    void (*init)(void* msg);
    int (*pack)(uint8_t* dst, const void* msg);
    int (*unpack)(void* msg, const uint8_t* src);
    const signal_t* signals;
    size_t count;
} message_t;

/* kept by hand: SIG/MSG lines have no semicolon, so clang-format would chain them as one */
/* clang-format off */
#define SIG(msg, field)                                                                        \
    static void set_##msg##_##field(void* m, float v)                                          \
    {                                                                                          \
        ((struct nte_can_##msg##_t*)m)->field = nte_can_##msg##_##field##_encode(v);           \
    }                                                                                          \
    static float get_##msg##_##field(const void* m)                                            \
    {                                                                                          \
        return nte_can_##msg##_##field##_decode(((const struct nte_can_##msg##_t*)m)->field);  \
    }
#define ENTRY(msg, field, name) {name, set_##msg##_##field, get_##msg##_##field}
#define MSG(msg)                                                                               \
    static void init_##msg(void* m) { (void)nte_can_##msg##_init((struct nte_can_##msg##_t*)m); } \
    static int pack_##msg(uint8_t* d, const void* m)                                           \
    {                                                                                          \
        return nte_can_##msg##_pack(d, (const struct nte_can_##msg##_t*)m, 8u);                \
    }                                                                                          \
    static int unpack_##msg(void* m, const uint8_t* d)                                         \
    {                                                                                          \
        return nte_can_##msg##_unpack((struct nte_can_##msg##_t*)m, d, 8u);                    \
    }

MSG(depth)
SIG(depth, crc) SIG(depth, counter) SIG(depth, depth) SIG(depth, velocity) SIG(depth, sensor_time)
static const signal_t depth_signals[] = {
    ENTRY(depth, crc, "Crc"), ENTRY(depth, counter, "Counter"), ENTRY(depth, depth, "Depth"),
    ENTRY(depth, velocity, "Velocity"), ENTRY(depth, sensor_time, "SensorTime")};

MSG(force)
SIG(force, crc) SIG(force, counter) SIG(force, force) SIG(force, sensor_time)
SIG(force, sensor_fault)
static const signal_t force_signals[] = {
    ENTRY(force, crc, "Crc"), ENTRY(force, counter, "Counter"), ENTRY(force, force, "Force"),
    ENTRY(force, sensor_time, "SensorTime"), ENTRY(force, sensor_fault, "SensorFault")};

MSG(command)
SIG(command, crc) SIG(command, counter) SIG(command, reset) SIG(command, model_sel)
SIG(command, estimator_sel) SIG(command, adapt_cmd) SIG(command, force_source)
static const signal_t command_signals[] = {
    ENTRY(command, crc, "Crc"), ENTRY(command, counter, "Counter"),
    ENTRY(command, reset, "Reset"), ENTRY(command, model_sel, "ModelSel"),
    ENTRY(command, estimator_sel, "EstimatorSel"), ENTRY(command, adapt_cmd, "AdaptCmd"),
    ENTRY(command, force_source, "ForceSource")};

MSG(setting)
SIG(setting, crc) SIG(setting, counter) SIG(setting, item) SIG(setting, value)
static const signal_t setting_signals[] = {
    ENTRY(setting, crc, "Crc"), ENTRY(setting, counter, "Counter"),
    ENTRY(setting, item, "Item"), ENTRY(setting, value, "Value")};

MSG(estimate)
SIG(estimate, crc) SIG(estimate, counter) SIG(estimate, in_tissue) SIG(estimate, adapting)
SIG(estimate, saturated) SIG(estimate, fault) SIG(estimate, stale) SIG(estimate, force_est)
SIG(estimate, innovation) SIG(estimate, z)
static const signal_t estimate_signals[] = {
    ENTRY(estimate, crc, "Crc"), ENTRY(estimate, counter, "Counter"),
    ENTRY(estimate, in_tissue, "InTissue"), ENTRY(estimate, adapting, "Adapting"),
    ENTRY(estimate, saturated, "Saturated"), ENTRY(estimate, fault, "Fault"),
    ENTRY(estimate, stale, "Stale"),
    ENTRY(estimate, force_est, "ForceEst"), ENTRY(estimate, innovation, "Innovation"),
    ENTRY(estimate, z, "Z")};

MSG(params)
SIG(params, crc) SIG(params, counter) SIG(params, param_index)
SIG(params, sigma0) SIG(params, sigma0_std_log10) SIG(params, sigma1) SIG(params, sigma1_std_log10)
SIG(params, sigma2) SIG(params, sigma2_std_log10) SIG(params, f1) SIG(params, f1_std_log10)
SIG(params, f2) SIG(params, f2_std_log10) SIG(params, alpha) SIG(params, alpha_std_log10)
SIG(params, beta) SIG(params, beta_std_log10)
SIG(params, g_fast) SIG(params, g_fast_std_log10) SIG(params, g_slow) SIG(params, g_slow_std_log10)
SIG(params, delta) SIG(params, delta_std_log10)
static const signal_t params_signals[] = {
    ENTRY(params, crc, "Crc"), ENTRY(params, counter, "Counter"),
    ENTRY(params, param_index, "ParamIndex"),
    ENTRY(params, sigma0, "Sigma0"), ENTRY(params, sigma0_std_log10, "Sigma0StdLog10"),
    ENTRY(params, sigma1, "Sigma1"), ENTRY(params, sigma1_std_log10, "Sigma1StdLog10"),
    ENTRY(params, sigma2, "Sigma2"), ENTRY(params, sigma2_std_log10, "Sigma2StdLog10"),
    ENTRY(params, f1, "F1"), ENTRY(params, f1_std_log10, "F1StdLog10"),
    ENTRY(params, f2, "F2"), ENTRY(params, f2_std_log10, "F2StdLog10"),
    ENTRY(params, alpha, "Alpha"), ENTRY(params, alpha_std_log10, "AlphaStdLog10"),
    ENTRY(params, beta, "Beta"), ENTRY(params, beta_std_log10, "BetaStdLog10"),
    ENTRY(params, g_fast, "GFast"), ENTRY(params, g_fast_std_log10, "GFastStdLog10"),
    ENTRY(params, g_slow, "GSlow"), ENTRY(params, g_slow_std_log10, "GSlowStdLog10"),
    ENTRY(params, delta, "Delta"), ENTRY(params, delta_std_log10, "DeltaStdLog10")};

MSG(heartbeat)
SIG(heartbeat, crc) SIG(heartbeat, counter) SIG(heartbeat, node_state)
SIG(heartbeat, active_model) SIG(heartbeat, active_estimator) SIG(heartbeat, uptime)
SIG(heartbeat, e2e_errors) SIG(heartbeat, range_errors) SIG(heartbeat, step_time)
static const signal_t heartbeat_signals[] = {
    ENTRY(heartbeat, crc, "Crc"), ENTRY(heartbeat, counter, "Counter"),
    ENTRY(heartbeat, node_state, "NodeState"), ENTRY(heartbeat, active_model, "ActiveModel"),
    ENTRY(heartbeat, uptime, "Uptime"), ENTRY(heartbeat, active_estimator, "ActiveEstimator"),
    ENTRY(heartbeat, e2e_errors, "E2eErrors"), ENTRY(heartbeat, range_errors, "RangeErrors"),
    ENTRY(heartbeat, step_time, "StepTime")};

MSG(contact)
SIG(contact, crc) SIG(contact, counter) SIG(contact, contact_state) SIG(contact, surface_valid)
SIG(contact, active_model) SIG(contact, surface) SIG(contact, tare) SIG(contact, layer)
static const signal_t contact_signals[] = {
    ENTRY(contact, crc, "Crc"), ENTRY(contact, counter, "Counter"),
    ENTRY(contact, contact_state, "ContactState"), ENTRY(contact, surface_valid, "SurfaceValid"),
    ENTRY(contact, active_model, "ActiveModel"), ENTRY(contact, surface, "Surface"),
    ENTRY(contact, tare, "Tare"), ENTRY(contact, layer, "Layer")};

MSG(health)
SIG(health, crc) SIG(health, counter) SIG(health, refined) SIG(health, converged)
SIG(health, refining)
SIG(health, confidence) SIG(health, filter0_flags) SIG(health, filter1_flags)
SIG(health, filter2_flags)
static const signal_t health_signals[] = {
    ENTRY(health, crc, "Crc"), ENTRY(health, counter, "Counter"),
    ENTRY(health, refined, "Refined"), ENTRY(health, converged, "Converged"),
    ENTRY(health, refining, "Refining"),
    ENTRY(health, confidence, "Confidence"), ENTRY(health, filter0_flags, "Filter0Flags"),
    ENTRY(health, filter1_flags, "Filter1Flags"), ENTRY(health, filter2_flags, "Filter2Flags")};
/* clang-format on */

#define COUNT(a) (sizeof(a) / sizeof((a)[0]))
static const message_t messages[] = {
    {"Depth", nte_frames_kind_depth, init_depth, pack_depth, unpack_depth, depth_signals,
     COUNT(depth_signals)},
    {"Force", nte_frames_kind_force, init_force, pack_force, unpack_force, force_signals,
     COUNT(force_signals)},
    {"Command", nte_frames_kind_command, init_command, pack_command, unpack_command,
     command_signals, COUNT(command_signals)},
    {"Setting", nte_frames_kind_setting, init_setting, pack_setting, unpack_setting,
     setting_signals, COUNT(setting_signals)},
    {"Estimate", nte_frames_kind_estimate, init_estimate, pack_estimate, unpack_estimate,
     estimate_signals, COUNT(estimate_signals)},
    {"Params", nte_frames_kind_params, init_params, pack_params, unpack_params, params_signals,
     COUNT(params_signals)},
    {"Heartbeat", nte_frames_kind_heartbeat, init_heartbeat, pack_heartbeat, unpack_heartbeat,
     heartbeat_signals, COUNT(heartbeat_signals)},
    {"Contact", nte_frames_kind_contact, init_contact, pack_contact, unpack_contact,
     contact_signals, COUNT(contact_signals)},
    {"Health", nte_frames_kind_health, init_health, pack_health, unpack_health, health_signals,
     COUNT(health_signals)},
};

typedef union {
    struct nte_can_depth_t depth;
    struct nte_can_force_t force;
    struct nte_can_command_t command;
    struct nte_can_setting_t setting;
    struct nte_can_estimate_t estimate;
    struct nte_can_params_t params;
    struct nte_can_heartbeat_t heartbeat;
    struct nte_can_contact_t contact;
    struct nte_can_health_t health;
} any_message_t;

static const message_t* find_message(const char* name)
{
    size_t i;
    for (i = 0; i < COUNT(messages); ++i) {
        if ((name != NULL) && (strcmp(messages[i].name, name) == 0)) {
            return &messages[i];
        }
    }
    return NULL;
}

static int parse_hex(const char* s, uint8_t* out, size_t max)
{
    size_t n = 0;
    if (s == NULL) {
        return -1;
    }
    while ((s[0] != '\0') && (s[1] != '\0')) {
        unsigned v;
        if ((n >= max) || (sscanf(s, "%2x", &v) != 1)) {
            return -1;
        }
        out[n++] = (uint8_t)v;
        s += 2;
    }
    return (s[0] == '\0') ? (int)n : -1;
}

static void print_hex(const uint8_t* d, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        printf("%02x", d[i]);
    }
}

static void handle(char* line)
{
    const char* sep = " \t\r\n";
    char* cmd = strtok(line, sep);
    if (cmd == NULL) {
        return;
    }
    if ((strcmp(cmd, "SIGNALS") == 0) || (strcmp(cmd, "ENC") == 0) || (strcmp(cmd, "DEC") == 0)) {
        const message_t* m = find_message(strtok(NULL, sep));
        any_message_t msg;
        uint8_t data[8];
        size_t i;
        if (m == NULL) {
            printf("ERR unknown message\n");
            return;
        }
        if (cmd[0] == 'S') {
            printf("OK");
            for (i = 0; i < m->count; ++i) {
                printf(" %s", m->signals[i].name);
            }
            printf("\n");
            return;
        }
        m->init(&msg);
        if (cmd[0] == 'E') {
            for (i = 0; i < m->count; ++i) {
                char* tok = strtok(NULL, sep);
                if (tok == NULL) {
                    printf("ERR missing value\n");
                    return;
                }
                m->signals[i].set(&msg, strtof(tok, NULL));
            }
            memset(data, 0xAA, sizeof data);
            if (m->pack(data, &msg) != 8) {
                printf("ERR pack\n");
                return;
            }
            printf("OK ");
            print_hex(data, 8);
            printf("\n");
        } else {
            if (parse_hex(strtok(NULL, sep), data, 8) != 8) {
                printf("ERR hex\n");
                return;
            }
            if (m->unpack(&msg, data) != 0) {
                printf("ERR unpack\n");
                return;
            }
            printf("OK");
            for (i = 0; i < m->count; ++i) {
                printf(" %.9g", (double)m->signals[i].get(&msg));
            }
            printf("\n");
        }
        return;
    }
    if (strcmp(cmd, "IDS") == 0) {
        size_t i;
        printf("OK");
        for (i = 0; i < COUNT(messages); ++i) {
            uint32_t offset = 0;
            uint16_t data_id = 0;
            (void)nte_frames_offset(messages[i].kind, &offset);
            (void)nte_frames_data_id(messages[i].kind, &data_id);
            printf(" %s:%lu:%u", messages[i].name, (unsigned long)offset, (unsigned)data_id);
        }
        printf("\n");
        return;
    }
    if ((strcmp(cmd, "CRC") == 0) || (strcmp(cmd, "PROTECT") == 0) || (strcmp(cmd, "CHECK") == 0)) {
        char* id_tok = strtok(NULL, sep);
        uint16_t data_id;
        uint8_t data[8];
        int n;
        if (id_tok == NULL) {
            printf("ERR missing data id\n");
            return;
        }
        data_id = (uint16_t)strtoul(id_tok, NULL, 0);
        if (strcmp(cmd, "CRC") == 0) {
            n = parse_hex(strtok(NULL, sep), data, 8);
            if (n < 1) {
                printf("ERR hex\n");
                return;
            }
            printf("OK %u\n", (unsigned)nte_e2e_frame_crc(data_id, data, (size_t)n));
        } else if (strcmp(cmd, "PROTECT") == 0) {
            nte_e2e_tx_t tx;
            long count;
            char* count_tok = strtok(NULL, sep);
            long k;
            count = (count_tok != NULL) ? strtol(count_tok, NULL, 10) : -1;
            n = parse_hex(strtok(NULL, sep), data, 8);
            if ((count < 0) || (n < 2) || (nte_e2e_tx_init(&tx, data_id, (uint8_t)n) != 0)) {
                printf("ERR args\n");
                return;
            }
            printf("OK");
            for (k = 0; k < count; ++k) {
                (void)nte_e2e_protect(&tx, data, (size_t)n);
                printf(" ");
                print_hex(data, (size_t)n);
            }
            printf("\n");
        } else { /* CHECK: the expected length is that of the first frame */
            nte_e2e_rx_t rx;
            char* tok;
            int first = 1;
            printf("OK");
            while ((tok = strtok(NULL, sep)) != NULL) {
                uint8_t lost = 0;
                nte_e2e_result_t r;
                n = parse_hex(tok, data, 8);
                if (n < 0) {
                    printf(" ERR");
                    continue;
                }
                if (first) {
                    (void)nte_e2e_rx_init(&rx, data_id, (uint8_t)(n < 2 ? 8 : n));
                    first = 0;
                }
                r = nte_e2e_check(&rx, data, (size_t)n, &lost);
                printf(" %d:%u", (int)r, (unsigned)lost);
            }
            printf("\n");
        }
        return;
    }
    printf("ERR unknown command\n");
}

int main(void)
{
    char line[4096];
    while (fgets(line, sizeof line, stdin) != NULL) {
        handle(line);
        fflush(stdout);
    }
    return 0;
}
