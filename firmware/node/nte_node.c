/*
 * nte_node.c -- the platform-free node loop (see nte_node.h for the contract).
 */
#include "nte_node.h"

#include <math.h>
#include <string.h>

#define NTE_NODE_TICK_US 100u
#define NTE_NODE_IN_DEPTH 0u
#define NTE_NODE_IN_FORCE 1u
#define NTE_NODE_IN_COMMAND 2u
#define NTE_NODE_IN_SETTING 3u
#define NTE_NODE_INPUTS 4u
#define NTE_NODE_OUT_ESTIMATE 0u
#define NTE_NODE_OUT_PARAMS 1u
#define NTE_NODE_OUT_HEARTBEAT 2u
#define NTE_NODE_OUT_CONTACT 3u
#define NTE_NODE_OUT_HEALTH 4u
#define NTE_NODE_MODELS 3

static const char* const nte_node_event_names[NTE_NODE_EVENT_COUNT] = {
    "wrong_dlc",        "unknown_id",           "bad_crc",           "counter_invalid",
    "counter_repeated", "counter_skipped",      "out_of_range",      "time_backwards",
    "queue_overflow",   "send_failed",          "command_refused",   "stale",
    "receive_error",    "encode_error",         "time_jump_dropped", "time_resync",
    "command_stale",    "command_rate_limited", "sensor_stuck",      "sensor_saturated",
    "setting_refused"};

/* Signed difference a - b of two unwrapped tick counts (they wrap modulo 2^32). */
static int32_t nte_node_tdiff(uint32_t a, uint32_t b)
{
    const uint32_t d = a - b;
    return (d <= 0x7FFFFFFFu) ? (int32_t)d : -(int32_t)(~d) - 1;
}

static void nte_node_count(nte_node_t* self, nte_node_event_t ev)
{
    self->counters.events[(uint32_t)ev]++;
}

void nte_node_config_default(nte_node_config_t* cfg, int32_t model)
{
    if (cfg == NULL) {
        return;
    }
    (void)memset(cfg, 0, sizeof *cfg);
    cfg->base_id = NTE_FRAMES_BASE_ID_DEFAULT;
    cfg->model = model;
    nte_node_settings_begin(cfg);
    cfg->depth_timeout_us = NTE_NODE_DEFAULT_DEPTH_TIMEOUT_US;
    cfg->heartbeat_period_us = NTE_NODE_DEFAULT_HEARTBEAT_PERIOD_US;
    cfg->params_per_step = NTE_NODE_DEFAULT_PARAMS_PER_STEP;
    cfg->rx_budget = NTE_NODE_DEFAULT_RX_BUDGET;
    cfg->resync_gap_us = NTE_NODE_DEFAULT_RESYNC_GAP_US;
    cfg->command_interval_us = NTE_NODE_DEFAULT_COMMAND_INTERVAL_US;
}

void nte_node_settings_begin(nte_node_config_t* cfg)
{
    for (int32_t m = 0; m < NTE_NODE_MODELS; m++) {
        nte_config_default(&cfg->estimator[m], m + 1, nte_schedule_all);
    }
    cfg->estimator[2].contact.enabled = true; /* Model III: Depth is the stage position */
}

/* value as a whole number in lo..hi (lo >= 0), or -1 */
static int32_t nte_node_whole(float value, int32_t lo, int32_t hi)
{
    if (!(value >= (float)lo) || !(value <= (float)hi)) {
        return -1;
    }
    const int32_t n = (int32_t)value; /* truncated: (float)n <= value, equal when whole */
    return ((float)n < value) ? -1 : n;
}

nte_node_err_t nte_node_setting_apply(nte_node_config_t* cfg, uint32_t item, float value)
{
    nte_config_t* c3 = &cfg->estimator[2];
    const nte_real_t v = (nte_real_t)value;
    /* unsigned differences: a parameter when j < NTE_PARAM_COUNT, a layer set's field when
     * l < NTE_FRAMES_SETTING_LAYER_FIELDS * NTE_LAYER_SETS_MAX (both wrap below their base) */
    const uint32_t j = item - (uint32_t)NTE_FRAMES_SETTING_PARAM0;
    const uint32_t l = item - (uint32_t)NTE_FRAMES_SETTING_LAYER0;
    const uint32_t fields = (uint32_t)NTE_FRAMES_SETTING_LAYER_FIELDS;
    int32_t n = 0;
    if (!isfinite(value)) {
        return nte_node_err_bad_config;
    }
    if (j < (uint32_t)nte_param_g_fast) {
        /* the force model's seven values are every model's nominal, as --preset sets them;
         * f1_excess 0: the library derives f1's identified part from f1 and f2 */
        for (int32_t m = 0; m < NTE_NODE_MODELS; m++) {
            nte_config_t* c = &cfg->estimator[m];
            c->nominal[j] = v;
            if (j == (uint32_t)nte_param_beta) {
                c->beta0 = v; /* Model I's fixed beta */
            }
            if ((j == (uint32_t)nte_param_f1) || (j == (uint32_t)nte_param_f2)) {
                c->f1_excess = (nte_real_t)0;
            }
        }
    } else if (j < (uint32_t)nte_param_delta) {
        c3->nominal[j] = v; /* the relaxation strengths: Model III's alone */
    } else if (l < (fields * (uint32_t)NTE_LAYER_SETS_MAX)) {
        nte_layer_set_t* ls = &c3->layer_set[l / fields];
        if ((l % fields) == 0u) {
            ls->start_mm = v;
        } else {
            ls->values[(l % fields) - 1u] = v;
        }
    } else {
        switch (item) {
        case NTE_FRAMES_SETTING_PARAM0 + nte_param_delta:
            c3->presliding_mm = v; /* delta starts at presliding_mm (nte.h) */
            break;
        case NTE_FRAMES_SETTING_MODEL:
            n = nte_node_whole(value, 1, NTE_NODE_MODELS);
            cfg->model = (n > 0) ? n : cfg->model;
            break;
        case NTE_FRAMES_SETTING_R_N2:
            for (int32_t m = 0; m < NTE_NODE_MODELS; m++) {
                cfg->estimator[m].r_n2 = v;
            }
            break;
        case NTE_FRAMES_SETTING_SURFACE_MM: c3->contact.surface_mm = v; break;
        case NTE_FRAMES_SETTING_TAU_FAST_S: c3->tau_fast_s = v; break;
        case NTE_FRAMES_SETTING_TAU_SLOW_S: c3->tau_slow_s = v; break;
        case NTE_FRAMES_SETTING_RELAX_BRANCHES:
            n = nte_node_whole(value, 1, 2);
            c3->relax_branches = (n > 0) ? n : c3->relax_branches;
            break;
        case NTE_FRAMES_SETTING_RELAXATION:
            n = nte_node_whole(value, 0, 1);
            c3->relaxation = (n >= 0) ? (n == 1) : c3->relaxation;
            break;
        case NTE_FRAMES_SETTING_DIRECTION_MEMORY:
            n = nte_node_whole(value, 0, 1);
            c3->direction_memory = (n >= 0) ? (n == 1) : c3->direction_memory;
            break;
        case NTE_FRAMES_SETTING_LAYER_SETS:
            n = nte_node_whole(value, 0, (int32_t)NTE_LAYER_SETS_MAX);
            c3->layer_sets = (n >= 0) ? (uint32_t)n : c3->layer_sets;
            break;
        default: n = -1; break; /* BEGIN, COMMIT, a layer set beyond the capacity */
        }
    }
    return (n >= 0) ? nte_node_ok : nte_node_err_bad_config;
}

