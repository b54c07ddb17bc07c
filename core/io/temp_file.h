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

}  // namespace distband
