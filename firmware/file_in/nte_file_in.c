/* A whole file into memory: see nte_file_in.h. */
#include "nte_file_in.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>

char* nte_file_read_all(const char* path, size_t* len)
{
    *len = 0U;
    FILE* fh = fopen(path, "rb");
    if (fh == NULL) {
        return NULL;
    }
    size_t cap = 65536U;
    size_t n = 0U;
    char* buf = malloc(cap);
    int err = (buf == NULL) ? ENOMEM : 0;
    while (err == 0) {
        /* one byte always kept free for the terminating '\0' */
        if (n + 1U == cap) {
            char* bigger = realloc(buf, cap * 2U);
            if (bigger == NULL) {
                err = ENOMEM;
                break;
            }
            buf = bigger;
            cap *= 2U;
        }
        errno = 0;
        const size_t got = fread(&buf[n], 1U, cap - n - 1U, fh);
        n += got;
        if (got == 0U) {
            /* the end, or an error (reading a directory fails here with EISDIR) */
            if (ferror(fh) != 0) {
                err = (errno != 0) ? errno : EIO;
            }
            break;
        }
    }
    (void)fclose(fh);
    if (err != 0) {
        free(buf);
        errno = err;
        return NULL;
    }
    buf[n] = '\0';
    *len = n;
    return buf;
}
