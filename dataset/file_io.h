#pragma once
// Every file the program writes goes through these two functions, so a full disk, a file-size
// limit or a missing folder is one clear error naming the file and the cause (the operating
// system's own words, e.g. "No space left on device"), and a failed write never leaves a
// truncated file or a stray temporary behind.
#include <filesystem>
#include <string>
#include <string_view>

namespace layersnet::io {

// Writes `bytes` to `path` atomically: PATH.tmp in the same folder, write, fsync, rename, fsync
// of the folder. On failure PATH.tmp is removed and an existing file at `path` is untouched.
// Throws std::runtime_error "PATH: cannot be written: CAUSE (HINT)".
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

// Appends `line` and a newline to `path` (created if missing) with one write(2), so a line
// is never interleaved or half-written unless the disk fills in the middle of it.
void append_line(const std::string& path, std::string_view line);

// The user's next step for a write that failed with `err` (an errno value): "free space on
// the disk", "check the folder's permissions", ... Empty when there is nothing to add.
std::string write_failure_hint(int err);

}  // namespace layersnet::io