/* Every estimator configuration is its model's and passes nte_config_check. */
static bool nte_node_estimators_ok(const nte_node_config_t* cfg)
{
    for (int32_t m = 0; m < NTE_NODE_MODELS; m++) {
        if ((cfg->estimator[m].model != (m + 1)) ||
            (nte_config_check(&cfg->estimator[m]) != nte_err_ok)) {
            return false;
        }
    }
    return true;
}

static nte_node_err_t nte_node_check(const nte_node_config_t* cfg, const nte_node_port_t* port)
{
    uint32_t id = 0u;
    if ((port->receive == NULL) || (port->send == NULL) || (port->now_us == NULL)) {
        return nte_node_err_null;
    }
    if ((nte_frames_can_id(cfg->base_id, nte_frames_kind_health, &id) != nte_frames_ok) ||
        (cfg->model < 1) || (cfg->model > NTE_NODE_MODELS) || (cfg->depth_timeout_us < 100u) ||
        (cfg->depth_timeout_us > 3000000u) || (cfg->heartbeat_period_us < 1000u) ||
        (cfg->heartbeat_period_us > 10000000u) || (cfg->params_per_step < 1u) ||
        (cfg->params_per_step > (uint32_t)NTE_FRAMES_PARAM_COUNT_MODEL_II) ||
        (cfg->rx_budget < 1u) || (cfg->rx_budget > 65535u) || (cfg->resync_gap_us < 1000u) ||
        (cfg->resync_gap_us > 3000000u) || (cfg->command_interval_us > 10000000u)) {
        return nte_node_err_bad_config;
    }
    return nte_node_estimators_ok(cfg) ? nte_node_ok : nte_node_err_estimator;
}

/* (Re)start the estimator with `model` and `estimator`; on failure the previous one is kept. */
static bool nte_node_start_model(nte_node_t* self, int32_t model, nte_estimator_t estimator)
{
    nte_config_t c = self->cfg.estimator[model - 1];
    c.estimator = estimator;
    if (nte_init(&self->est, &c) != nte_err_ok) {
        return false;
    }
    self->model = model;
    self->estimator = estimator;
    self->state = nte_node_state_init;
    (void)memset(&self->last, 0, sizeof self->last);
    self->last.adapting = true;
    self->contact_sent = false;
    self->health_sent = false;
    return true;
}

/* Params multiplexer indices cycled in the active model: 0..6, Model III 0..8. */
static uint32_t nte_node_param_count(const nte_node_t* self)
{
    return (self->model == 3) ? (uint32_t)NTE_FRAMES_PARAM_COUNT
                              : (uint32_t)NTE_FRAMES_PARAM_COUNT_MODEL_II;
}

nte_node_err_t nte_node_init(nte_node_t* self, const nte_node_config_t* cfg,
                             const nte_node_port_t* port)
{
    static const nte_frames_kind_t in_kinds[NTE_NODE_INPUTS] = {
        nte_frames_kind_depth, nte_frames_kind_force, nte_frames_kind_command,
        nte_frames_kind_setting};
    static const nte_frames_kind_t out_kinds[NTE_NODE_OUTPUTS] = {
        nte_frames_kind_estimate, nte_frames_kind_params, nte_frames_kind_heartbeat,
        nte_frames_kind_contact, nte_frames_kind_health};
    if ((self == NULL) || (cfg == NULL) || (port == NULL)) {
        return nte_node_err_null;
    }
    const nte_node_err_t err = nte_node_check(cfg, port);
    if (err != nte_node_ok) {
        return err;
    }
    (void)memset(self, 0, sizeof *self);
    self->cfg = *cfg;
    self->port = *port;
    for (uint32_t i = 0u; i < NTE_NODE_INPUTS; i++) {
        (void)nte_frames_rx_init(&self->rx[i], in_kinds[i]);
    }
    for (uint32_t i = 0u; i < NTE_NODE_OUTPUTS; i++) {
        (void)nte_frames_tx_init(&self->tx[i], out_kinds[i]);
    }
    nte_frames_clock_reset(&self->clock);
    if (!nte_node_start_model(self, cfg->model, cfg->estimator[cfg->model - 1].estimator)) {
        return nte_node_err_estimator;
    }
    self->t_start_us = port->now_us(port->ctx);
    self->next_heartbeat_us = self->t_start_us + cfg->heartbeat_period_us;
    return nte_node_ok;
}

uint32_t nte_node_input_id(const nte_node_t* self, uint32_t kind)
{
    static const uint32_t offsets[NTE_NODE_INPUTS] = {
        NTE_FRAMES_OFFSET_DEPTH, NTE_FRAMES_OFFSET_FORCE, NTE_FRAMES_OFFSET_COMMAND,
        NTE_FRAMES_OFFSET_SETTING};
    return self->cfg.base_id + offsets[(kind < NTE_NODE_INPUTS) ? kind : 0u];
}

int32_t nte_node_model(const nte_node_t* self) { return self->model; }

nte_node_state_t nte_node_state(const nte_node_t* self) { return self->state; }

uint64_t nte_node_next_deadline_us(const nte_node_t* self) { return self->next_heartbeat_us; }

const char* nte_node_event_name(uint32_t event)
{
    return (event < (uint32_t)NTE_NODE_EVENT_COUNT) ? nte_node_event_names[event] : "?";
}

/* ------------------------------------------------------------------------------------------ */
/* Output                                                                                       */
/* ------------------------------------------------------------------------------------------ */

