/*
 * selftest.h -- the board self-test, shared by the M4 image and its host twin.
 *
 * nte_selftest_run() runs the float library over the built-in scenario (scenario.h, generated
 * from the Python reference by gen_scenario.py) in five configurations (Model I bank, Model II
 * bank rotating, Model II robust, Model II bank with every filter every sample, Model III bank)
 * and hands every output to `emit` as one text line: reals as the hex bits of their IEEE-754
 * float32 pattern, so the board and the host must print the same bytes.  No printf, no double,
 * no allocation.
 * A run whose refinement is still being sliced when the scenario ends goes on with its last
 * row held (time advancing by the last interval) until the refinement is adopted, at most
 * NTE_SELFTEST_REST_MAX samples more: the robust run's lines are the scenario's and those.
 */
#ifndef NTE_SELFTEST_H
#define NTE_SELFTEST_H

#include <stdint.h>

#include "nte.h"

/** Samples a run may go on past the scenario while its refinement is sliced (the default
 * refinement takes 1 710). */
#define NTE_SELFTEST_REST_MAX 4096U

/** Receives one line (NUL-terminated, ending with '\n'). */
typedef void (*nte_selftest_emit_t)(void* ctx, const char* line);

/** Called around every nte_step (may be NULL): marks for instruction counters. */
typedef void (*nte_selftest_mark_t)(void* ctx, int begin);

/** Runs every configuration; returns 0, or the first negative nte_err_t from nte_init/step. */
int nte_selftest_run(nte_selftest_emit_t emit, nte_selftest_mark_t mark, void* ctx);

/** Formatting helpers (shared with the board's figures lines). */
char* nte_selftest_put_str(char* p, const char* s);
char* nte_selftest_put_hex32(char* p, uint32_t v);
char* nte_selftest_put_u32(char* p, uint32_t v);

#endif /* NTE_SELFTEST_H */
