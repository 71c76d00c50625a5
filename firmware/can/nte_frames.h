/*
 * nte_frames.h -- the estimator node's CAN frames in physical units (mm, N, s).
 *
 * What it does: wraps the C code that cantools generates from firmware/can/nte.dbc
 * (firmware/can/generated/nte_can.{h,c}, never edited by hand) with
 *   - unit conversion: struct fields are floats in mm, mm/s, N, s; the bit layout, scales and
 *     offsets live only in the DBC;
 *   - range checks: an input outside its DBC range is an error (nte_frames_err_range), never
 *     silently clamped; outputs of the node that may legitimately exceed their frame's range
 *     (estimate, heartbeat) are clamped and flagged as documented per function;
 *   - end-to-end protection: every encode protects the frame with nte_e2e_protect, every decode
 *     checks it with nte_e2e_check before anything is unpacked.
 * It counts nothing itself: the caller decides what a failed decode means and keeps its own
 * error counters (they go out in the heartbeat).
 *
 * CAN ids: id = base + offset, base configurable (default NTE_FRAMES_BASE_ID_DEFAULT = 0x200,
 * the ids written in the DBC); offsets: depth 0x00, force 0x01, command 0x02, setting 0x03,
 * estimate 0x10, params 0x11, heartbeat 0x12, contact 0x13, health 0x14. Standard 11-bit ids,
 * so base <= 0x7FF - 0x14 = 0x7EB.
 * The DBC attribute
 * NteIdOffset holds the same offsets and NteE2EDataId the data ids below; a test checks that
 * this header and the DBC agree.
 *
 * Timestamps: depth and force carry the sender's clock in 100 us ticks, 16 bits, wrapping every
 * 6.5536 s; nte_frames_clock_unwrap turns them into a 32-bit count (wraps after 4.97 days).
 *
 * Integration: nte_frames.c, nte_e2e.c and generated/nte_can.c; C99, needs <math.h> (powf,
 * for a received parameter standard deviation only; link -lm). No dynamic memory, no globals,
 * not thread-safe (the E2E states passed in belong to the caller).
 * Costs: each encode/decode is a few dozen integer operations plus the E2E CRC (~640 simple
 * operations for 8 bytes); parameter frames add a 20-operation log10 (encode) or one powf
 * (decode).
 */
#ifndef NTE_FRAMES_H
#define NTE_FRAMES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "nte_e2e.h"

