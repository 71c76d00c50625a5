/*
 * selftest_host.c -- the host twin of nte-selftest.elf: the same scenario through the host's
 * float build, printing the same lines to stdout.  Exit status 0, or 1 on a library error.
 */
#include <stdio.h>

#include "selftest.h"

static void emit_stdout(void* ctx, const char* line)
{
    (void)ctx;
    (void)fputs(line, stdout);
}

int main(void)
{
    const int rc = nte_selftest_run(emit_stdout, NULL, NULL);
    if (rc != 0) {
        (void)fprintf(stderr, "nte-selftest-host: library error %d\n", rc);
        return 1;
    }
    return 0;
}
