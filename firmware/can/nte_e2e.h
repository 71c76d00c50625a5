/*
 * nte_e2e.h -- end-to-end protection of the estimator node's CAN frames.
 *
 * What it does: AUTOSAR E2E profile 11 style protection of a classic CAN payload, in the layout
 * the project's DBC (firmware/can/nte.dbc) fixes for every frame:
 *   byte 0      CRC-8 SAE J1850 (polynomial 0x1D, initial value 0x00, no final XOR -- the values
 *               profile 11 ends up with), computed over the 16-bit data id, low byte first, then
 *               high byte ("data id mode BOTH"), then payload bytes 1 .. length-1;
 *   bits 8..11  alive counter 0..14, incremented by one per frame of one message, 14 wraps to 0
 *               (15 is never sent);
 *   bits 12..63 the message's own signals (protected by the CRC, not touched here).
 * The sender keeps one nte_e2e_tx_t per message, the receiver one nte_e2e_rx_t per message.
 * Checked against the independent `autosar-e2e` Python package by tests/python/test_can_codec.py.
 *
 * Integration: copy nte_e2e.h and nte_e2e.c; C99, no dependency beyond <stdint.h>, <stddef.h>,
 * <stdbool.h>. No dynamic memory, no globals: the caller owns every state struct. Not thread-safe:
 * one state struct must not be used by two contexts at once.
 *
 * Costs: every function is O(length) with length <= 8; the CRC is computed bit by bit
 * (8 shifts per byte, no table), about 80 simple operations per byte.
 */
#ifndef NTE_E2E_H
#define NTE_E2E_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Largest alive counter value; the counter counts 0, 1, ..., 14, 0, ... */
#define NTE_E2E_COUNTER_MAX 14u
/** Shortest protected frame: the CRC byte and the counter nibble. */
#define NTE_E2E_MIN_LENGTH 2u
/** Longest protected frame (classic CAN). */
#define NTE_E2E_MAX_LENGTH 8u

/** Outcome of a protect or a check. 0 = accepted, positive = accepted with a note, negative =
 *  the frame must be discarded. */
typedef enum {
    nte_e2e_ok = 0,                /**< CRC right, counter is the previous one + 1 (or the first
                                        frame since init/reset). */
    nte_e2e_skipped = 1,           /**< CRC right, the counter jumped: frames were lost (how many
                                        is reported through `lost`); the frame is accepted. */
    nte_e2e_err_null = -1,         /**< A pointer argument was NULL. */
    nte_e2e_err_wrong_length = -2, /**< The frame length is not the one configured. */
    nte_e2e_err_bad_crc = -3,      /**< The CRC does not match payload and data id. */
    nte_e2e_err_repeated = -4,     /**< CRC right, same counter as the previous accepted frame
                                        (a repeat -- or exactly 15 frames lost, which is
                                        indistinguishable). */
    nte_e2e_err_bad_counter = -5,  /**< The counter is 15, which is never sent. */
    nte_e2e_err_bad_config = -6    /**< Length outside 2..8 at init. */
} nte_e2e_result_t;

/** Sender state for one message. */
typedef struct {
    uint16_t data_id; /**< The message's E2E data id (NteE2EDataId in the DBC). */
    uint8_t length;   /**< Frame length in bytes, 2..8. */
    uint8_t counter;  /**< Counter the next protected frame gets, 0..14. */
} nte_e2e_tx_t;

/** Receiver state for one message. */
typedef struct {
    uint16_t data_id;     /**< Expected data id. */
    uint8_t length;       /**< Expected frame length in bytes, 2..8. */
    uint8_t last_counter; /**< Counter of the last accepted frame (valid when synced). */
    bool synced;          /**< False until the first frame is accepted (after init or reset). */
} nte_e2e_rx_t;

/** CRC-8 SAE J1850 polynomial 0x1D, no reflection, continued from `crc` (pass 0x00 to start a
 *  profile 11 CRC), no final XOR. Cost: 8 shift/xor steps per byte. `data` may be NULL if
 *  `length` is 0. */
uint8_t nte_e2e_crc8(const uint8_t* data, size_t length, uint8_t crc);

/** The profile 11 CRC of a frame: over data id (low, high byte) and frame[1 .. length-1].
 *  Does not read frame[0]. Requires length >= 1. */
uint8_t nte_e2e_frame_crc(uint16_t data_id, const uint8_t* frame, size_t length);

/** Set up a sender; the first protected frame gets counter 0.
 *  Returns nte_e2e_ok, nte_e2e_err_null or nte_e2e_err_bad_config (length not in 2..8). */
nte_e2e_result_t nte_e2e_tx_init(nte_e2e_tx_t* self, uint16_t data_id, uint8_t length);

/** Protect a frame whose signals (bits 12 and up) are already packed: writes the counter into
 *  bits 8..11 (keeping bits 12..15), then the CRC into byte 0, then advances the counter.
 *  Returns nte_e2e_ok, nte_e2e_err_null, or nte_e2e_err_wrong_length if `length` differs from
 *  the configured one (the frame is then left untouched and the counter is not advanced). */
nte_e2e_result_t nte_e2e_protect(nte_e2e_tx_t* self, uint8_t* frame, size_t length);

/** Set up a receiver, not synced: the first frame with a right CRC is accepted with any counter.
 *  Returns nte_e2e_ok, nte_e2e_err_null or nte_e2e_err_bad_config. */
nte_e2e_result_t nte_e2e_rx_init(nte_e2e_rx_t* self, uint16_t data_id, uint8_t length);

/** Forget the counter history (e.g. after a bus-off or a sender restart). */
void nte_e2e_rx_reset(nte_e2e_rx_t* self);

/** Check a received frame. Order: length, counter value (15 is invalid), CRC, counter
 *  continuity (the autosar-e2e package also rejects counter 15 before anything else).
 *  `lost` (may be NULL) receives the number of frames missed before this one (0 unless the
 *  result is nte_e2e_skipped, then 1..13). The state advances only when the result is >= 0.
 *  Counter delta d = (counter - last) mod 15: d = 1 -> ok, d = 0 -> repeated, d = 2..14 ->
 *  skipped with d - 1 frames lost. */
nte_e2e_result_t nte_e2e_check(nte_e2e_rx_t* self, const uint8_t* frame, size_t length,
                               uint8_t* lost);

/** Counter of a frame (bits 8..11); the frame must hold at least 2 bytes. */
uint8_t nte_e2e_counter_of(const uint8_t* frame);

#ifdef __cplusplus
}
#endif

#endif /* NTE_E2E_H */