#ifdef __cplusplus
extern "C" {
#endif

#define NTE_FRAMES_LENGTH 8u              /**< Every frame is a classic 8-byte frame. */
#define NTE_FRAMES_BASE_ID_DEFAULT 0x200u /**< Base id the DBC is written for. */
#define NTE_FRAMES_MAX_STD_ID 0x7FFu

#define NTE_FRAMES_OFFSET_DEPTH 0x00u
#define NTE_FRAMES_OFFSET_FORCE 0x01u
#define NTE_FRAMES_OFFSET_COMMAND 0x02u
#define NTE_FRAMES_OFFSET_SETTING 0x03u
#define NTE_FRAMES_OFFSET_ESTIMATE 0x10u
#define NTE_FRAMES_OFFSET_PARAMS 0x11u
#define NTE_FRAMES_OFFSET_HEARTBEAT 0x12u
#define NTE_FRAMES_OFFSET_CONTACT 0x13u
#define NTE_FRAMES_OFFSET_HEALTH 0x14u

#define NTE_FRAMES_DATA_ID_DEPTH 0x4E00u
#define NTE_FRAMES_DATA_ID_FORCE 0x4E01u
#define NTE_FRAMES_DATA_ID_COMMAND 0x4E02u
#define NTE_FRAMES_DATA_ID_SETTING 0x4E03u
#define NTE_FRAMES_DATA_ID_ESTIMATE 0x4E10u
#define NTE_FRAMES_DATA_ID_PARAMS 0x4E11u
#define NTE_FRAMES_DATA_ID_HEARTBEAT 0x4E12u
#define NTE_FRAMES_DATA_ID_CONTACT 0x4E13u
#define NTE_FRAMES_DATA_ID_HEALTH 0x4E14u

/** Sender clock tick of SensorTime, s. */
#define NTE_FRAMES_TICK_S 1.0e-4f

/* Physical ranges (the DBC's). */
#define NTE_FRAMES_DEPTH_MAX_MM 500.0f
#define NTE_FRAMES_VELOCITY_MAX_MM_S 500.0f
#define NTE_FRAMES_FORCE_MAX_N 50.0f
#define NTE_FRAMES_INNOVATION_MIN_N (-0.8192f)
#define NTE_FRAMES_INNOVATION_MAX_N 0.8188f
#define NTE_FRAMES_Z_MIN (-8.192f)
#define NTE_FRAMES_Z_MAX 8.1915f
#define NTE_FRAMES_UPTIME_WRAP_S 52428.8f /**< 19-bit Uptime at 0.1 s (14.56 h) */
/** Largest uptime an encoder takes, s: 2^24 wraps (27 000 years). */
#define NTE_FRAMES_UPTIME_MAX_S (16777216.0f * NTE_FRAMES_UPTIME_WRAP_S)
#define NTE_FRAMES_SURFACE_MAX_MM 500.0f /**< |Contact.Surface|, stage position mm */
#define NTE_FRAMES_STEP_TIME_MAX_S 0.00819f
/** log10(std) is sent in 0.001 steps in [-32.767, 32.767]; -32.768 means std = 0 (fixed). */
#define NTE_FRAMES_STD_LOG10_MIN (-32.767f)
#define NTE_FRAMES_STD_LOG10_MAX 32.767f

/** Result of every function here: 0 success, negative error. */
typedef enum {
    nte_frames_ok = 0,
    nte_frames_err_null = -1,       /**< A pointer argument was NULL. */
    nte_frames_err_e2e = -2,        /**< E2E check failed (length, CRC, repeated or invalid
                                         counter): see the nte_e2e_result_t reported. */
    nte_frames_err_range = -3,      /**< A value is outside its range. */
    nte_frames_err_not_finite = -4, /**< A float is NaN or infinite. */
    nte_frames_err_selector = -5,   /**< An enumerated field (command selector, parameter
                                         index, node state) has an undefined value. */
    nte_frames_err_unknown_id = -6, /**< The CAN id is none of the node's. */
    nte_frames_err_bad_config = -7, /**< Base id too large, or bad kind. */
    nte_frames_err_wrong_kind = -8  /**< The E2E state passed in belongs to another message. */
} nte_frames_err_t;

/** The eight messages (setting, the last added, keeps the others' numbers). */
typedef enum {
    nte_frames_kind_depth = 0,
    nte_frames_kind_force = 1,
    nte_frames_kind_command = 2,
    nte_frames_kind_estimate = 3,
    nte_frames_kind_params = 4,
    nte_frames_kind_heartbeat = 5,
    nte_frames_kind_contact = 6,
    nte_frames_kind_setting = 7,
    nte_frames_kind_health = 8,
    nte_frames_kind_count = 9
} nte_frames_kind_t;

/** Command selectors (0 = keep the current setting). */
enum {
    NTE_FRAMES_MODEL_KEEP = 0,
    NTE_FRAMES_MODEL_I = 1,
    NTE_FRAMES_MODEL_II = 2,
    NTE_FRAMES_MODEL_III = 3
};
enum {
    NTE_FRAMES_ESTIMATOR_KEEP = 0,
    NTE_FRAMES_ESTIMATOR_BANK = 1,
    NTE_FRAMES_ESTIMATOR_ROBUST = 2
};
enum { NTE_FRAMES_ADAPT_KEEP = 0, NTE_FRAMES_ADAPT_FREEZE = 1, NTE_FRAMES_ADAPT_RESUME = 2 };
/** Command.ForceSource: 1 = identify from the force sensor, 2 = predict from the model alone
 *  (predict-only). */
enum {
    NTE_FRAMES_FORCE_SOURCE_KEEP = 0,
    NTE_FRAMES_FORCE_SOURCE_SENSOR = 1,
    NTE_FRAMES_FORCE_SOURCE_MODEL = 2
};
/** Parameter indices of the Params frame (nte.h nte_param_id_t order).  Models I and II
 *  publish 0..6 (NTE_FRAMES_PARAM_COUNT_MODEL_II), Model III 0..9 (NTE_FRAMES_PARAM_COUNT). */
enum {
    NTE_FRAMES_PARAM_SIGMA0 = 0,
    NTE_FRAMES_PARAM_SIGMA1 = 1,
    NTE_FRAMES_PARAM_SIGMA2 = 2,
    NTE_FRAMES_PARAM_F1 = 3,
    NTE_FRAMES_PARAM_F2 = 4,
    NTE_FRAMES_PARAM_ALPHA = 5,
    NTE_FRAMES_PARAM_BETA = 6,
    NTE_FRAMES_PARAM_G_FAST = 7,
    NTE_FRAMES_PARAM_G_SLOW = 8,
    NTE_FRAMES_PARAM_DELTA = 9,
    NTE_FRAMES_PARAM_COUNT_MODEL_II = 7,
    NTE_FRAMES_PARAM_COUNT = 10
};
/** Items of the Setting frame (the DBC's Item; a configuration sent item by item, see
 *  nte_node.h SETTINGS).  Items 2..11 are the nominal of parameter item - 2 (nte.h
 *  nte_param_id_t; 11, delta, is Model III's presliding_mm); items 20..59 the layer sets:
 *  NTE_FRAMES_SETTING_LAYER0 + NTE_FRAMES_SETTING_LAYER_FIELDS k + j, set k, field j = 0 its
 *  start (mm below the surface), 1 + nte_layer_value_t its values. */
enum {
    NTE_FRAMES_SETTING_BEGIN = 0,
    NTE_FRAMES_SETTING_MODEL = 1,
    NTE_FRAMES_SETTING_PARAM0 = 2,
    NTE_FRAMES_SETTING_R_N2 = 12,
    NTE_FRAMES_SETTING_SURFACE_MM = 13,
    NTE_FRAMES_SETTING_TAU_FAST_S = 14,
    NTE_FRAMES_SETTING_TAU_SLOW_S = 15,
    NTE_FRAMES_SETTING_RELAX_BRANCHES = 16,
    NTE_FRAMES_SETTING_RELAXATION = 17,
    NTE_FRAMES_SETTING_DIRECTION_MEMORY = 18,
    NTE_FRAMES_SETTING_LAYER_SETS = 19,
    NTE_FRAMES_SETTING_LAYER0 = 20,
    NTE_FRAMES_SETTING_LAYER_FIELDS = 5,
    NTE_FRAMES_SETTING_LAYER_SETS_MAX = 8,
    NTE_FRAMES_SETTING_LAST_VALUE = 59,
    NTE_FRAMES_SETTING_COMMIT = 255
};
/** Contact states of the Contact frame. */
enum { NTE_FRAMES_CONTACT_AIR = 0, NTE_FRAMES_CONTACT_TISSUE = 1 };
/** Heartbeat node states. */
enum { NTE_FRAMES_STATE_INIT = 0, NTE_FRAMES_STATE_RUNNING = 1, NTE_FRAMES_STATE_FAULT = 2 };

/** Depth sample (input). */
typedef struct {
    float depth_mm;      /**< 0 .. 500 mm, sent with 0.001 mm resolution. */
    float velocity_mm_s; /**< -500 .. 500 mm/s, 0.01 mm/s resolution. */
    uint16_t time_ticks; /**< Sender clock, 100 us ticks, wrapping. */
} nte_frames_depth_t;

/** Force sample (input). */
typedef struct {
    float force_n;       /**< -50 .. 50 N, 0.1 mN resolution; with sensor_fault any value
                              (a non-finite or out-of-range one is sent as 0; a received
                              raw value is not range-checked: up to +-52.4288 N). */
    uint16_t time_ticks; /**< Same clock as the depth samples. */
    bool sensor_fault;   /**< The sensor's driver flags the sample bad (SensorFault). */
} nte_frames_force_t;

/** Command (input). */
typedef struct {
    bool reset;            /**< Reset the estimator after applying the selections. */
    uint8_t model_sel;     /**< NTE_FRAMES_MODEL_*. */
    uint8_t estimator_sel; /**< NTE_FRAMES_ESTIMATOR_*. */
    uint8_t adapt_cmd;     /**< NTE_FRAMES_ADAPT_*. */
    uint8_t force_source;  /**< NTE_FRAMES_FORCE_SOURCE_*. */
} nte_frames_command_t;

/** One configuration item (input, on event). */
typedef struct {
    uint8_t item; /**< NTE_FRAMES_SETTING_*: 0..59 or 255 (an error otherwise). */
    float value;  /**< Any finite float32 (an error otherwise), in the item's unit. */
} nte_frames_setting_t;

/** Estimate (output, one per force sample). */
typedef struct {
    float force_n;      /**< Estimated force, N; clamped to +-50 N, 0.1 mN resolution. */
    float innovation_n; /**< Measured - predicted force, N; clamped to -0.8192..0.8188 N,
                             0.4 mN resolution. */
    float z;            /**< Internal state z; clamped to -8.192..8.1915, 5e-4 resolution. */
    bool in_tissue;     /**< Depth > 0. */
    bool adapting;      /**< Parameter adaptation running; false: held (AdaptCmd freeze), or
                             predict-only, the force then the model's alone. */
    bool saturated;     /**< Encode: ORed with "a value was clamped"; decode: as received. */
    bool fault;         /**< The estimator rejected its update. */
    bool stale;         /**< No recent depth: the estimate is held, not updated. */
} nte_frames_estimate_t;

/** One identified parameter and its standard deviation (output, multiplexed by index). */
typedef struct {
    uint8_t index; /**< NTE_FRAMES_PARAM_*. */
    float value;   /**< Any finite float32, in the parameter's unit (see the DBC). */
    float std;     /**< >= 0; 0 = fixed. Sent as log10 with 0.001 resolution (0.23 % relative),
                        clamped to 10^-32.767 .. 10^32.767. */
} nte_frames_param_t;

/** Heartbeat (output). */
typedef struct {
    uint8_t node_state;       /**< NTE_FRAMES_STATE_*. */
    uint8_t active_model;     /**< 0 = Model I, 1 = Model II, 2 = Model III. */
    uint8_t active_estimator; /**< 0 = bank, 1 = robust. */
    float uptime_s;           /**< 0 .. NTE_FRAMES_UPTIME_MAX_S s; sent modulo 52428.8 s
                                   with 0.1 s resolution. */
    uint32_t e2e_errors;      /**< Counter of frames rejected by E2E; sent modulo 256. */
    uint32_t range_errors;    /**< Counter of frames rejected by range checks; modulo 256. */
    float step_time_s;        /**< >= 0 s, longest step since the last heartbeat; clamped to
                                   8.19 ms, 2 us resolution. */
} nte_frames_heartbeat_t;

/** Model III's contact front end (output). */
typedef struct {
    uint8_t contact_state; /**< NTE_FRAMES_CONTACT_AIR or _TISSUE. */
    bool surface_valid;    /**< A surface is known; false: surface_mm is ignored (sent as 0). */
    uint8_t active_model;  /**< 0 = Model I, 1 = Model II, 2 = Model III. */
    float surface_mm;      /**< Surface, stage position mm, -500..500 (an error beyond), 1 um
                                resolution; must be finite when surface_valid. */
    float tare_n;          /**< Tare, N; clamped to +-50 N, 0.1 mN resolution. */
    uint8_t layer;         /**< Model III's layer index, 0..NTE_FRAMES_LAYER_MAX (an error
                                beyond; the estimator's is 0..NTE_LAYER_MAX - 1). */
} nte_frames_contact_t;

/** Largest layer index the Contact frame carries (its 3-bit Layer signal). */
#define NTE_FRAMES_LAYER_MAX 7u

/** Bits of a filter's fault word in the Health frame (Filter<i>Flags). */
enum {
    NTE_FRAMES_FILTER_GATED = 1u << 0,          /**< the update was refused by the gate */
    NTE_FRAMES_FILTER_RESET = 1u << 1,          /**< the filter restarted (covariance lost) */
    NTE_FRAMES_FILTER_DIVERGED = 1u << 2,       /**< its prediction left the physical range */
    NTE_FRAMES_FILTER_CLIPPED = 1u << 3,        /**< a parameter is at its clip */
    NTE_FRAMES_FILTER_FLOORED = 1u << 4,        /**< a variance was raised to its floor */
    NTE_FRAMES_FILTER_SIGN_UNCERTAIN = 1u << 5, /**< R inflated for the smooth sign */
    NTE_FRAMES_FILTER_FLAGS = (1u << 6) - 1u    /**< every defined bit */
};
/** Filters of the bank, one fault word each. */
#define NTE_FRAMES_FILTERS 3u

/** The estimator's health (output): the robust refinement and the filters' fault words. */
typedef struct {
    bool refined;     /**< The robust estimator adopted a refinement at this step. */
    bool converged;   /**< Its last refinement agreed with the data. */
    float confidence; /**< 0 .. 1 (an error beyond or non-finite), 1e-4 resolution. */
    uint8_t filter_flags[NTE_FRAMES_FILTERS]; /**< NTE_FRAMES_FILTER_* bits (an error beyond
                                                   NTE_FRAMES_FILTER_FLAGS). */
    bool refining;                            /**< A slice of its refinement ran at this step. */
} nte_frames_health_t;

/** Sender clock unwrapper: use ONE for all streams stamped by the same clock. */
typedef struct {
    uint32_t ticks;    /**< Unwrapped count of the last sample. */
    uint16_t last_raw; /**< Raw 16-bit value of the last sample. */
    bool started;
} nte_frames_clock_t;

/** Offset of a message's id from the base; returns nte_frames_err_bad_config for a bad kind. */
nte_frames_err_t nte_frames_offset(nte_frames_kind_t kind, uint32_t* offset);
/** E2E data id of a message. */
nte_frames_err_t nte_frames_data_id(nte_frames_kind_t kind, uint16_t* data_id);
/** CAN id of a message for a base id; nte_frames_err_bad_config if it exceeds 0x7FF. */
nte_frames_err_t nte_frames_can_id(uint32_t base, nte_frames_kind_t kind, uint32_t* can_id);
/** Which message a received CAN id is; nte_frames_err_unknown_id if none. */
nte_frames_err_t nte_frames_kind_of(uint32_t base, uint32_t can_id, nte_frames_kind_t* kind);

/** Initialise the E2E sender / receiver state of one message (data id and length 8). */
nte_frames_err_t nte_frames_tx_init(nte_e2e_tx_t* e2e, nte_frames_kind_t kind);
nte_frames_err_t nte_frames_rx_init(nte_e2e_rx_t* e2e, nte_frames_kind_t kind);

/* Encoders: validate, pack into out[8] (all 8 bytes written), protect with `e2e` (whose counter
 * advances only on success). On error `out` is unspecified and `e2e` unchanged. */
nte_frames_err_t nte_frames_encode_depth(const nte_frames_depth_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out);
nte_frames_err_t nte_frames_encode_force(const nte_frames_force_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out);
nte_frames_err_t nte_frames_encode_command(const nte_frames_command_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out);
nte_frames_err_t nte_frames_encode_setting(const nte_frames_setting_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out);
/** Non-finite values are an error (send fault = true with finite values instead). */
nte_frames_err_t nte_frames_encode_estimate(const nte_frames_estimate_t* in, nte_e2e_tx_t* e2e,
                                            uint8_t* out);
nte_frames_err_t nte_frames_encode_param(const nte_frames_param_t* in, nte_e2e_tx_t* e2e,
                                         uint8_t* out);
nte_frames_err_t nte_frames_encode_heartbeat(const nte_frames_heartbeat_t* in, nte_e2e_tx_t* e2e,
                                             uint8_t* out);
/** Non-finite tare (or surface, when valid) and |surface| > 500 mm are errors. */
nte_frames_err_t nte_frames_encode_contact(const nte_frames_contact_t* in, nte_e2e_tx_t* e2e,
                                           uint8_t* out);
/** Confidence outside 0..1 or non-finite, and undefined filter bits, are errors. */
nte_frames_err_t nte_frames_encode_health(const nte_frames_health_t* in, nte_e2e_tx_t* e2e,
                                          uint8_t* out);

/* Decoders: E2E check with `e2e` (its result goes to *e2e_result if that is not NULL; a skipped
 * counter is accepted, the number lost is in *lost if not NULL), then unpack and range check.
 * On error *out is unspecified. An E2E failure leaves `e2e` unchanged; a frame that passes E2E
 * but fails a range check has advanced it (it was received intact). */
nte_frames_err_t nte_frames_decode_depth(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_depth_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost);
nte_frames_err_t nte_frames_decode_force(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_force_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost);
nte_frames_err_t nte_frames_decode_command(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_command_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost);
nte_frames_err_t nte_frames_decode_setting(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_setting_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost);
nte_frames_err_t nte_frames_decode_estimate(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                            nte_frames_estimate_t* out,
                                            nte_e2e_result_t* e2e_result, uint8_t* lost);
nte_frames_err_t nte_frames_decode_param(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                         nte_frames_param_t* out, nte_e2e_result_t* e2e_result,
                                         uint8_t* lost);
nte_frames_err_t nte_frames_decode_heartbeat(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                             nte_frames_heartbeat_t* out,
                                             nte_e2e_result_t* e2e_result, uint8_t* lost);
nte_frames_err_t nte_frames_decode_contact(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                           nte_frames_contact_t* out, nte_e2e_result_t* e2e_result,
                                           uint8_t* lost);
nte_frames_err_t nte_frames_decode_health(nte_e2e_rx_t* e2e, const uint8_t* data, size_t length,
                                          nte_frames_health_t* out, nte_e2e_result_t* e2e_result,
                                          uint8_t* lost);

/** Forget the clock history. */
void nte_frames_clock_reset(nte_frames_clock_t* self);
/** Unwrap a 16-bit SensorTime into a 32-bit tick count by the signed 16-bit difference to the
 *  previous sample (so samples may arrive slightly out of order, but two consecutive calls must
 *  be less than 32768 ticks = 3.2768 s apart). The first sample maps to raw + 65536 so that an
 *  older sample still maps to a non-negative count; only differences are meaningful:
 *  dt_s = (float)(b - a) * NTE_FRAMES_TICK_S. */
uint32_t nte_frames_clock_unwrap(nte_frames_clock_t* self, uint16_t raw);

#ifdef __cplusplus
}
#endif

#endif /* NTE_FRAMES_H */
