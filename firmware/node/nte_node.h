/*
 * nte_node.h -- the needle-tissue force estimator as a CAN node: the platform-free node loop.
 *
 * WHAT IT DOES
 *   Receives the Depth, Force and Command frames of firmware/can/nte.dbc, checks them (length,
 *   E2E CRC and alive counter, DBC ranges, sensor timestamps), and runs one estimator step
 *   (firmware/include/nte.h) per accepted Force frame, with depth and velocity interpolated
 *   linearly to the force sample's own timestamp.  After every step it sends one Estimate frame
 *   and `params_per_step` Params frames (rotating through the multiplexer indices: 0..6 in
 *   Models I and II, 0..9 in Model III, whose 7, 8 and 9 are g_fast, g_slow and delta); every
 *   `heartbeat_period_us` of the port's clock it sends a Heartbeat.  In Model III it also sends
 *   a Contact frame (see MODEL III).  It counts every dropped or rejected frame by cause
 *   (nte_node_event_t).
 *
 * MODEL III (model 3: nte.h, Model II + direction memory + relaxation; the contact front end on)
 *   The Depth frames carry the STAGE position (mm, 0..500 as the DBC allows) and the Force
 *   frames the raw force: the library's contact front end learns the tare in the air and finds
 *   the surface from the force onset (nte.h, THE CONTACT FRONT END; estimator[2].contact).
 *   The Estimate's InTissue bit is then the front end's contact state (not depth > 0).  After
 *   an estimator step (not after a stale hold) a Contact frame is sent when its contact state,
 *   layer index (nte.h, THE LAYER INDEX), surface validity or surface differs from the last
 *   Contact frame sent, or when the force
 *   sample is at least NTE_NODE_CONTACT_PERIOD_US of sensor time after the last one (10 Hz):
 *   the decision uses the frames' SensorTime only, so a replay is deterministic.  Heartbeat
 *   ActiveModel 2.  Models I and II send no Contact frame and cycle Params 0..6 as before.
 *
 * HEALTH (every model)
 *   After an estimator step (not after a stale hold) a Health frame is sent when its content
 *   differs from the last Health frame sent, or when the force sample is at least
 *   NTE_NODE_HEALTH_PERIOD_US of sensor time after the last one (10 Hz), by SensorTime only as
 *   for the Contact frame.  It carries the robust estimator's Refined and Converged bits and
 *   confidence (0 for the bank), and the fault word of each filter of the bank at that step
 *   (nte.h nte_output_t.filter_status, mapped to the NTE_FRAMES_FILTER_* bits): a gate, a
 *   reset, a diverged prior, a clip, a floor, an inflated R, per filter.  A step whose words
 *   are those of the previous step sends nothing new, so a flag that stays up costs one frame
 *   per 100 ms; every change of any filter's word is on the bus at the step it happened.
 *
 * TIME
 *   Results depend only on the frames' SensorTime stamps (unwrapped, one clock for both streams),
 *   never on arrival times: a force sample at t_f is processed once a depth sample with
 *   t >= t_f has been received (interpolation between the newest depth at or before t_f and the
 *   next one), or declared STALE when the newest depth at or before t_f is older than
 *   `depth_timeout_us`, or when a later force sample shows that no bracketing depth sample came
 *   within the timeout.  A stale force sample does not step the estimator: the Estimate frame
 *   repeats the last estimate with the Stale bit set.  This is deterministic provided the two
 *   streams are not skewed on the bus by more than the timeout.  The port clock is used only for
 *   the heartbeat period, the uptime and the step-time measurement.
 *
 * TIME JUMPS (resynchronisation)
 *   A sample later than its stream's newest by at most `resync_gap_us` is accepted; one at most
 *   `resync_gap_us` older (a duplicate or a reordered frame) is dropped as time_backwards.  A
 *   sample further away, forward or backward, is a time jump and is not trusted alone: it is held,
 *   its E2E counter state and the clock left uncommitted, until the next frame of its stream.  If
 *   that frame continues the old timeline, the held one is dropped (time_jump_dropped); if it
 *   continues the held one (later by at most `resync_gap_us`), the jump is confirmed
 *   (time_resync) and both are accepted.  A jump back restarts the stream: the depth history is
 *   forgotten, the force samples waiting for depth are published stale.  Consequences: a single
 *   forged or corrupted frame that passes the CRC with a time jump costs that frame only (the
 *   next genuine frame is checked against the counter state before it); a real clock jump, or
 *   the first sample after a gap longer than `resync_gap_us`, costs one sample period of latency
 *   and no sample.  A frame within `resync_gap_us` of the stream is indistinguishable from a
 *   genuine one (E2E is integrity, not authentication): accepted, it can cost the genuine
 *   samples of the next `resync_gap_us`.  A last sample after a jump with nothing behind it
 *   stays held.
 *
 * COMMANDS (the Command frame)
 *   A command is applied entirely or not at all.  ModelSel I/II/III and EstimatorSel
 *   bank/robust re-initialise the estimator with that model and estimator (the configured
 *   nominal values; the robust estimator refines after each insertion: nte.h; Model III with
 *   the robust estimator is refused, command_refused, as nte_init refuses it); Reset restarts
 *   the running one; ForceSource 2 / 1 switches predict-only on / off (see PREDICT-ONLY).
 *   "Out of tissue" below is the last Estimate's InTissue bit: in Model III
 *   the contact front end's state (see MODEL III).
 *   Rules: (1) the E2E counter must be the successor of the last command's: a replayed frame
 *   (stale counter) or one after a lost command is ignored (command_stale; the sender repeats
 *   with its next counter); a repeated counter fails E2E already.  (2) At most one command per
 *   `command_interval_us` of the port clock (command_rate_limited).  (3) A model or estimator
 *   change and a reset take effect only while the needle is out of tissue (the last estimate's
 *   InTissue bit clear, or no estimate yet): during an insertion they would throw away the
 *   identification in progress; refused (command_refused).  (4) AdaptCmd freeze holds the
 *   parameters (nte_set_frozen, nte.h HELD PARAMETERS: the force is still read and z follows
 *   it; Estimate.Adapting 0) and resume lets them adapt again; both are accepted in tissue.
 *   The freeze outlives a Reset; a model or estimator change starts adapting.  E2E
 *   protects integrity (corruption, loss, repetition), not authenticity: any sender on the bus
 *   can compute the CRC and follow the counter.  Protect the bus, or add a MAC, if that matters.
 *
 * SETTINGS (a configuration sent over the bus: the Setting frame, firmware/can/nte.dbc)
 *   A board has no file system: what `nte-node --config FILE` reads from a file, a sender
 *   (`nte-bench settings FILE`) sends as Setting frames, one item per frame (nte_frames.h
 *   NTE_FRAMES_SETTING_*): BEGIN with the number of value items, the value items (model, the
 *   nominal parameters, r_n2, a known surface, Model III's constants and layer sets), COMMIT
 *   with the same number.  BEGIN and COMMIT are taken only while the needle is out of tissue
 *   (as a model change).  BEGIN sets the three estimator configurations to their defaults
 *   (nte_node_settings_begin) and each value item is written into them at once
 *   (nte_node_setting_apply: the same function nte-node --config uses, so a file and its
 *   transfer configure the node alike, bit for bit); the running estimator keeps its own copy
 *   and is not touched.  COMMIT checks the configurations (nte_config_check) and restarts the
 *   estimator (the bank) with the transfer's model: counted in settings_applied.
 *   The transfer breaks off, counted as setting_refused, at: a value item outside a transfer,
 *   an item given twice, more items than announced, a value the item cannot take (a model
 *   not 1..3, a count or switch that is not a whole number in range, a layer set beyond
 *   NTE_LAYER_SETS_MAX), a lost Setting frame (its E2E counter skipped; a frame that
 *   fails E2E is counted by its cause and breaks the transfer off too), BEGIN or COMMIT in tissue, a COMMIT whose number differs from the
 *   announced and received ones or that misses the model, a configuration nte_config_check
 *   refuses.  Nothing that runs changes then, but the configurations hold a partial
 *   transfer: until a transfer is applied, model changes and resets are refused
 *   (command_refused) so that the partial one never runs.  Send the transfer again.
 *   No rate limit (a transfer is some forty frames), no port clock: a replay is
 *   deterministic.
 *
 * PREDICT-ONLY (the model alone: a force sensor that fails or is switched off; nte.h THE
 * PREDICT-ONLY MODE)
 *   The node runs the estimator in predict-only mode -- the force is not read, the parameters
 *   identified so far are kept, z and the memories go on with the depth -- in four cases:
 *   (a) commanded: Command.ForceSource 2 (the model) until ForceSource 1 (the sensor); the
 *       command follows the COMMANDS rules (counter, rate limit) and is accepted in tissue, a
 *       failing sensor having to be bridged mid-insertion; it outlives model changes and resets;
 *   (b) a force sample whose SensorFault bit is set (its driver knows it is bad; its value is not
 *       range-checked or read): that sample is processed in predict-only, in its place in the
 *       force stream (interpolated depth, stale rule, one Estimate), so a stretch of flagged
 *       frames is a stretch of predictions and the first unflagged frame identifies again;
 *   (c) a lost sensor: Depth samples received over more than `depth_timeout_us` (sensor time,
 *       from the first depth sample after the newest force sample to this one), no force
 *       sample waiting, once a force sample was seen (a pause of both streams, or a confirmed
 *       jump of the depth clock, starts that span afresh).  The force
 *       samples then carry no schedule, so the node steps on the Depth stream: at such a depth
 *       sample, if it is at least NTE_NODE_PREDICT_PERIOD_US (sensor time) after the last step,
 *       one predict-only step at that sample's own time, depth and velocity, then the Estimate
 *       and Params (and Model III's Contact) as after any step.  A force sample that comes back
 *       is processed as usual if it is later than that last step, else held (Stale, counted
 *       stale): the estimator's time line cannot go back.  After a loss longer than
 *       `resync_gap_us` the first returning force sample is a time jump, confirmed by the next
 *       (TIME JUMPS): the depth stream steps on meanwhile, and that first one is published
 *       stale.
 *   (d) a reading the node does not believe (SENSOR WATCH below): like (b), that sample alone.
 *   In every case the Estimate's Adapting bit is 0 (1 otherwise) and Innovation 0.  Every change
 *   of the mode between two steps is counted (nte_node_counters_t predict_on, predict_off;
 *   predict_depth_steps counts the steps of case (c)).  Switching back resumes identification
 *   from the state reached (nte.h).
 *
 * SENSOR WATCH (a force sensor that lies without saying so)
 *   A sensor stuck at one value, or pinned at a limit, still sends well-formed frames, and an
 *   estimator fed them learns the fault: a stuck force for 1 s left the error after it at 16
 *   times the fault-free run's, a saturated one at 13 000 times (the fault table, README).
 *   The node reads a force sample (without SensorFault) as PREDICT-ONLY (d), counted, when
 *   (1) saturated: |Force| is at the Force frame's limit (NTE_FRAMES_FORCE_MAX_N): the true
 *       force is beyond what the frame can say (nte_node_ev_sensor_saturated); or
 *   (2) stuck: the reading is exactly the previous one's, NTE_NODE_STUCK_SAMPLES readings in
 *       a row, while the last Estimate said in tissue and the newest depth is at least
 *       NTE_NODE_STUCK_TRAVEL_UM away from the depth when the first of them came
 *       (nte_node_ev_sensor_stuck).  A working sensor's noise (7-51 mN measured, against the
 *       frame's 0.1 mN step) makes five equal readings about as likely as 1e-12, and a
 *       needle that moves half a millimetre in tissue changes the force; in the air, where a
 *       coarse sensor may repeat its tare, and in a dwell, the rule does not fire.
 *   Recovery is automatic: the first reading that differs (or leaves the limit) is read
 *   again.  The first readings of a stuck run are read before the rule can fire.
 *
 * THE PORT INTERFACE (bring the node to a board by writing these three functions)
 *   nte_node_port_t holds three function pointers and a context pointer passed back to each:
 *     receive(ctx, frame)  NON-BLOCKING: 1 = *frame filled with one received frame, 0 = nothing
 *                          pending, negative = receive error (counted; the poll stops there).
 *                          Error frames and remote frames may be passed with their flags set
 *                          (they are counted as unknown ids) or filtered by the port.
 *     send(ctx, frame)     NON-BLOCKING: 0 = queued for transmission, negative = not sent (bus
 *                          or TX FIFO full, bus off, ...): the frame is dropped and counted.
 *     now_us(ctx)          monotonic clock in microseconds (any epoch, must not go backwards).
 *   A port for a microcontroller's CAN controller reads its RX FIFO in receive(), writes a TX
 *   mailbox in send() and reads a free-running timer in now_us().  The Linux SocketCAN port is
 *   firmware/port/linux/.  Hardware acceptance filters may pass only the node's four input ids
 *   (nte_node_input_id); nothing else is needed.
 *
 * INTEGRATION
 *   Compile nte_node.c with the estimator library (firmware/src) and the CAN layer
 *   (firmware/can: nte_frames.c, nte_e2e.c, generated/nte_can.c); C99, -ffp-contract=off.
 *   Call nte_node_init once, then nte_node_poll whenever a frame may have arrived and at least
 *   every heartbeat period (a main loop, a CAN RX interrupt deferring to a task, or poll() on a
 *   socket with a timeout of nte_node_next_deadline_us).
 *
 * MEMORY MODEL
 *   The caller owns the instance (sizeof(nte_node_t) is 5352 bytes on x86-64 with the default
 *   sizes: the estimator nte_t 3232, three estimator configurations 3 x 336, the queues):
 *   no allocation, no global or static mutable state; queues are fixed arrays in the instance
 *   (sizes NTE_NODE_DEPTH_HISTORY and NTE_NODE_FORCE_QUEUE below, compile-time).
 *
 * THREAD SAFETY
 *   None: call every function of one instance from one context.
 *
 * COST
 *   nte_node_poll: per received frame one E2E CRC (8 bytes) and a few dozen operations; per
 *   force sample one nte_step (see nte.h), a search of at most NTE_NODE_DEPTH_HISTORY entries,
 *   1 + params_per_step encodes (one float log10 each for Params).  At most `rx_budget` frames
 *   are received per call, so one call is bounded.
 */