static void nte_node_send(nte_node_t* self, nte_frames_kind_t kind, uint32_t out_index,
                          const uint8_t* data)
{
    nte_node_frame_t f;
    uint32_t id = 0u;
    (void)nte_frames_can_id(self->cfg.base_id, kind, &id);
    (void)memset(&f, 0, sizeof f);
    f.id = id;
    f.len = NTE_FRAMES_LENGTH;
    (void)memcpy(f.data, data, NTE_FRAMES_LENGTH);
    if (self->port.send(self->port.ctx, &f) < 0) {
        nte_node_count(self, nte_node_ev_send_failed);
    } else {
        self->counters.tx[out_index]++;
    }
}

static void nte_node_publish_estimate(nte_node_t* self, const nte_frames_estimate_t* e)
{
    uint8_t data[NTE_FRAMES_LENGTH];
    if (nte_frames_encode_estimate(e, &self->tx[NTE_NODE_OUT_ESTIMATE], data) != nte_frames_ok) {
        nte_frames_estimate_t safe;
        (void)memset(&safe, 0, sizeof safe);
        safe.fault = true;
        safe.stale = e->stale;
        safe.adapting = e->adapting;
        nte_node_count(self, nte_node_ev_encode_error);
        if (nte_frames_encode_estimate(&safe, &self->tx[NTE_NODE_OUT_ESTIMATE], data) !=
            nte_frames_ok) {
            return;
        }
    }
    nte_node_send(self, nte_frames_kind_estimate, NTE_NODE_OUT_ESTIMATE, data);
}

/* Every parameter (fixed ones: the configured value, sd 0), frame index order. */
static void nte_node_all_params(const nte_node_t* self, float value[NTE_FRAMES_PARAM_COUNT],
                                float sd[NTE_FRAMES_PARAM_COUNT])
{
    nte_param_estimate_t pe[NTE_IDENTIFIED_MAX];
    const nte_config_t* c = &self->cfg.estimator[self->model - 1];
    /* NTE_FRAMES_PARAM_COUNT == NTE_PARAM_COUNT: the frame's indices are nte_param_id_t */
    for (uint32_t j = 0u; j < (uint32_t)NTE_FRAMES_PARAM_COUNT; j++) {
        value[j] = (float)c->nominal[j];
        sd[j] = 0.0f;
    }
    /* Model III's turn-over length starts at presliding_mm (nominal[delta] is not read) */
    value[nte_param_delta] = (float)c->presliding_mm;
    if (self->model == 1) {
        value[nte_param_beta] = (float)c->beta0;
    }
    const size_t n = nte_get_params(&self->est, pe, NTE_IDENTIFIED_MAX);
    for (size_t k = 0u; (k < n) && (k < (size_t)NTE_IDENTIFIED_MAX); k++) {
        const uint32_t j = (uint32_t)pe[k].id;
        if (j < (uint32_t)NTE_FRAMES_PARAM_COUNT) {
            value[j] = (float)pe[k].value;
            sd[j] = (float)pe[k].sd;
        }
    }
}

static void nte_node_publish_params(nte_node_t* self)
{
    float value[NTE_FRAMES_PARAM_COUNT];
    float sd[NTE_FRAMES_PARAM_COUNT];
    const uint32_t count = nte_node_param_count(self);
    nte_node_all_params(self, value, sd);
    for (uint32_t k = 0u; k < self->cfg.params_per_step; k++) {
        nte_frames_param_t p;
        uint8_t data[NTE_FRAMES_LENGTH];
        if (self->param_next >= count) {
            self->param_next = 0u; /* after a change from Model III to I or II */
        }
        p.index = self->param_next;
        p.value = value[p.index];
        p.std = sd[p.index];
        self->param_next = (uint8_t)((self->param_next + 1u) % count);
        if (nte_frames_encode_param(&p, &self->tx[NTE_NODE_OUT_PARAMS], data) != nte_frames_ok) {
            nte_node_count(self, nte_node_ev_encode_error);
            continue;
        }
        nte_node_send(self, nte_frames_kind_params, NTE_NODE_OUT_PARAMS, data);
    }
}

/* Whole 0.1 s steps in `us` microseconds, modulo 2^19 (the Heartbeat's Uptime wrap), without
 * a 64-bit division: on the Cortex-M4 that links the C library's 64-bit divide, 700 B of the
 * board's 32 KiB.  With us = h 2^32 + l and 2^32 = M 100000 + R (M = 42949, R = 67296),
 * floor(us / 100000) = h M + floor((h R + l) / 100000), and h R + l < us while h > 0, so the
 * loop ends (R < 2^17: within three rounds) with a high word of 0 and one 32-bit division.
 * The sum wraps modulo 2^32, a multiple of 2^19, so the result is exact. */
static uint32_t nte_node_tenths_wrapped(uint64_t us)
{
    const uint32_t m = 42949u;
    const uint32_t r = 67296u;
    uint32_t q = 0u;
    while ((us >> 32u) != 0u) {
        const uint32_t h = (uint32_t)(us >> 32u);
        q += h * m;
        us = ((uint64_t)h * r) + (uint32_t)us;
    }
    q += (uint32_t)us / 100000u;
    return q % 524288u;
}

static void nte_node_heartbeat(nte_node_t* self, uint64_t now)
{
    nte_frames_heartbeat_t hb;
    uint8_t data[NTE_FRAMES_LENGTH];
    const uint32_t* ev = self->counters.events;
    const uint64_t up_us = now - self->t_start_us;
    hb.node_state = (uint8_t)self->state;
    hb.active_model = (uint8_t)(self->model - 1);
    hb.active_estimator = (self->estimator == nte_estimator_robust) ? 1u : 0u;
    /* 0.1 s steps, reduced modulo the frame's wrap (2^19 steps) before the float */
    hb.uptime_s = (float)nte_node_tenths_wrapped(up_us) * 0.1f;
    hb.e2e_errors = ev[nte_node_ev_wrong_dlc] + ev[nte_node_ev_bad_crc] +
                    ev[nte_node_ev_counter_invalid] + ev[nte_node_ev_counter_repeated];
    hb.range_errors = ev[nte_node_ev_out_of_range] + ev[nte_node_ev_time_backwards] +
                      ev[nte_node_ev_time_jump_dropped];
    hb.step_time_s = (float)self->step_time_max_us * 1.0e-6f;
    if (nte_frames_encode_heartbeat(&hb, &self->tx[NTE_NODE_OUT_HEARTBEAT], data) ==
        nte_frames_ok) {
        nte_node_send(self, nte_frames_kind_heartbeat, NTE_NODE_OUT_HEARTBEAT, data);
    } else {
        nte_node_count(self, nte_node_ev_encode_error);
    }
    self->step_time_max_us = 0u;
}

