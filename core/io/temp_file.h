// openTempBeside: the first half of an atomic write — a fresh temporary file next to `path`, opened as a FILE*.
// Contract: on success `*tmp` names the file (path + ".tmp-XXXXXX") and `*file` is open in `mode`; the caller
// writes, closes, and renames it over `path` (or unlinks it on failure). The file gets the permissions a plain
// fopen() would give (0666 minus the umask), not mkstemp's 0600, so the renamed output is readable as usual.
// Returns "" or a message naming `path` and the problem.
#pragma once

#include <cstdio>
#include <string>

namespace distband {

std::string openTempBeside(const std::string& path, const char* mode, std::string* tmp, std::FILE** file);

/// The second half: flushes, syncs and closes `file`, then renames `tmp` over `path`. `error` is what the writer
/// met so far ("" if nothing); on any error the temporary file is removed and the first error returned.
std::string commitTemp(std::FILE* file, const std::string& tmp, const std::string& path, std::string error);

}  // namespace distband
