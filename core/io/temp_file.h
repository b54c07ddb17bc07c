// openTempBeside: the first half of an atomic write — a fresh temporary file next to `path`, opened as a FILE*.
// Contract: on success `*tmp` names the file (path + ".tmp-XXXXXX") and `*file` is open in `mode`; the caller
// writes, closes, and renames it over `path` (or unlinks it on failure). The file gets the permissions a plain
// fopen() would give (0666 minus the umask), not mkstemp's 0600, so the renamed output is readable as usual.
// Returns OK, or kIoError with a message naming `path` and the OS's reason (a missing or unwritable directory, a
// full disk: the OS could not create the file).
#pragma once

#include <cstdio>
#include <string>

#include "core/status.h"

namespace distband {

Status openTempBeside(const std::string& path, const char* mode, std::string* tmp, std::FILE** file);

/// The second half: flushes, syncs and closes `file`, then renames `tmp` over `path`. `error` is what the writer
/// met so far (OK if nothing). On any error the temporary file is removed and the first error is returned: `error`
/// itself with its code, or kIoError naming the file when the flush, sync, close or rename fails.
Status commitTemp(std::FILE* file, const std::string& tmp, const std::string& path, Status error);

}  // namespace distband
