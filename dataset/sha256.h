#pragma once
// SHA-256 (FIPS 180-4) of bytes and of files: reports name the exact checkpoint and data set
// manifest behind their figures, so a figure can be traced to the weights that made it.
#include <string>
#include <string_view>

namespace layersnet::io {

// Lower-case hex digest (64 characters) of `bytes`.
std::string sha256_hex(std::string_view bytes);
// The same of a file's contents, read in blocks. Throws std::runtime_error naming the file when
// it cannot be read.
std::string sha256_file(const std::string& path);

}  // namespace layersnet::io
