/*
 * Error-detection figures of the E2E check (firmware/can/nte_e2e.c) on 8-byte frames.
 *   crc_coverage N_RANDOM NAME:DATA_ID [NAME:DATA_ID ...]
 * For every frame type given: a receiver is synced on a valid frame with counter c, then a
 * second valid frame (counter c + 1) is corrupted by an error pattern and checked.  Detected =
 * nte_e2e_check < 0.  Exhaustive: every 1-, 2- and 3-bit error and every burst of length 2..8
 * over the 64 transmitted bits (wire order), each on 4 different base frames (all counters 0..14 are used as
 * c over the patterns).  Random: N_RANDOM uniformly random non-zero 64-bit error patterns; the
 * residual acceptance (any accept, and accept as the in-sequence frame) is printed.
 * Output: one "key=value" line per frame type; exit 1 if a 1- or 2-bit error, or a burst of
 * length <= 8 within the data bytes 1..7, went undetected.  3-bit errors are NOT all detected:
 * x^8+x^4+x^3+x^2+1 is primitive without the factor (x+1), so its Hamming distance is 3 (at
 * these lengths), not 4: the figures are printed, not required to be 0.
 */
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nte_e2e.h"

static uint64_t rng_state = 0x9E3779B97F4A7C15ULL;

static uint64_t rng(void)
{
    /* xorshift64* */
    rng_state ^= rng_state >> 12U;
    rng_state ^= rng_state << 25U;
    rng_state ^= rng_state >> 27U;
    return rng_state * 0x2545F4914F6CDD1DULL;
}

typedef struct {
    uint16_t data_id;
    uint8_t base[4][8]; /* signal bits of 4 base frames (byte 0 and counter set per test) */
    uint32_t turn;
} ctx_t;

/* 0 = detected, 1 = accepted in sequence (ok), 2 = accepted with a counter skip. */
static int trial(ctx_t* c, uint64_t mask)
{
    const uint8_t* sig = c->base[c->turn & 3U];
    const uint8_t prev = (uint8_t)(c->turn % 15U);
    c->turn++;
    nte_e2e_tx_t tx;
    nte_e2e_rx_t rx;
    if ((nte_e2e_tx_init(&tx, c->data_id, 8U) != nte_e2e_ok) ||
        (nte_e2e_rx_init(&rx, c->data_id, 8U) != nte_e2e_ok)) {
        abort();
    }
    tx.counter = prev;
    uint8_t f0[8];
    uint8_t f1[8];
    memcpy(f0, sig, 8U);
    memcpy(f1, sig, 8U);
    if ((nte_e2e_protect(&tx, f0, 8U) != nte_e2e_ok) ||
        (nte_e2e_check(&rx, f0, 8U, NULL) != nte_e2e_ok)) {
        abort();
    }
    f1[7] ^= 0x5AU; /* the next frame carries other signal values */
    if (nte_e2e_protect(&tx, f1, 8U) != nte_e2e_ok) {
        abort();
    }
    for (unsigned b = 0U; b < 8U; b++) {
        f1[b] ^= (uint8_t)(mask >> (8U * b));
    }
    const nte_e2e_result_t r = nte_e2e_check(&rx, f1, 8U, NULL);
    if (r < 0) {
        return 0;
    }
    return (r == nte_e2e_ok) ? 1 : 2;
}

int main(int argc, char** argv)
{
    if (argc < 3) {
        (void)fprintf(stderr, "usage: %s N_RANDOM NAME:DATA_ID...\n", argv[0]);
        return 2;
    }
    const unsigned long n_random = strtoul(argv[1], NULL, 10);
    int bad = 0;
    for (int a = 2; a < argc; a++) {
        char name[64];
        unsigned id = 0U;
        if (sscanf(argv[a], "%63[^:]:%u", name, &id) != 2 || id > 0xFFFFU) {
            (void)fprintf(stderr, "bad argument %s\n", argv[a]);
            return 2;
        }
        ctx_t c;
        memset(&c, 0, sizeof c);
        c.data_id = (uint16_t)id;
        for (unsigned k = 0U; k < 4U; k++) {
            const uint64_t r = rng();
            memcpy(c.base[k], &r, 8U);
        }
        unsigned long n1 = 0U, m1 = 0U, n2 = 0U, m2 = 0U, n3 = 0U, m3 = 0U, nb = 0U, mb = 0U;
        for (unsigned i = 0U; i < 64U; i++) {
            const uint64_t e1 = 1ULL << i;
            n1++;
            m1 += (trial(&c, e1) != 0) ? 1U : 0U;
            for (unsigned j = i + 1U; j < 64U; j++) {
                const uint64_t e2 = e1 | (1ULL << j);
                n2++;
                m2 += (trial(&c, e2) != 0) ? 1U : 0U;
                for (unsigned k = j + 1U; k < 64U; k++) {
                    n3++;
                    m3 += (trial(&c, e2 | (1ULL << k)) != 0) ? 1U : 0U;
                }
            }
        }
        /* Bursts in wire order (CAN sends byte 0 first, each byte MSB first): wire bit w is bit
         * 7 - w % 8 of byte w / 8.  First and last bit flipped, any inner bits, length 2..8.
         * "data" bursts lie within bytes 1..7 (the CRC's own codeword order, every burst of
         * length <= 8 is detected by any CRC-8); the others touch the CRC byte, which is sent
         * BEFORE the data it protects, so they are not bursts of the CRC codeword. */
        unsigned long nbd = 0U, mbd = 0U;
        for (unsigned len = 2U; len <= 8U; len++) {
            for (unsigned start = 0U; start + len <= 64U; start++) {
                for (uint64_t inner = 0U; inner < (1ULL << (len - 2U)); inner++) {
                    const uint64_t wire = (1ULL | (inner << 1U) | (1ULL << (len - 1U)));
                    uint64_t e = 0U;
                    for (unsigned b = 0U; b < len; b++) {
                        if (((wire >> b) & 1U) != 0U) {
                            const unsigned w = start + b;
                            e |= 1ULL << (8U * (w / 8U) + (7U - (w % 8U)));
                        }
                    }
                    const int undetected = (trial(&c, e) != 0) ? 1 : 0;
                    if (start >= 8U) {
                        nbd++;
                        mbd += (unsigned long)undetected;
                    } else {
                        nb++;
                        mb += (unsigned long)undetected;
                    }
                }
            }
        }
        unsigned long acc = 0U, acc_ok = 0U;
        for (unsigned long t = 0U; t < n_random; t++) {
            uint64_t e;
            do {
                e = rng();
            } while (e == 0U);
            const int r = trial(&c, e);
            acc += (r != 0) ? 1U : 0U;
            acc_ok += (r == 1) ? 1U : 0U;
        }
        printf("frame=%s data_id=%u single=%lu single_undetected=%lu double=%lu "
               "double_undetected=%lu triple=%lu triple_undetected=%lu bursts=%lu "
               "burst_undetected=%lu crc_byte_bursts=%lu crc_byte_burst_undetected=%lu random=%lu "
               "random_accepted=%lu random_rate=%.6g "
               "random_accepted_in_sequence=%lu in_sequence_rate=%.6g\n",
               name, id, n1, m1, n2, m2, n3, m3, nbd, mbd, nb, mb, n_random, acc,
               (n_random > 0U) ? (double)acc / (double)n_random : 0.0, acc_ok,
               (n_random > 0U) ? (double)acc_ok / (double)n_random : 0.0);
        if ((m1 | m2 | mbd) != 0U) {
            bad = 1;
        }
    }
    return bad;
}