#ifndef NTE_NODE_H
#define NTE_NODE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "nte.h"
#include "nte_frames.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Depth samples kept for interpolation (ring; the oldest is overwritten), 2..1024. */
#ifndef NTE_NODE_DEPTH_HISTORY
#define NTE_NODE_DEPTH_HISTORY 32
#endif
#if (NTE_NODE_DEPTH_HISTORY < 2) || (NTE_NODE_DEPTH_HISTORY > 1024)
#error "NTE_NODE_DEPTH_HISTORY must be in 2..1024"
#endif

/** Force samples waiting for a later depth sample, 1..1024; a force frame arriving when it is
 *  full is dropped and counted (nte_node_ev_queue_overflow). */
#ifndef NTE_NODE_FORCE_QUEUE
#define NTE_NODE_FORCE_QUEUE 16
#endif
#if (NTE_NODE_FORCE_QUEUE < 1) || (NTE_NODE_FORCE_QUEUE > 1024)
#error "NTE_NODE_FORCE_QUEUE must be in 1..1024"
#endif

/** Classic CAN frame as the port passes it. */
typedef struct nte_node_frame_t {
    uint32_t id;   /**< 11-bit (or 29-bit if `extended`) identifier */
    uint8_t len;   /**< data length, 0..8 */
    bool extended; /**< 29-bit identifier (never one of the node's) */
    bool remote;   /**< remote request (never one of the node's) */
    uint8_t data[8];
} nte_node_frame_t;

