/*
 * libFuzzer harness: the host programs' strict CSV reader (firmware/host/csv_in.c), which takes
 * a path, so the input is written to a private temporary file first.  Then nte_py_repr and
 * nte_central_difference run over what was read.
 * Properties (abort() on violation): the reader returns 0 or -1; on -1 the error text is a
 * terminated, non-empty "PATH:LINE: ..." string and the trial holds no samples; on 0 there is
 * at least one sample, every value is finite, time strictly increases, the velocity column is
 * finite whether given or derived; nte_py_repr of every value parses back to the same double.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "csv_in.h"

static char path[64];

/* A violated property: say which one (file:line), then abort() so libFuzzer keeps the input. */
#define need(ok) need_at((ok) ? 1 : 0, __LINE__)
static void need_at(int ok, int line)
{
    if (!ok) {
        (void)fprintf(stderr, "%s:%d: property violated\n", __FILE__, line);
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (path[0] == '\0') {
        (void)snprintf(path, sizeof path, "/tmp/nte_fuzz_csv_%ld.csv", (long)getpid());
    }
    FILE* fh = fopen(path, "wb");
    need(fh != NULL);
    need(fwrite(data, 1U, size, fh) == size);
    need(fclose(fh) == 0);

    nte_trial_t tr;
    memset(&tr, 0, sizeof tr);
    char err[512];
    memset(err, 0x5A, sizeof err);
    const int r = nte_trial_read(path, &tr, err, sizeof err);
    if (r != 0) {
        need(r == -1);
        need(memchr(err, '\0', sizeof err) != NULL);
        need(strncmp(err, path, strlen(path)) == 0);
        need(err[strlen(path)] == ':');
        need((tr.n == 0U) && (tr.t_s == NULL));
        return 0;
    }
    need(tr.n >= 1U);
    need((tr.t_s != NULL) && (tr.depth_mm != NULL) && (tr.force_n != NULL) &&
         (tr.velocity_mm_s != NULL));
    for (size_t i = 0U; i < tr.n; i++) {
        need(isfinite(tr.t_s[i]) && isfinite(tr.depth_mm[i]) && isfinite(tr.force_n[i]));
        if (tr.velocity_given) {
            need(isfinite(tr.velocity_mm_s[i]));
        }
        if (i > 0U) {
            need(tr.t_s[i] > tr.t_s[i - 1U]);
        }
        char buf[64];
        nte_py_repr(tr.depth_mm[i], buf, sizeof buf);
        const double back = strtod(buf, NULL);
        need(memcmp(&back, &tr.depth_mm[i], sizeof back) == 0);
    }
    if (tr.n >= 2U) {
        double* v = (double*)malloc(tr.n * sizeof(double));
        need(v != NULL);
        nte_central_difference(tr.t_s, tr.depth_mm, tr.n, v);
        free(v);
    }
    nte_trial_free(&tr);
    return 0;
}