/* The rule of the frames sent on a change (Contact, Health; nte_node.h MODEL III, HEALTH):
 * a change, else once period_us of sensor time has passed since the last one, or time went
 * back. */
static bool nte_node_due(const bool changed, const uint32_t t, const uint32_t last_t,
                         const uint32_t period_us)
{
    const int32_t since = nte_node_tdiff(t, last_t);
    return changed || (since < 0) || (since >= (int32_t)(period_us / NTE_NODE_TICK_US));
}

/* Model III: the Contact frame after a step at sensor time t (rule in nte_node.h, MODEL III). */
static void nte_node_publish_contact(nte_node_t* self, uint32_t t, const nte_output_t* o)
{
    nte_frames_contact_t c;
    uint8_t data[NTE_FRAMES_LENGTH];
    (void)memset(&c, 0, sizeof c);
    c.contact_state = (o->contact == nte_contact_tissue) ? (uint8_t)NTE_FRAMES_CONTACT_TISSUE
                                                         : (uint8_t)NTE_FRAMES_CONTACT_AIR;
    c.surface_valid = !isnan(o->surface_mm);
    c.active_model = (uint8_t)(self->model - 1);
    c.surface_mm = c.surface_valid ? (float)o->surface_mm : 0.0f;
    c.tare_n = (float)o->tare_n;
    c.layer = (uint8_t)o->layer;
    const bool changed = !self->contact_sent || (c.contact_state != self->contact.contact_state) ||
                         (c.layer != self->contact.layer) ||
                         (c.surface_valid != self->contact.surface_valid) ||
                         (c.surface_mm < self->contact.surface_mm) ||
                         (c.surface_mm > self->contact.surface_mm); /* finite: 0 when invalid */
    if (!nte_node_due(changed, t, self->contact_t, NTE_NODE_CONTACT_PERIOD_US)) {
        return;
    }
    self->contact_sent = true;
    self->contact_t = t;
    self->contact = c;
    if (nte_frames_encode_contact(&c, &self->tx[NTE_NODE_OUT_CONTACT], data) != nte_frames_ok) {
        nte_node_count(self, nte_node_ev_encode_error);
        return;
    }
    nte_node_send(self, nte_frames_kind_contact, NTE_NODE_OUT_CONTACT, data);
}

/* A filter's fault word (nte.h NTE_STATUS_FILTER_BITS) in the Health frame's bits. */
static uint8_t nte_node_filter_flags(uint32_t s)
{
    static const uint32_t from[6] = {NTE_STATUS_GATED,    NTE_STATUS_FILTER_RESET,
                                     NTE_STATUS_DIVERGED, NTE_STATUS_CLIPPED,
                                     NTE_STATUS_FLOORED,  NTE_STATUS_SIGN_UNCERTAIN};
    uint32_t flags = 0u;
    for (uint32_t b = 0u; b < 6u; b++) {
        flags |= ((s & from[b]) != 0u) ? (1u << b) : 0u; /* NTE_FRAMES_FILTER_* order */
    }
    return (uint8_t)flags;
}

/* The Health frame after a step at sensor time t (rule in nte_node.h, HEALTH). */
static void nte_node_publish_health(nte_node_t* self, uint32_t t, const nte_output_t* o)
{
    nte_frames_health_t h;
    uint8_t data[NTE_FRAMES_LENGTH];
    (void)memset(&h, 0, sizeof h);
    h.refined = (o->status & NTE_STATUS_REFINED) != 0u;
    h.converged = (o->status & NTE_STATUS_CONVERGED) != 0u;
    h.refining = (o->status & NTE_STATUS_REFINING) != 0u;
    /* in [0, 1] by construction (nte.h); NaN would fail the encoder: 0 */
    const float c = (float)o->confidence;
    h.confidence = (c > 0.0f) ? ((c < 1.0f) ? c : 1.0f) : 0.0f;
    for (uint32_t i = 0u; i < NTE_FRAMES_FILTERS; i++) {
        h.filter_flags[i] = nte_node_filter_flags(o->filter_status[i]);
    }
    const bool changed =
        !self->health_sent || (h.refined != self->health.refined) ||
        (h.converged != self->health.converged) || (h.refining != self->health.refining) ||
        (h.confidence < self->health.confidence) || (h.confidence > self->health.confidence) ||
        (memcmp(h.filter_flags, self->health.filter_flags, sizeof h.filter_flags) != 0);
    if (!nte_node_due(changed, t, self->health_t, NTE_NODE_HEALTH_PERIOD_US)) {
        return;
    }
    self->health_sent = true;
    self->health_t = t;
    self->health = h;
    if (nte_frames_encode_health(&h, &self->tx[NTE_NODE_OUT_HEALTH], data) != nte_frames_ok) {
        nte_node_count(self, nte_node_ev_encode_error);
        return;
    }
    nte_node_send(self, nte_frames_kind_health, NTE_NODE_OUT_HEALTH, data);
}

/* ------------------------------------------------------------------------------------------ */
/* Estimation                                                                                   */
/* ------------------------------------------------------------------------------------------ */

static const nte_node_depth_t* nte_node_depth_at(const nte_node_t* self, uint32_t age)
{
    /* age 0 = newest */
    const uint32_t n = (uint32_t)NTE_NODE_DEPTH_HISTORY;
    return &self->depth[(self->depth_next + n - 1u - age) % n];
}

static void nte_node_hold(nte_node_t* self)
{
    nte_frames_estimate_t e = self->last;
    e.stale = true;
    e.saturated = false;
    nte_node_count(self, nte_node_ev_stale);
    nte_node_publish_estimate(self, &e);
    nte_node_publish_params(self);
}

/* One estimator step at sensor time f->t; predict-only when commanded, when the sample is
 * flagged faulty, or for a step on the depth stream (f->on_depth; PREDICT-ONLY in
 * nte_node.h). */