/** THE port interface: see "THE PORT INTERFACE" above. */
typedef struct nte_node_port_t {
    void* ctx;
    int (*receive)(void* ctx, nte_node_frame_t* frame);
    int (*send)(void* ctx, const nte_node_frame_t* frame);
    uint64_t (*now_us)(void* ctx);
} nte_node_port_t;

/** Events counted by the node (nte_node_counters_t.events[]). */
typedef enum nte_node_event_t {
    nte_node_ev_wrong_dlc = 0,          /**< input frame whose length is not 8: dropped */
    nte_node_ev_unknown_id = 1,         /**< id none of the node's inputs, extended or remote */
    nte_node_ev_bad_crc = 2,            /**< E2E CRC wrong: dropped */
    nte_node_ev_counter_invalid = 3,    /**< alive counter 15 (never sent): dropped */
    nte_node_ev_counter_repeated = 4,   /**< alive counter equal to the previous one: dropped */
    nte_node_ev_counter_skipped = 5,    /**< counter jumped (frames lost upstream): ACCEPTED;
                                             the number lost is in frames_lost */
    nte_node_ev_out_of_range = 6,       /**< E2E-valid frame with a raw value outside the DBC
                                             range, or a command selector undefined: dropped */
    nte_node_ev_time_backwards = 7,     /**< sample not later than the previous one of its stream */
    nte_node_ev_queue_overflow = 8,     /**< force frame dropped: force queue full */
    nte_node_ev_send_failed = 9,        /**< port send() refused an output frame: dropped */
    nte_node_ev_command_refused = 10,   /**< valid command the node may not carry out (model,
                                             estimator or reset while in tissue; Model III
                                             with the robust estimator): ignored */
    nte_node_ev_stale = 11,             /**< force sample without recent depth: estimate held */
    nte_node_ev_receive_error = 12,     /**< port receive() reported an error */
    nte_node_ev_encode_error = 13,      /**< an output could not be encoded (non-finite): the
                                             Estimate is sent with Fault set instead */
    nte_node_ev_time_jump_dropped = 14, /**< sample held for a time jump and not confirmed by
                                           the next sample of its stream: dropped */
    nte_node_ev_time_resync = 15,       /**< time jump confirmed: the stream resynchronised */
    nte_node_ev_command_stale = 16,     /**< command whose counter is not the successor of the
                                             last command's (replayed or after a loss): ignored */
    nte_node_ev_command_rate_limited = 17, /**< command within command_interval_us of the last
                                           applied one: ignored */
    nte_node_ev_sensor_stuck = 18,         /**< force reading judged stuck (SENSOR WATCH): not
                                               read, predicted from the model */
    nte_node_ev_sensor_saturated = 19,     /**< force reading at the Force frame's limit (SENSOR
                                               WATCH): not read, predicted from the model */
    nte_node_ev_setting_refused = 20       /**< Setting frame not taken: the transfer breaks off
                                               (SETTINGS) */
} nte_node_event_t;
#define NTE_NODE_EVENT_COUNT 21

