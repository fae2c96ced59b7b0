// file_type_name: what a stat()ed path is, in words, for errors that refuse
// anything but a regular file (a FIFO would block a reader, a device never
// ends).
//
// Thread-safety: a pure function.
#pragma once

#include <sys/stat.h>

namespace outcore {

// "a FIFO", "a directory", ... or "a special file"; "a regular file" for one.
inline const char* file_type_name(mode_t mode) {
  if (S_ISREG(mode)) return "a regular file";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISLNK(mode)) return "a symbolic link";
  return "a special file";
}

}  // namespace outcore
