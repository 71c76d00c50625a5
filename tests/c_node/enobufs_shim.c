/*
 * Fault injection for the Linux port (LD_PRELOAD): while the file named by the environment
 * variable NTE_ENOBUFS_FILE exists, send() on an AF_CAN socket fails with ENOBUFS, as it does
 * when a CAN interface's TX queue is full.  Everything else passes through.
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
    if (real_send == NULL) {
        real_send = (send_fn)dlsym(RTLD_NEXT, "send");
    }
    const char* flag = getenv("NTE_ENOBUFS_FILE");
    if ((flag != NULL) && (access(flag, F_OK) == 0)) {
        int domain = 0;
        socklen_t l = sizeof domain;
        if ((getsockopt(fd, SOL_SOCKET, SO_DOMAIN, &domain, &l) == 0) && (domain == AF_CAN)) {
            errno = ENOBUFS;
            return -1;
        }
    }
    return real_send(fd, buf, len, flags);
}