/** SENSOR WATCH: a force reading repeated exactly this many times in a row (this one
 *  included) ... */
#define NTE_NODE_STUCK_SAMPLES 5u
/** ... while the depth moved at least this far since the first of them, micrometres, in
 *  tissue, is a stuck sensor. */
#define NTE_NODE_STUCK_TRAVEL_UM 500u

/** Frames the node sends: Estimate, Params, Heartbeat, Contact, Health. */
#define NTE_NODE_OUTPUTS 5u

/** Counters (monotonic, wrap modulo 2^32); public, the application may clear them. */
typedef struct nte_node_counters_t {
    uint32_t events[NTE_NODE_EVENT_COUNT]; /**< by nte_node_event_t */
    uint32_t frames_lost;                  /**< frames missed upstream, from counter skips */
    uint32_t rx_accepted[4];               /**< accepted depth, force, command, setting
                                                frames */
    uint32_t tx[NTE_NODE_OUTPUTS];         /**< sent estimate, params, heartbeat, contact,
                                                health frames */
    uint32_t steps;                        /**< estimator steps (non-stale force samples,
                                                and the depth samples of PREDICT-ONLY (c)) */
    uint32_t commands_applied;             /**< commands carried out */
    uint32_t predict_on;                   /**< steps that entered predict-only mode */
    uint32_t predict_off;                  /**< steps that left it (identifying again) */
    uint32_t predict_depth_steps;          /**< steps on Depth samples, the sensor lost */
    uint32_t settings_applied;             /**< configurations received and applied
                                                (SETTINGS) */
} nte_node_counters_t;