static void nte_node_step(nte_node_t* self, const nte_node_force_t* f, float depth_mm,
                          float velocity_mm_s)
{
    nte_sample_t s;
    nte_output_t o;
    nte_frames_estimate_t e;
    /* a step on the depth stream is flagged faulty too (nte_node_depth_predict) */
    const bool po = self->force_cmd_model || f->fault;
    self->counters.predict_on += (po && !self->predicting) ? 1u : 0u;
    self->counters.predict_off += (!po && self->predicting) ? 1u : 0u;
    self->predicting = po;
    (void)nte_set_predict_only(&self->est, po);
    self->have_step = true;
    self->step_t = f->t;
    self->depth_stepped = f->on_depth;
    s.t_us = (int64_t)f->t * (int64_t)NTE_NODE_TICK_US;
    s.depth_mm = (nte_real_t)depth_mm;
    s.velocity_mm_s = (nte_real_t)velocity_mm_s;
    s.force_n = (nte_real_t)f->force_n; /* not read in predict-only */
    const uint64_t t0 = self->port.now_us(self->port.ctx);
    (void)nte_step(&self->est, &s, &o);
    const uint64_t dt = self->port.now_us(self->port.ctx) - t0;
    const uint32_t dt32 = (dt > 0xFFFFFFFFu) ? 0xFFFFFFFFu : (uint32_t)dt;
    if (dt32 > self->step_time_max_us) {
        self->step_time_max_us = dt32;
    }
    self->counters.steps++;
    (void)memset(&e, 0, sizeof e);
    e.force_n = (float)o.force_hat_n;
    e.innovation_n = (float)o.innovation_n;
    e.z = (float)o.z;
    const bool front_end = self->cfg.estimator[self->model - 1].contact.enabled;
    /* with the contact front end the depth is the stage position: its contact state decides */
    e.in_tissue = front_end ? (o.contact == nte_contact_tissue) : (depth_mm > 0.0f);
    e.adapting = !po && !nte_frozen(&self->est);
    e.fault = (o.status & NTE_STATUS_REJECTED) != 0u;
    e.stale = false;
    self->state = e.fault ? nte_node_state_fault : nte_node_state_running;
    self->last = e;
    nte_node_publish_estimate(self, &e);
    nte_node_publish_params(self);
    if (front_end) {
        nte_node_publish_contact(self, f->t, &o);
    }
    nte_node_publish_health(self, f->t, &o);
}

/* Decide the force sample at the head of the queue: 1 = done (stepped or held), 0 = wait. */
static int nte_node_decide(nte_node_t* self, const nte_node_force_t* f)
{
    const int32_t timeout = (int32_t)(self->cfg.depth_timeout_us / NTE_NODE_TICK_US);
    if (self->depth_count == 0u) {
        /* no depth yet: wait until the force samples span more than the timeout */
        if (nte_node_tdiff(self->last_force_t, f->t) > timeout) {
            nte_node_hold(self);
            return 1;
        }
        return 0;
    }
    const nte_node_depth_t* newest = nte_node_depth_at(self, 0u);
    if (nte_node_tdiff(newest->t, f->t) < 0) {
        /* no depth at or after t_f yet: wait unless the depth is too old already, or a later
         * force sample shows that none came within the timeout */
        if ((nte_node_tdiff(f->t, newest->t) > timeout) ||
            (nte_node_tdiff(self->last_force_t, newest->t) > timeout)) {
            /* a depth sample held for a time jump at or before t_f (within the timeout) would
             * decide it: wait for its confirmation while later forces stay within the timeout */
            const nte_node_pending_t* p = &self->pending[NTE_NODE_IN_DEPTH];
            if (p->held && (nte_node_tdiff(f->t, p->t) >= 0) &&
                (nte_node_tdiff(f->t, p->t) <= timeout) &&
                (nte_node_tdiff(self->last_force_t, p->t) <= timeout)) {
                return 0;
            }
            nte_node_hold(self);
            return 1;
        }
        return 0;
    }
    /* newest depth at or before t_f (a) and the one after it (b) */
    const nte_node_depth_t* b = newest;
    for (uint32_t age = 0u; age < self->depth_count; age++) {
        const nte_node_depth_t* a = nte_node_depth_at(self, age);
        if (nte_node_tdiff(a->t, f->t) <= 0) {
            /* stale, or the estimator predicted past this sample on the depth stream (the
             * sensor was lost: that step's depth sample is at or after t_f, so we are here) */
            if ((nte_node_tdiff(f->t, a->t) > timeout) ||
                (self->depth_stepped && (nte_node_tdiff(f->t, self->step_t) <= 0))) {
                nte_node_hold(self);
            } else if (a->t == f->t) {
                nte_node_step(self, f, a->depth_mm, a->velocity_mm_s);
            } else {
                const float w = (float)nte_node_tdiff(f->t, a->t) /
                                (float)nte_node_tdiff(b->t, a->t);
                const float d = a->depth_mm + (w * (b->depth_mm - a->depth_mm));
                const float v = a->velocity_mm_s + (w * (b->velocity_mm_s - a->velocity_mm_s));
                nte_node_step(self, f, d, v);
            }
            return 1;
        }
        b = a;
    }
    /* t_f is older than the whole depth history */
    nte_node_hold(self);
    return 1;
}

/* PREDICT-ONLY (c): at the depth sample at time t, once the forces it decided are done, a
 * sensor lost for longer than the timeout -- depth samples received over more than the timeout
 * since the last force sample, none waiting -- is bridged by a step on the depth stream: an
 * entry of the force queue at t marked on_depth (decided like a force sample at a depth
 * sample's own time, so one call site steps the estimator). */
static bool nte_node_depth_predict(nte_node_t* self, uint32_t t)
{
    const int32_t timeout = (int32_t)(self->cfg.depth_timeout_us / NTE_NODE_TICK_US);
    const int32_t period = (int32_t)(NTE_NODE_PREDICT_PERIOD_US / NTE_NODE_TICK_US);
    if (!self->have_force || (self->force_count > 0u) || !self->depth_since_force ||
        (nte_node_tdiff(t, self->depth_since_force_t) <= timeout) ||
        (self->have_step && (nte_node_tdiff(t, self->step_t) < period))) {
        return false;
    }
    nte_node_force_t* f = &self->force[self->force_head];
    f->t = t;
    f->force_n = 0.0f;
    f->fault = true;
    f->on_depth = true;
    self->force_count = 1u;
    self->counters.predict_depth_steps++;
    return true;
}

static void nte_node_process_forces(nte_node_t* self)
{
    while (self->force_count > 0u) {
        const nte_node_force_t f = self->force[self->force_head];
        if (nte_node_decide(self, &f) == 0) {
            return;
        }
        self->force_head = (self->force_head + 1u) % (uint32_t)NTE_NODE_FORCE_QUEUE;
        self->force_count--;
    }
}

/* ------------------------------------------------------------------------------------------ */
/* Input                                                                                        */
/* ------------------------------------------------------------------------------------------ */

