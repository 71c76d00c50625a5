/* nte_e2e.c -- see nte_e2e.h. */
#include "nte_e2e.h"

#define NTE_E2E_POLY 0x1Du
#define NTE_E2E_COUNTER_MODULUS 15u

uint8_t nte_e2e_crc8(const uint8_t* data, size_t length, uint8_t crc)
{
    size_t i;
    for (i = 0u; i < length; ++i) {
        unsigned bit;
        crc = (uint8_t)(crc ^ data[i]);
        for (bit = 0u; bit < 8u; ++bit) {
            if ((crc & 0x80u) != 0u) {
                crc = (uint8_t)((uint8_t)(crc << 1) ^ NTE_E2E_POLY);
            } else {
                crc = (uint8_t)(crc << 1);
            }
        }
    }
    return crc;
}

uint8_t nte_e2e_frame_crc(uint16_t data_id, const uint8_t* frame, size_t length)
{
    uint8_t id[2];
    uint8_t crc;
    id[0] = (uint8_t)(data_id & 0xFFu);
    id[1] = (uint8_t)(data_id >> 8);
    crc = nte_e2e_crc8(id, 2u, 0x00u);
    return nte_e2e_crc8(&frame[1], length - 1u, crc);
}

uint8_t nte_e2e_counter_of(const uint8_t* frame) { return (uint8_t)(frame[1] & 0x0Fu); }

static bool nte_e2e_length_ok(uint8_t length)
{
    return (length >= NTE_E2E_MIN_LENGTH) && (length <= NTE_E2E_MAX_LENGTH);
}

nte_e2e_result_t nte_e2e_tx_init(nte_e2e_tx_t* self, uint16_t data_id, uint8_t length)
{
    if (self == NULL) {
        return nte_e2e_err_null;
    }
    if (!nte_e2e_length_ok(length)) {
        return nte_e2e_err_bad_config;
    }
    self->data_id = data_id;
    self->length = length;
    self->counter = 0u;
    return nte_e2e_ok;
}

nte_e2e_result_t nte_e2e_protect(nte_e2e_tx_t* self, uint8_t* frame, size_t length)
{
    if ((self == NULL) || (frame == NULL)) {
        return nte_e2e_err_null;
    }
    if (length != (size_t)self->length) {
        return nte_e2e_err_wrong_length;
    }
    frame[1] = (uint8_t)((frame[1] & 0xF0u) | (self->counter & 0x0Fu));
    frame[0] = nte_e2e_frame_crc(self->data_id, frame, length);
    self->counter = (uint8_t)((self->counter + 1u) % NTE_E2E_COUNTER_MODULUS);
    return nte_e2e_ok;
}

nte_e2e_result_t nte_e2e_rx_init(nte_e2e_rx_t* self, uint16_t data_id, uint8_t length)
{
    if (self == NULL) {
        return nte_e2e_err_null;
    }
    if (!nte_e2e_length_ok(length)) {
        return nte_e2e_err_bad_config;
    }
    self->data_id = data_id;
    self->length = length;
    self->last_counter = 0u;
    self->synced = false;
    return nte_e2e_ok;
}

void nte_e2e_rx_reset(nte_e2e_rx_t* self)
{
    if (self != NULL) {
        self->synced = false;
        self->last_counter = 0u;
    }
}

nte_e2e_result_t nte_e2e_check(nte_e2e_rx_t* self, const uint8_t* frame, size_t length,
                               uint8_t* lost)
{
    uint8_t counter;
    uint8_t delta;
    if (lost != NULL) {
        *lost = 0u;
    }
    if ((self == NULL) || (frame == NULL)) {
        return nte_e2e_err_null;
    }
    if (length != (size_t)self->length) {
        return nte_e2e_err_wrong_length;
    }
    counter = nte_e2e_counter_of(frame);
    if (counter > NTE_E2E_COUNTER_MAX) {
        return nte_e2e_err_bad_counter;
    }
    if (frame[0] != nte_e2e_frame_crc(self->data_id, frame, length)) {
        return nte_e2e_err_bad_crc;
    }
    if (!self->synced) {
        self->synced = true;
        self->last_counter = counter;
        return nte_e2e_ok;
    }
    delta = (uint8_t)((counter + NTE_E2E_COUNTER_MODULUS - self->last_counter) %
                      NTE_E2E_COUNTER_MODULUS);
    if (delta == 0u) {
        return nte_e2e_err_repeated;
    }
    self->last_counter = counter;
    if (delta == 1u) {
        return nte_e2e_ok;
    }
    if (lost != NULL) {
        *lost = (uint8_t)(delta - 1u);
    }
    return nte_e2e_skipped;
}