/** Node tuning; fill with nte_node_config_default, then change what you need. */
typedef struct nte_node_config_t {
    uint32_t base_id;             /**< CAN id base, 0..0x7FF - 0x14 = 0x7EB (default 0x200) */
    int32_t model;                /**< model at start: 1, 2 or 3 */
    nte_config_t estimator[3];    /**< estimator configuration for Model I [0], II [1] and
                                       III [2] (model fields 1, 2, 3; Model III: the bank
                                       estimator only, the robust one refuses it) */
    uint32_t depth_timeout_us;    /**< depth older than this (sensor time) at a force sample
                                       makes it stale, 100..3000000 us (default 50000) */
    uint32_t heartbeat_period_us; /**< port clock, 1000..10000000 us (default 100000) */
    uint32_t params_per_step;     /**< Params frames after each step, 1..7 (default 1) */
    uint32_t rx_budget;           /**< frames received per nte_node_poll, 1..65535 (default 64) */
    uint32_t resync_gap_us;       /**< a sample further than this (sensor time) from its stream's
                                       newest is a time jump, held until confirmed (see TIME),
                                       1000..3000000 us (default 20000) */
    uint32_t command_interval_us; /**< port clock: a command within this of the last applied
                                       one is ignored, 0..10000000 us (default 100000) */
} nte_node_config_t;

