/* cmocka tests of firmware/can/nte_e2e: CRC reference values, counter sequence, every result
 * code, every counter delta. The bit-exact comparison with the independent autosar-e2e package
 * is in tests/python/test_can_codec.py. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "nte_e2e.h"

/* CRC-8 SAE J1850 check value: "123456789" with init 0xFF and final XOR 0xFF gives 0x4B
 * (the catalogued CRC-8/SAE-J1850); with init 0 and no XOR (profile 11's form) 0x37. */
static void test_crc8_catalogue(void** state)
{
    const uint8_t msg[9] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
    (void)state;
    assert_int_equal(nte_e2e_crc8(msg, 9, 0xFFu) ^ 0xFFu, 0x4Bu);
    assert_int_equal(nte_e2e_crc8(msg, 9, 0x00u), 0x37u);
    assert_int_equal(nte_e2e_crc8(NULL, 0, 0x5Au), 0x5Au);
}

/* Values produced by the autosar-e2e package (e2e.p11.e2e_p11_protect, data id mode BOTH). */
static void test_frame_crc_reference(void** state)
{
    uint8_t f1[8] = {0x00, 0xA1, 1, 2, 3, 4, 5, 6}; /* data id 0x1234 -> crc 0x1E */
    uint8_t f2[8] = {0x00, 0xA2, 1, 2, 3, 4, 5, 6}; /* -> 0xF9 */
    uint8_t f3[8] = {0x00, 0xA0, 1, 2, 3, 4, 5, 6}; /* -> 0x43 */
    (void)state;
    assert_int_equal(nte_e2e_frame_crc(0x1234u, f1, 8), 0x1Eu);
    assert_int_equal(nte_e2e_frame_crc(0x1234u, f2, 8), 0xF9u);
    assert_int_equal(nte_e2e_frame_crc(0x1234u, f3, 8), 0x43u);
}

static void test_protect_sequence_and_wrap(void** state)
{
    nte_e2e_tx_t tx;
    uint8_t frame[8];
    int k;
    (void)state;
    assert_int_equal(nte_e2e_tx_init(&tx, 0x4E00u, 8), nte_e2e_ok);
    for (k = 0; k < 40; ++k) {
        memset(frame, 0, sizeof frame);
        frame[1] = 0x70u; /* a signal nibble that must survive */
        frame[5] = (uint8_t)k;
        assert_int_equal(nte_e2e_protect(&tx, frame, 8), nte_e2e_ok);
        assert_int_equal(nte_e2e_counter_of(frame), (uint8_t)(k % 15));
        assert_int_equal(frame[1] & 0xF0u, 0x70u);
        assert_int_equal(frame[0], nte_e2e_frame_crc(0x4E00u, frame, 8));
    }
}

static void test_protect_errors(void** state)
{
    nte_e2e_tx_t tx;
    uint8_t frame[8] = {0};
    (void)state;
    assert_int_equal(nte_e2e_tx_init(NULL, 1, 8), nte_e2e_err_null);
    assert_int_equal(nte_e2e_tx_init(&tx, 1, 1), nte_e2e_err_bad_config);
    assert_int_equal(nte_e2e_tx_init(&tx, 1, 9), nte_e2e_err_bad_config);
    assert_int_equal(nte_e2e_tx_init(&tx, 1, 8), nte_e2e_ok);
    assert_int_equal(nte_e2e_protect(&tx, NULL, 8), nte_e2e_err_null);
    assert_int_equal(nte_e2e_protect(&tx, frame, 7), nte_e2e_err_wrong_length);
    assert_int_equal(tx.counter, 0); /* not advanced */
    assert_int_equal(frame[0], 0);
}

static void make_frame(nte_e2e_tx_t* tx, uint8_t* frame, uint8_t counter)
{
    memset(frame, 0x33, 8);
    tx->counter = counter;
    assert_int_equal(nte_e2e_protect(tx, frame, 8), nte_e2e_ok);
}

/* Every counter delta from every previous counter: 1 ok, 0 repeated, 2..14 skipped d-1. */
static void test_check_every_delta(void** state)
{
    nte_e2e_tx_t tx;
    nte_e2e_rx_t rx;
    uint8_t frame[8];
    uint8_t lost;
    unsigned prev;
    unsigned d;
    (void)state;
    assert_int_equal(nte_e2e_tx_init(&tx, 0x0815u, 8), nte_e2e_ok);
    for (prev = 0; prev <= 14u; ++prev) {
        for (d = 0; d < 15u; ++d) {
            uint8_t next = (uint8_t)((prev + d) % 15u);
            assert_int_equal(nte_e2e_rx_init(&rx, 0x0815u, 8), nte_e2e_ok);
            make_frame(&tx, frame, (uint8_t)prev);
            assert_int_equal(nte_e2e_check(&rx, frame, 8, &lost), nte_e2e_ok); /* first */
            make_frame(&tx, frame, next);
            if (d == 0u) {
                assert_int_equal(nte_e2e_check(&rx, frame, 8, &lost), nte_e2e_err_repeated);
                assert_int_equal(lost, 0);
                assert_int_equal(rx.last_counter, prev);
            } else if (d == 1u) {
                assert_int_equal(nte_e2e_check(&rx, frame, 8, &lost), nte_e2e_ok);
                assert_int_equal(lost, 0);
                assert_int_equal(rx.last_counter, next);
            } else {
                assert_int_equal(nte_e2e_check(&rx, frame, 8, &lost), nte_e2e_skipped);
                assert_int_equal(lost, d - 1u);
                assert_int_equal(rx.last_counter, next);
            }
        }
    }
}