/* Count a failed decode by cause; account a skipped counter on success. */
static bool nte_node_decoded(nte_node_t* self, nte_frames_err_t err, nte_e2e_result_t e2e,
                             uint8_t lost)
{
    if (err == nte_frames_ok) {
        if (e2e == nte_e2e_skipped) {
            nte_node_count(self, nte_node_ev_counter_skipped);
            self->counters.frames_lost += lost;
        }
        return true;
    }
    if (err == nte_frames_err_e2e) {
        switch (e2e) {
        case nte_e2e_err_wrong_length: nte_node_count(self, nte_node_ev_wrong_dlc); break;
        case nte_e2e_err_repeated: nte_node_count(self, nte_node_ev_counter_repeated); break;
        case nte_e2e_err_bad_counter: nte_node_count(self, nte_node_ev_counter_invalid); break;
        default: nte_node_count(self, nte_node_ev_bad_crc); break;
        }
    } else {
        nte_node_count(self, nte_node_ev_out_of_range);
    }
    return false;
}

/* A decoded depth or force sample before its time is checked. */
typedef struct nte_node_in_t {
    uint16_t raw_t;
    float a; /* depth_mm or force_n */
    float b; /* velocity_mm_s (depth); force: 1 = SensorFault set */
} nte_node_in_t;

/* Decode a depth (stream 0) or force (stream 1) frame with the E2E state `rx`. */
static nte_frames_err_t nte_node_decode_sample(uint32_t stream, nte_e2e_rx_t* rx,
                                               const nte_node_frame_t* fr, nte_node_in_t* in,
                                               nte_e2e_result_t* e2e, uint8_t* lost)
{
    nte_frames_err_t err;
    (void)memset(in, 0, sizeof *in);
    if (stream == NTE_NODE_IN_DEPTH) {
        nte_frames_depth_t d;
        err = nte_frames_decode_depth(rx, fr->data, fr->len, &d, e2e, lost);
        if (err == nte_frames_ok) {
            in->raw_t = d.time_ticks;
            in->a = d.depth_mm;
            in->b = d.velocity_mm_s;
        }
    } else {
        nte_frames_force_t f;
        err = nte_frames_decode_force(rx, fr->data, fr->len, &f, e2e, lost);
        if (err == nte_frames_ok) {
            in->raw_t = f.time_ticks;
            in->a = f.force_n;
            in->b = (float)(uint32_t)f.sensor_fault;
        }
    }
    return err;
}

/* Newest accepted time of a stream; false if the stream has none yet. */
static bool nte_node_newest(const nte_node_t* self, uint32_t stream, uint32_t* t)
{
    if (stream == NTE_NODE_IN_DEPTH) {
        if (self->depth_count == 0u) {
            return false;
        }
        *t = nte_node_depth_at(self, 0u)->t;
        return true;
    }
    *t = self->last_force_t;
    return self->have_force;
}

/* SENSOR WATCH (nte_node.h): true when the force reading is not to be read -- pinned at the
 * frame's limit, or repeated NTE_NODE_STUCK_SAMPLES times while the needle moved in tissue;
 * counted. */
static bool nte_node_watch(nte_node_t* self, float force_n)
{
    const float depth = (self->depth_count > 0u) ? nte_node_depth_at(self, 0u)->depth_mm : 0.0f;
    /* exactly the previous reading (decoded from an integer: never NaN) */
    const bool same = !(force_n < self->watch_force) && !(force_n > self->watch_force);
    if ((self->watch_run > 0u) && same) {
        self->watch_run += (self->watch_run < NTE_NODE_STUCK_SAMPLES) ? 1u : 0u;
    } else {
        self->watch_run = 1u;
        self->watch_force = force_n;
        self->watch_depth_mm = depth;
    }
    if (fabsf(force_n) >= NTE_FRAMES_FORCE_MAX_N) {
        nte_node_count(self, nte_node_ev_sensor_saturated);
        return true;
    }
    const float travel_mm = (float)NTE_NODE_STUCK_TRAVEL_UM * 0.001f;
    if (self->last.in_tissue && (self->watch_run >= NTE_NODE_STUCK_SAMPLES) &&
        (fabsf(depth - self->watch_depth_mm) >= travel_mm)) {
        nte_node_count(self, nte_node_ev_sensor_stuck);
        return true;
    }
    return false;
}

/* Store an accepted sample of `stream` at unwrapped time t (later than the stream's newest). */
static void nte_node_store(nte_node_t* self, uint32_t stream, uint32_t t, float a, float b)
{
    if (stream == NTE_NODE_IN_DEPTH) {
        self->depth[self->depth_next].t = t;
        self->depth[self->depth_next].depth_mm = a;
        self->depth[self->depth_next].velocity_mm_s = b;
        self->depth_next = (self->depth_next + 1u) % (uint32_t)NTE_NODE_DEPTH_HISTORY;
        if (self->depth_count < (uint32_t)NTE_NODE_DEPTH_HISTORY) {
            self->depth_count++;
        }
        if (!self->depth_since_force) {
            self->depth_since_force = true;
            self->depth_since_force_t = t;
        }
        self->counters.rx_accepted[stream]++;
        nte_node_process_forces(self);
        if (nte_node_depth_predict(self, t)) {
            nte_node_process_forces(self); /* the step on the depth stream */
        }
        return;
    }
    if (self->force_count >= (uint32_t)NTE_NODE_FORCE_QUEUE) {
        nte_node_count(self, nte_node_ev_queue_overflow);
        return;
    }
    self->have_force = true;
    self->last_force_t = t;
    self->depth_since_force = false;
    const uint32_t k = (self->force_head + self->force_count) % (uint32_t)NTE_NODE_FORCE_QUEUE;
    self->force[k].t = t;
    self->force[k].force_n = a;
    /* a flagged sample's value is not read, nor watched */
    self->force[k].fault = (b > 0.5f) || nte_node_watch(self, a);
    self->force[k].on_depth = false;
    self->force_count++;
    self->counters.rx_accepted[stream]++;
    nte_node_process_forces(self);
}

/* A confirmed jump of the sensor clock to time t: a jump back restarts the stream's timeline
 * (depth: the history is forgotten; force: the samples still waiting are published stale). */
static void nte_node_resync(nte_node_t* self, uint32_t stream, uint32_t t)
{
    uint32_t newest = 0u;
    nte_node_count(self, nte_node_ev_time_resync);
    if (stream == NTE_NODE_IN_DEPTH) {
        /* the depth stream starts afresh: a lost force sensor is judged on its new timeline */
        self->depth_since_force = false;
    }
    if (!nte_node_newest(self, stream, &newest) || (nte_node_tdiff(t, newest) > 0)) {
        return;
    }
    if (stream == NTE_NODE_IN_DEPTH) {
        self->depth_count = 0u;
        self->depth_next = 0u;
    } else {
        while (self->force_count > 0u) {
            nte_node_hold(self);
            self->force_head = (self->force_head + 1u) % (uint32_t)NTE_NODE_FORCE_QUEUE;
            self->force_count--;
        }
        self->have_force = false;
    }
}

