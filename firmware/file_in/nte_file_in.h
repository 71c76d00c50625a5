/*
 * A whole file into memory, for the host programs and the Linux port (nte-run's CSV reader,
 * the configuration file's reader).  The board image has no files and never links this.
 */
#ifndef NTE_FILE_IN_H
#define NTE_FILE_IN_H

#include <stddef.h>

/*
 * The bytes of the file at `path`, followed by one '\0' that `*len` (bytes read) does not
 * count, in a buffer the caller frees; NULL with errno set when the file cannot be opened or
 * read (a directory: EISDIR, as Python's open() reports it) or memory runs out (ENOMEM).
 * A file holding a '\0' is returned whole: strlen(buffer) < *len tells the caller.
 */
char* nte_file_read_all(const char* path, size_t* len);

#endif
