/*
 * slcan.c -- see slcan.h.
 */
#include "slcan.h"

#include <string.h>

#include "board.h"

void nte_slcan_init(nte_slcan_t* self) { memset(self, 0, sizeof *self); }

static int hex_val(char c)
{
    if ((c >= '0') && (c <= '9')) {
        return c - '0';
    }
    if ((c >= 'A') && (c <= 'F')) {
        return c - 'A' + 10;
    }
    if ((c >= 'a') && (c <= 'f')) {
        return c - 'a' + 10;
    }
    return -1;
}

/* n hex digits at s -> *out; false if any is not a hex digit */
static bool parse_hex(const char* s, uint32_t n, uint32_t* out)
{
    uint32_t v = 0U;
    for (uint32_t i = 0U; i < n; i++) {
        const int d = hex_val(s[i]);
        if (d < 0) {
            return false;
        }
        v = (v << 4U) | (uint32_t)d;
    }
    *out = v;
    return true;
}

static int parse_frame(const char* line, uint32_t len, nte_node_frame_t* frame)
{
    const char kind = line[0];
    const bool extended = (kind == 'T') || (kind == 'R');
    const bool remote = (kind == 'r') || (kind == 'R');
    const uint32_t id_digits = extended ? 8U : 3U;
    uint32_t id;
    uint32_t dlc;
    if (len < (1U + id_digits + 1U)) {
        return -1;
    }
    if (!parse_hex(&line[1], id_digits, &id) || !parse_hex(&line[1U + id_digits], 1U, &dlc)) {
        return -1;
    }
    if ((dlc > 8U) || (id > (extended ? 0x1FFFFFFFU : 0x7FFU))) {
        return -1;
    }
    const uint32_t data_at = 2U + id_digits;
    if (len != (data_at + (remote ? 0U : (2U * dlc)))) {
        return -1;
    }
    frame->id = id;
    frame->len = (uint8_t)dlc;
    frame->extended = extended;
    frame->remote = remote;
    memset(frame->data, 0, sizeof frame->data);
    if (!remote) {
        for (uint32_t i = 0U; i < dlc; i++) {
            uint32_t b;
            if (!parse_hex(&line[data_at + (2U * i)], 2U, &b)) {
                return -1;
            }
            frame->data[i] = (uint8_t)b;
        }
    }
    return 1;
}

int nte_slcan_parse(nte_slcan_t* self, const char* line, uint32_t len, nte_node_frame_t* frame,
                    char* reply)
{
    reply[0] = '\0';
    if (len == 0U) {
        reply[0] = '\r';
        reply[1] = '\0';
        return 0;
    }
    switch (line[0]) {
    case 't':
    case 'T':
    case 'r':
    case 'R': {
        const int rc = parse_frame(line, len, frame);
        if (rc < 0) {
            reply[0] = '\a';
            reply[1] = '\0';
        }
        return rc;
    }
    case 'O': self->open = true; break;
    case 'C': self->open = false; break;
    case 'S':
    case 's':
    case 'L':
    case 'Z':
    case 'F':
    case 'X':
    case 'M':
    case 'm':
    case 'W': break;
    case 'V': (void)strcpy(reply, "V0100\r"); return 0;
    default:
        reply[0] = '\a';
        reply[1] = '\0';
        return -1;
    }
    reply[0] = '\r';
    reply[1] = '\0';
    return 0;
}

int nte_slcan_receive(void* ctx, nte_node_frame_t* frame)
{
    nte_slcan_t* self = (nte_slcan_t*)ctx;
    uint8_t c;
    while (nte_uart_getc(&c)) {
        if (c == (uint8_t)'\n') {
            continue; /* tolerate CR LF */
        }
        if (c != (uint8_t)'\r') {
            if (self->len < NTE_SLCAN_LINE_MAX) {
                self->line[self->len] = (char)c;
                self->len++;
            } else {
                self->overflow = true;
            }
            continue;
        }
        /* end of line */
        char reply[8];
        int rc;
        if (self->overflow) {
            reply[0] = '\a';
            reply[1] = '\0';
            rc = -1;
        } else {
            rc = nte_slcan_parse(self, self->line, self->len, frame, reply);
        }
        self->len = 0U;
        self->overflow = false;
        if (rc < 0) {
            self->bad_lines++;
        }
        nte_uart_write(reply);
        if (rc == 1) {
            return 1;
        }
    }
    return 0;
}

int nte_slcan_send(void* ctx, const nte_node_frame_t* frame)
{
    static const char HEX[] = "0123456789ABCDEF";
    const nte_slcan_t* self = (const nte_slcan_t*)ctx;
    if (!self->open || frame->extended || frame->remote || (frame->len > 8U)) {
        return -1;
    }
    char out[1U + 3U + 1U + 16U + 2U];
    uint32_t n = 0U;
    out[n++] = 't';
    out[n++] = HEX[(frame->id >> 8U) & 0x7U];
    out[n++] = HEX[(frame->id >> 4U) & 0xFU];
    out[n++] = HEX[frame->id & 0xFU];
    out[n++] = (char)('0' + (char)frame->len);
    for (uint32_t i = 0U; i < frame->len; i++) {
        out[n++] = HEX[(frame->data[i] >> 4U) & 0xFU];
        out[n++] = HEX[frame->data[i] & 0xFU];
    }
    out[n++] = '\r';
    out[n] = '\0';
    nte_uart_write(out);
    return 0;
}