/* Commit a decoded frame's E2E state and account its counter skip. */
static void nte_node_commit_e2e(nte_node_t* self, uint32_t stream, const nte_e2e_rx_t* rx,
                                nte_e2e_result_t e2e, uint8_t lost)
{
    self->rx[stream] = *rx;
    (void)nte_node_decoded(self, nte_frames_ok, e2e, lost);
}

/* The frame against a held sample's timeline: its E2E counter checked against the held
 * state `rx_p` (advanced if accepted), its values the ones `in` decoded against the committed
 * timeline with result `err` (E2E result `e2e`) -- unless that timeline refused it as a
 * repeat, the one E2E refusal that depends on a timeline's counter history: then its values
 * were never unpacked, and they are here, against the held state. */
static nte_frames_err_t nte_node_decode_held(uint32_t stream, nte_e2e_rx_t* rx_p,
                                             const nte_node_frame_t* fr, nte_frames_err_t err,
                                             nte_e2e_result_t e2e, nte_node_in_t* in,
                                             nte_e2e_result_t* e2e_p, uint8_t* lost_p)
{
    if ((err == nte_frames_err_e2e) && (e2e == nte_e2e_err_repeated)) {
        return nte_node_decode_sample(stream, rx_p, fr, in, e2e_p, lost_p);
    }
    *e2e_p = nte_e2e_check(rx_p, fr->data, fr->len, lost_p);
    return ((int)*e2e_p >= 0) ? err : nte_frames_err_e2e;
}

/* A depth or force frame.  Time rules (nte_node.h, "TIME"): a sample later than its stream's
 * newest by at most resync_gap is accepted; one not later by at most resync_gap is dropped
 * (time_backwards); any other is held, with its E2E state and clock uncommitted, until the
 * next frame of the stream: one that continues the old timeline drops it (time_jump_dropped),
 * one that continues the held sample confirms it (time_resync, both accepted). */
static void nte_node_on_sample(nte_node_t* self, uint32_t stream, const nte_node_frame_t* fr)
{
    nte_node_pending_t* p = &self->pending[stream];
    const int32_t gap = (int32_t)(self->cfg.resync_gap_us / NTE_NODE_TICK_US);
    nte_e2e_rx_t rx = self->rx[stream];
    nte_e2e_result_t e2e = nte_e2e_ok;
    uint8_t lost = 0u;
    nte_node_in_t in;
    const nte_frames_err_t err = nte_node_decode_sample(stream, &rx, fr, &in, &e2e, &lost);
    nte_frames_clock_t clk = self->clock;
    uint32_t t = 0u;
    uint32_t newest = 0u;
    int32_t d = 0;
    if (err == nte_frames_ok) {
        t = nte_frames_clock_unwrap(&clk, in.raw_t);
        d = nte_node_newest(self, stream, &newest) ? nte_node_tdiff(t, newest) : 1;
        if ((d > 0) && (d <= gap)) {
            if (p->held) {
                p->held = false;
                nte_node_count(self, nte_node_ev_time_jump_dropped);
            }
            nte_node_commit_e2e(self, stream, &rx, e2e, lost);
            self->clock = clk;
            nte_node_store(self, stream, t, in.a, in.b);
            return;
        }
    }
    if (p->held) {
        /* does this frame continue the held one's timeline? */
        nte_e2e_rx_t rx_p = p->rx;
        nte_e2e_result_t e2e_p = nte_e2e_ok;
        uint8_t lost_p = 0u;
        if (nte_node_decode_held(stream, &rx_p, fr, err, e2e, &in, &e2e_p, &lost_p) ==
            nte_frames_ok) {
            nte_frames_clock_t clk_p = p->clock;
            const uint32_t t_p = nte_frames_clock_unwrap(&clk_p, in.raw_t);
            const int32_t d_p = nte_node_tdiff(t_p, p->t);
            if ((d_p > 0) && (d_p <= gap)) {
                const nte_node_pending_t held = *p;
                p->held = false;
                nte_node_resync(self, stream, held.t);
                nte_node_commit_e2e(self, stream, &held.rx, held.e2e, held.lost);
                self->clock = held.clock;
                nte_node_store(self, stream, held.t, held.a, held.b);
                nte_node_commit_e2e(self, stream, &rx_p, e2e_p, lost_p);
                self->clock = clk_p;
                nte_node_store(self, stream, t_p, in.a, in.b);
                return;
            }
        }
    }
    if (err != nte_frames_ok) {
        self->rx[stream] = rx; /* a range error follows a valid E2E check: the counter moved */
        (void)nte_node_decoded(self, err, e2e, lost);
        return;
    }
    if ((d <= 0) && (d >= -gap)) {
        nte_node_commit_e2e(self, stream, &rx, e2e, lost);
        nte_node_count(self, nte_node_ev_time_backwards);
        return;
    }
    /* a jump: hold it (a previously held frame is dropped) */
    if (p->held) {
        nte_node_count(self, nte_node_ev_time_jump_dropped);
    }
    p->held = true;
    p->t = t;
    p->clock = clk;
    p->rx = rx;
    p->e2e = e2e;
    p->lost = lost;
    p->a = in.a;
    p->b = in.b;
}