/** Result of the node functions: 0 success, negative error. */
typedef enum nte_node_err_t {
    nte_node_ok = 0,
    nte_node_err_null = -1,       /**< a pointer argument or port function is NULL */
    nte_node_err_bad_config = -2, /**< a node field outside its range */
    nte_node_err_estimator = -3   /**< an estimator configuration fails nte_config_check */
} nte_node_err_t;

/** Sensor time between two steps on the Depth stream while the force sensor is lost
 *  (PREDICT-ONLY (c)), us: 200 Hz, the Force frame's cycle time. */
#define NTE_NODE_PREDICT_PERIOD_US 5000u

/** Sensor time between two Contact frames when nothing changes (Model III), us (10 Hz). */
#define NTE_NODE_CONTACT_PERIOD_US 100000u
/** Sensor time between two Health frames when nothing changes, us (10 Hz). */
#define NTE_NODE_HEALTH_PERIOD_US 100000u

/* The node's defaults, written once: nte_node_config_default, the Linux port's options
 * (port/linux/nte_node_main.c) and the bench's node mirror (host_bench/node_mirror.py, which
 * reads these lines at import) take them from here. */
#define NTE_NODE_DEFAULT_MODEL 2
#define NTE_NODE_DEFAULT_DEPTH_TIMEOUT_US 50000u
#define NTE_NODE_DEFAULT_HEARTBEAT_PERIOD_US 100000u
#define NTE_NODE_DEFAULT_PARAMS_PER_STEP 1u
#define NTE_NODE_DEFAULT_RX_BUDGET 64u
#define NTE_NODE_DEFAULT_RESYNC_GAP_US 20000u
#define NTE_NODE_DEFAULT_COMMAND_INTERVAL_US 100000u

