/*
 * Fault injection for the Linux port (LD_PRELOAD): once the file named by the environment
 * variable NTE_ENOBUFS_FILE exists, the next NTE_ENOBUFS_SENDS send() calls on an AF_CAN socket
 * fail with ENOBUFS, as they do when a CAN interface's TX queue is full.  Everything else
 * passes through.  A count, not a time: how many frames a node sends in a second depends on
 * the machine (a loaded one failed 46 sends in the second a test had counted on for > 100).
 */
#include <dlfcn.h>
#include <errno.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <unistd.h>

#ifndef AF_CAN
#define AF_CAN 29
#endif

typedef ssize_t (*send_fn)(int, const void*, size_t, int);

ssize_t send(int fd, const void* buf, size_t len, int flags)
{
    static send_fn real_send = NULL;
    static long failed = 0;
    if (real_send == NULL) {
        real_send = (send_fn)dlsym(RTLD_NEXT, "send");
    }
    const char* flag = getenv("NTE_ENOBUFS_FILE");
    const char* sends = getenv("NTE_ENOBUFS_SENDS");
    const long limit = (sends != NULL) ? strtol(sends, NULL, 10) : 0L;
    if ((flag != NULL) && (failed < limit) && (access(flag, F_OK) == 0)) {
        int domain = 0;
        socklen_t l = sizeof domain;
        if ((getsockopt(fd, SOL_SOCKET, SO_DOMAIN, &domain, &l) == 0) && (domain == AF_CAN)) {
            failed++;
            errno = ENOBUFS;
            return -1;
        }
    }
    return real_send(fd, buf, len, flags);
}