static void test_check_errors(void** state)
{
    nte_e2e_tx_t tx;
    nte_e2e_rx_t rx;
    uint8_t frame[8];
    uint8_t good[8];
    unsigned byte;
    unsigned bit;
    (void)state;
    assert_int_equal(nte_e2e_tx_init(&tx, 0x4E01u, 8), nte_e2e_ok);
    assert_int_equal(nte_e2e_rx_init(&rx, 0x4E01u, 8), nte_e2e_ok);
    make_frame(&tx, good, 3);
    /* every single-bit error is detected (CRC-8 detects all 1-bit errors) */
    for (byte = 0; byte < 8u; ++byte) {
        for (bit = 0; bit < 8u; ++bit) {
            memcpy(frame, good, 8);
            frame[byte] = (uint8_t)(frame[byte] ^ (1u << bit));
            assert_int_equal(nte_e2e_check(&rx, frame, 8, NULL), nte_e2e_err_bad_crc);
        }
    }
    assert_false(rx.synced); /* errors do not advance the state */
    /* wrong data id (masquerade) */
    {
        nte_e2e_rx_t other;
        assert_int_equal(nte_e2e_rx_init(&other, 0x4E02u, 8), nte_e2e_ok);
        assert_int_equal(nte_e2e_check(&other, good, 8, NULL), nte_e2e_err_bad_crc);
    }
    /* wrong length, every length but 8 */
    for (byte = 0; byte < 8u; ++byte) {
        assert_int_equal(nte_e2e_check(&rx, good, byte, NULL), nte_e2e_err_wrong_length);
    }
    /* counter 15 with a right CRC */
    memcpy(frame, good, 8);
    frame[1] = (uint8_t)(frame[1] | 0x0Fu);
    frame[0] = nte_e2e_frame_crc(0x4E01u, frame, 8);
    assert_int_equal(nte_e2e_check(&rx, frame, 8, NULL), nte_e2e_err_bad_counter);
    frame[0] = (uint8_t)(frame[0] ^ 0xFFu); /* and with a wrong CRC: still the counter */
    assert_int_equal(nte_e2e_check(&rx, frame, 8, NULL), nte_e2e_err_bad_counter);
    assert_int_equal(nte_e2e_check(NULL, good, 8, NULL), nte_e2e_err_null);
    assert_int_equal(nte_e2e_check(&rx, NULL, 8, NULL), nte_e2e_err_null);
    /* the good frame is accepted, then repeated, then after reset accepted again */
    assert_int_equal(nte_e2e_check(&rx, good, 8, NULL), nte_e2e_ok);
    assert_int_equal(nte_e2e_check(&rx, good, 8, NULL), nte_e2e_err_repeated);
    nte_e2e_rx_reset(&rx);
    assert_int_equal(nte_e2e_check(&rx, good, 8, NULL), nte_e2e_ok);
}

static void test_short_frames(void** state)
{
    nte_e2e_tx_t tx;
    nte_e2e_rx_t rx;
    uint8_t frame[2] = {0, 0x50};
    (void)state;
    assert_int_equal(nte_e2e_tx_init(&tx, 0xBEEFu, 2), nte_e2e_ok);
    assert_int_equal(nte_e2e_rx_init(&rx, 0xBEEFu, 2), nte_e2e_ok);
    assert_int_equal(nte_e2e_protect(&tx, frame, 2), nte_e2e_ok);
    assert_int_equal(nte_e2e_check(&rx, frame, 2, NULL), nte_e2e_ok);
    assert_int_equal(nte_e2e_protect(&tx, frame, 2), nte_e2e_ok);
    assert_int_equal(nte_e2e_check(&rx, frame, 2, NULL), nte_e2e_ok);
    assert_int_equal(nte_e2e_counter_of(frame), 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc8_catalogue),
        cmocka_unit_test(test_frame_crc_reference),
        cmocka_unit_test(test_protect_sequence_and_wrap),
        cmocka_unit_test(test_protect_errors),
        cmocka_unit_test(test_check_every_delta),
        cmocka_unit_test(test_check_errors),
        cmocka_unit_test(test_short_frames),
    };
    return cmocka_run_group_tests_name("nte_e2e", tests, NULL, NULL);
}