/** Node state (as in the Heartbeat). */
typedef enum nte_node_state_t {
    nte_node_state_init = 0, /**< no estimate yet (after start, reset or model change) */
    nte_node_state_running = 1,
    nte_node_state_fault = 2 /**< the last step was rejected by the estimator */
} nte_node_state_t;

typedef struct nte_node_depth_t {
    uint32_t t; /**< unwrapped sensor ticks (100 us) */
    float depth_mm;
    float velocity_mm_s;
} nte_node_depth_t;

typedef struct nte_node_force_t {
    uint32_t t;
    float force_n;
    bool fault;    /**< SensorFault: processed in predict-only, force not read */
    bool on_depth; /**< not a force sample: a step on the depth stream at a depth
                        sample's time (PREDICT-ONLY (c)) */
} nte_node_force_t;

/** A sample held for a time jump, with the E2E state and clock it would commit. */
typedef struct nte_node_pending_t {
    bool held;
    uint32_t t;               /**< unwrapped against `clock` */
    nte_frames_clock_t clock; /**< the shared clock after this sample */
    nte_e2e_rx_t rx;          /**< the stream's E2E state after this sample */
    nte_e2e_result_t e2e;
    uint8_t lost;
    float a; /**< depth_mm or force_n */
    float b; /**< velocity_mm_s (depth); force: 1 = SensorFault, 0 = not */
} nte_node_pending_t;

/** A configuration transfer in progress (SETTINGS). */
typedef struct nte_node_settings_t {
    bool open;         /**< BEGIN taken, no COMMIT or break yet */
    bool unapplied;    /**< the configurations hold a transfer not applied */
    uint8_t announced; /**< value items BEGIN announced */
    uint8_t received;  /**< value items taken */
    uint64_t seen;     /**< bit i: item i taken (items 1..59) */
} nte_node_settings_t;

/** One node.  Every field except `counters` is private. */
typedef struct nte_node_t {
    nte_node_config_t cfg;
    nte_node_port_t port;
    nte_t est;
    int32_t model;
    nte_estimator_t estimator;
    bool have_command;
    uint64_t last_command_us;          /* port clock of the last applied command */
    nte_e2e_rx_t rx[4];                /* depth, force, command, setting */
    nte_e2e_tx_t tx[NTE_NODE_OUTPUTS]; /* estimate, params, heartbeat, contact, health */
    nte_frames_clock_t clock;
    nte_node_depth_t depth[NTE_NODE_DEPTH_HISTORY];
    uint32_t depth_next; /* ring write index */
    uint32_t depth_count;
    nte_node_force_t force[NTE_NODE_FORCE_QUEUE];
    uint32_t force_head;
    uint32_t force_count;
    bool have_force;
    /* SENSOR WATCH: the last unflagged force reading, how many times in a row it came, the
     * depth when it first came */
    float watch_force;
    uint32_t watch_run;
    float watch_depth_mm;
    nte_node_pending_t pending[2]; /* depth, force */
    uint32_t last_force_t;         /* newest accepted force time (queued or processed) */
    nte_frames_estimate_t last;    /* last published estimate values (held when stale) */
    uint8_t param_next;
    bool contact_sent;            /* a Contact frame was sent since the model started */
    uint32_t contact_t;           /* sensor ticks of the force sample of the last one */
    nte_frames_contact_t contact; /* its content */
    bool health_sent;             /* a Health frame was sent since the model started */
    uint32_t health_t;            /* sensor ticks of the force sample of the last one */
    nte_frames_health_t health;   /* its content */
    nte_node_state_t state;
    bool force_cmd_model; /* Command.ForceSource 2 in force (PREDICT-ONLY (a)) */
    bool predicting;      /* the mode of the last step */
    bool depth_stepped;   /* the last step was on a depth sample (PREDICT-ONLY (c)) */
    bool have_step;
    uint32_t step_t;              /* sensor ticks of the last step */
    bool depth_since_force;       /* a depth sample came after the newest force sample ... */
    uint32_t depth_since_force_t; /* ... the first of them, sensor ticks */
    uint64_t t_start_us;
    uint64_t next_heartbeat_us;
    uint32_t step_time_max_us;
    nte_node_settings_t settings;
    nte_node_counters_t counters;
} nte_node_t;

