/*
 * nte_port_log.c -- the node's port over candump log files (see nte_port_log.h).
 */
#include "nte_port_log.h"

#include <string.h>

static int hexval(char c)
{
    if ((c >= '0') && (c <= '9')) {
        return c - '0';
    }
    if ((c >= 'a') && (c <= 'f')) {
        return c - 'a' + 10;
    }
    if ((c >= 'A') && (c <= 'F')) {
        return c - 'A' + 10;
    }
    return -1;
}

/* Parse "(SEC.USEC) IFACE ID#DATA"; 1 = a frame, 0 = not a frame line. */
static int parse_line(const char* s, uint64_t* t_us, nte_node_frame_t* f)
{
    uint64_t sec = 0u;
    uint64_t usec = 0u;
    int digits = 0;
    if (*s++ != '(') {
        return 0;
    }
    while ((*s >= '0') && (*s <= '9')) {
        sec = (sec * 10u) + (uint64_t)(*s++ - '0');
    }
    if (*s++ != '.') {
        return 0;
    }
    while ((*s >= '0') && (*s <= '9') && (digits < 6)) {
        usec = (usec * 10u) + (uint64_t)(*s++ - '0');
        digits++;
    }
    while (digits < 6) {
        usec *= 10u;
        digits++;
    }
    while ((*s >= '0') && (*s <= '9')) {
        s++;
    }
    if ((*s++ != ')') || (*s++ != ' ')) {
        return 0;
    }
    while ((*s != ' ') && (*s != '\0')) {
        s++;
    }
    if (*s++ != ' ') {
        return 0;
    }
    uint32_t id = 0u;
    int n = 0;
    while (hexval(*s) >= 0) {
        id = (id << 4) | (uint32_t)hexval(*s++);
        n++;
    }
    if (((n != 3) && (n != 8)) || (*s++ != '#')) {
        return 0;
    }
    (void)memset(f, 0, sizeof *f);
    f->id = id;
    f->extended = (n == 8);
    if (*s == 'R') {
        f->remote = true;
        return 1;
    }
    while ((hexval(s[0]) >= 0) && (hexval(s[1]) >= 0)) {
        if (f->len >= 8u) {
            return 0;
        }
        f->data[f->len++] = (uint8_t)((hexval(s[0]) << 4) | hexval(s[1]));
        s += 2;
    }
    /* the end of the line, or a direction flag after a space (" T" / " R", python-can) */
    if ((*s != '\0') && (*s != '\n') && (*s != '\r') && (*s != ' ')) {
        return 0;
    }
    *t_us = (sec * 1000000u) + usec;
    return 1;
}

static int log_receive(void* ctx, nte_node_frame_t* frame)
{
    nte_port_log_t* self = (nte_port_log_t*)ctx;
    char line[256];
    while (self->eof == 0) {
        uint64_t t = 0u;
        if (fgets(line, (int)sizeof line, self->in) == NULL) {
            self->eof = 1;
            break;
        }
        if (parse_line(line, &t, frame) == 1) {
            if (t > self->now_us) {
                self->now_us = t; /* the clock never goes backwards */
            }
            self->frames_in++;
            return 1;
        }
        if ((line[0] != '\n') && (line[0] != '\0')) {
            self->lines_bad++;
        }
    }
    return 0;
}

static int log_send(void* ctx, const nte_node_frame_t* frame)
{
    nte_port_log_t* self = (nte_port_log_t*)ctx;
    self->frames_out++;
    if (self->out == NULL) {
        return 0;
    }
    (void)fprintf(self->out, "(%llu.%06llu) %s %03X#",
                  (unsigned long long)(self->now_us / 1000000u),
                  (unsigned long long)(self->now_us % 1000000u), self->iface, (unsigned)frame->id);
    for (uint32_t i = 0u; (i < frame->len) && (i < 8u); i++) {
        (void)fprintf(self->out, "%02X", (unsigned)frame->data[i]);
    }
    (void)fputc('\n', self->out);
    return 0;
}

static uint64_t log_now(void* ctx) { return ((const nte_port_log_t*)ctx)->now_us; }

nte_node_port_t nte_port_log_port(nte_port_log_t* self)
{
    nte_node_port_t p = {self, log_receive, log_send, log_now};
    return p;
}