/* A Command (rules in nte_node.h, "COMMANDS"): applied entirely or not at all. */
static void nte_node_on_command(nte_node_t* self, const nte_node_frame_t* fr)
{
    nte_frames_command_t c;
    nte_e2e_result_t e2e = nte_e2e_ok;
    uint8_t lost = 0u;
    const nte_frames_err_t err = nte_frames_decode_command(&self->rx[NTE_NODE_IN_COMMAND], fr->data,
                                                           fr->len, &c, &e2e, &lost);
    if (!nte_node_decoded(self, err, e2e, lost)) {
        return;
    }
    self->counters.rx_accepted[NTE_NODE_IN_COMMAND]++;
    if (e2e == nte_e2e_skipped) {
        /* not the successor of the last command: a replayed (stale) frame, or one after a
         * lost command -- the sender repeats it with the next counter */
        nte_node_count(self, nte_node_ev_command_stale);
        return;
    }
    const uint64_t now = self->port.now_us(self->port.ctx);
    if (self->have_command && ((now - self->last_command_us) < self->cfg.command_interval_us)) {
        nte_node_count(self, nte_node_ev_command_rate_limited);
        return;
    }
    int32_t model = self->model;
    nte_estimator_t estimator = self->estimator;
    if (c.model_sel != NTE_FRAMES_MODEL_KEEP) {
        model = (int32_t)c.model_sel; /* 1, 2, 3: the frame layer refused the rest */
    }
    if (c.estimator_sel != NTE_FRAMES_ESTIMATOR_KEEP) {
        estimator = (c.estimator_sel == NTE_FRAMES_ESTIMATOR_ROBUST) ? nte_estimator_robust
                                                                     : nte_estimator_bank;
    }
    const bool restart = (model != self->model) || (estimator != self->estimator);
    /* a restart or reset needs the needle out of tissue (the last estimate's InTissue clear) */
    if (((restart || c.reset) && (self->last.in_tissue || self->settings.unapplied)) ||
        (restart && !nte_node_start_model(self, model, estimator))) {
        nte_node_count(self, nte_node_ev_command_refused);
        return;
    }
    if (c.adapt_cmd != NTE_FRAMES_ADAPT_KEEP) {
        /* accepted in tissue; set after a restart the same command asked for, so that it
         * holds the new estimator's parameters (nte.h HELD PARAMETERS) */
        (void)nte_set_frozen(&self->est, c.adapt_cmd == NTE_FRAMES_ADAPT_FREEZE);
    }
    if (c.force_source != NTE_FRAMES_FORCE_SOURCE_KEEP) {
        /* accepted in tissue: a failing sensor is bridged mid-insertion (nte_node.h) */
        self->force_cmd_model = (c.force_source == NTE_FRAMES_FORCE_SOURCE_MODEL);
    }
    if (c.reset) {
        (void)nte_reset(&self->est);
        self->state = nte_node_state_init;
        self->contact_sent = false;
        self->health_sent = false;
        (void)memset(&self->last, 0, sizeof self->last);
        self->last.adapting = true;
    }
    self->have_command = true;
    self->last_command_us = now;
    self->counters.commands_applied++;
}

/* A Setting frame refused: the transfer breaks off (nte_node.h, SETTINGS). */
static void nte_node_setting_refused(nte_node_t* self)
{
    self->settings.open = false;
    nte_node_count(self, nte_node_ev_setting_refused);
}

/* The end of a transfer: the configurations it wrote run, or nothing changes. */
static void nte_node_settings_commit(nte_node_t* self, float announced)
{
    nte_node_settings_t* st = &self->settings;
    st->open = false;
    if ((nte_node_whole(announced, 0, 255) != (int32_t)st->announced) ||
        (st->received != st->announced) ||
        ((st->seen & (1ULL << NTE_FRAMES_SETTING_MODEL)) == 0ULL) || self->last.in_tissue ||
        !nte_node_estimators_ok(&self->cfg) ||
        !nte_node_start_model(self, self->cfg.model, nte_estimator_bank)) {
        nte_node_count(self, nte_node_ev_setting_refused);
        return;
    }
    st->unapplied = false;
    self->counters.settings_applied++;
}

static void nte_node_on_setting(nte_node_t* self, const nte_node_frame_t* fr)
{
    nte_frames_setting_t s;
    nte_e2e_result_t e2e = nte_e2e_ok;
    uint8_t lost = 0u;
    nte_node_settings_t* st = &self->settings;
    const nte_frames_err_t err = nte_frames_decode_setting(&self->rx[NTE_NODE_IN_SETTING], fr->data,
                                                           fr->len, &s, &e2e, &lost);
    if (!nte_node_decoded(self, err, e2e, lost)) {
        st->open = false; /* an item may be missing: the transfer cannot complete */
        return;
    }
    self->counters.rx_accepted[NTE_NODE_IN_SETTING]++;
    if (s.item == (uint8_t)NTE_FRAMES_SETTING_BEGIN) {
        const int32_t n = nte_node_whole(s.value, 1, NTE_FRAMES_SETTING_LAST_VALUE);
        if ((n < 0) || self->last.in_tissue) {
            nte_node_setting_refused(self);
            return;
        }
        nte_node_settings_begin(&self->cfg);
        st->open = true;
        st->unapplied = true;
        st->announced = (uint8_t)n;
        st->received = 0u;
        st->seen = 0ULL;
        return;
    }
    if (!st->open || (e2e == nte_e2e_skipped)) {
        nte_node_setting_refused(self);
        return;
    }
    if (s.item == (uint8_t)NTE_FRAMES_SETTING_COMMIT) {
        nte_node_settings_commit(self, s.value);
        return;
    }
    const uint64_t bit = 1ULL << s.item; /* 1..59: the frame layer refused the rest */
    if (((st->seen & bit) != 0ULL) || (st->received >= st->announced) ||
        (nte_node_setting_apply(&self->cfg, s.item, s.value) != nte_node_ok)) {
        nte_node_setting_refused(self);
        return;
    }
    st->seen |= bit;
    st->received++;
}

static void nte_node_on_frame(nte_node_t* self, const nte_node_frame_t* fr)
{
    if (fr->extended || fr->remote) {
        nte_node_count(self, nte_node_ev_unknown_id);
        return;
    }
    if (fr->id == nte_node_input_id(self, NTE_NODE_IN_DEPTH)) {
        nte_node_on_sample(self, NTE_NODE_IN_DEPTH, fr);
    } else if (fr->id == nte_node_input_id(self, NTE_NODE_IN_FORCE)) {
        nte_node_on_sample(self, NTE_NODE_IN_FORCE, fr);
    } else if (fr->id == nte_node_input_id(self, NTE_NODE_IN_COMMAND)) {
        nte_node_on_command(self, fr);
    } else if (fr->id == nte_node_input_id(self, NTE_NODE_IN_SETTING)) {
        nte_node_on_setting(self, fr);
    } else {
        nte_node_count(self, nte_node_ev_unknown_id);
    }
}

int32_t nte_node_poll(nte_node_t* self)
{
    int32_t n = 0;
    if (self == NULL) {
        return (int32_t)nte_node_err_null;
    }
    while ((uint32_t)n < self->cfg.rx_budget) {
        nte_node_frame_t fr;
        (void)memset(&fr, 0, sizeof fr);
        const int r = self->port.receive(self->port.ctx, &fr);
        if (r < 0) {
            nte_node_count(self, nte_node_ev_receive_error);
            break;
        }
        if (r == 0) {
            break;
        }
        n++;
        nte_node_on_frame(self, &fr);
    }
    const uint64_t now = self->port.now_us(self->port.ctx);
    if (now >= self->next_heartbeat_us) {
        nte_node_heartbeat(self, now);
        self->next_heartbeat_us += self->cfg.heartbeat_period_us;
        if (self->next_heartbeat_us <= now) {
            self->next_heartbeat_us = now + self->cfg.heartbeat_period_us;
        }
    }
    return n;
}