/** Defaults: base 0x200, the given model, nte_config_default for the three models (schedule
 *  all, bank estimator; Model III with the contact front end on, surface found from the
 *  force), 50 ms depth timeout, 100 ms heartbeat, one Params frame per step, 64 frames
 *  per poll, 20 ms resync gap, 100 ms between commands. */
void nte_node_config_default(nte_node_config_t* cfg, int32_t model);

/** SETTINGS: the three estimator configurations to their defaults (nte_config_default,
 *  schedule all, bank; Model III with the contact front end on, the surface found from the
 *  force): where a transfer, and nte-node --config, start from. */
void nte_node_settings_begin(nte_node_config_t* cfg);

/** SETTINGS: write one value item (NTE_FRAMES_SETTING_MODEL .. _LAST_VALUE) into cfg: the
 *  model into cfg->model; a nominal parameter sigma0..beta into the three estimator
 *  configurations (beta also as Model I's beta0; f1 or f2 make the f1 excess computed from
 *  the nominal, f1_excess 0), g_fast, g_slow, delta (presliding_mm), the time constants,
 *  branches, switches, known surface and layer sets into Model III's; r_n2 into all three.
 *  Returns nte_node_err_bad_config, cfg unchanged, for a non-finite value, an item that is not
 *  a value item, a model not 1..3, a branch count, switch or set count that is not a whole
 *  number in range, or a layer set at or beyond NTE_LAYER_SETS_MAX; the ranges of the
 *  values themselves are nte_config_check's, at COMMIT. */
nte_node_err_t nte_node_setting_apply(nte_node_config_t* cfg, uint32_t item, float value);

/** Validate cfg and the port, initialise the estimator and every queue; the first heartbeat is
 *  due one period after now_us().  On error self is unspecified.  Cost: one nte_init. */
nte_node_err_t nte_node_init(nte_node_t* self, const nte_node_config_t* cfg,
                             const nte_node_port_t* port);

/** One pass of the loop: receive up to rx_budget frames (each handled at once, estimating and
 *  publishing as force samples become ready), then send the heartbeat if it is due.  Never
 *  blocks (beyond what the port's functions do).  Returns the number of frames received
 *  (0 when none was pending), or nte_node_err_null. */
int32_t nte_node_poll(nte_node_t* self);

/** Port clock time of the next heartbeat: sleep at most until then between polls. */
uint64_t nte_node_next_deadline_us(const nte_node_t* self);

/** CAN id of input `kind` (0 depth, 1 force, 2 command, 3 setting) for the configured base. */
uint32_t nte_node_input_id(const nte_node_t* self, uint32_t kind);

/** Active model (1, 2 or 3) and state. */
int32_t nte_node_model(const nte_node_t* self);
nte_node_state_t nte_node_state(const nte_node_t* self);

/** Short name of an event ("wrong_dlc", ...), "?" if out of range.  Cost: O(1). */
const char* nte_node_event_name(uint32_t event);

#ifdef __cplusplus
}
#endif

#endif /* NTE_NODE_H */
