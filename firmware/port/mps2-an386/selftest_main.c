/*
 * selftest_main.c -- nte-selftest.elf: runs the self-test (selftest.c) on the board and prints
 * every line through semihosting, then the figures of the run:
 *   "F stack_used=<bytes> stack_size=<bytes> sizeof_nte_t=<bytes>"
 * and exits with SYS_EXIT_EXTENDED: 0 on success, 1 on a library error.
 * The F line is the only one the host twin does not print.
 */
#include "board.h"
#include "selftest.h"

/* Marker functions around every nte_step, for an instruction-counting QEMU plugin:
   never inlined, never removed, no effect. */
void nte_mark_step_begin(void) __attribute__((noinline, used));
void nte_mark_step_end(void) __attribute__((noinline, used));
void nte_mark_step_begin(void) { __asm__ volatile("" ::: "memory"); }
void nte_mark_step_end(void) { __asm__ volatile("" ::: "memory"); }

static void emit_semihost(void* ctx, const char* line)
{
    (void)ctx;
    nte_board_write0(line);
}

static void mark(void* ctx, int begin)
{
    (void)ctx;
    if (begin != 0) {
        nte_mark_step_begin();
    } else {
        nte_mark_step_end();
    }
}

int main(void);
int main(void)
{
    const int rc = nte_selftest_run(emit_semihost, mark, NULL);
    char line[128];
    char* p = nte_selftest_put_str(line, "F stack_used=");
    p = nte_selftest_put_u32(p, nte_board_stack_used());
    p = nte_selftest_put_str(p, " stack_size=");
    p = nte_selftest_put_u32(p, nte_board_stack_size());
    p = nte_selftest_put_str(p, " sizeof_nte_t=");
    p = nte_selftest_put_u32(p, (uint32_t)sizeof(nte_t));
    (void)nte_selftest_put_str(p, "\n");
    nte_board_write0(line);
    if (rc != 0) {
        nte_board_write0("nte-selftest: library error\n");
        return 1;
    }
    return 0;
}
