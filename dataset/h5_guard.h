#pragma once
// libhdf5 (1.10) can crash or loop forever on some corrupt files, inside its own code (global
// heap reads of variable-length strings, for one), where no return code can catch it. Before
// the program first opens a file, a forked child reads all of it with a time limit: through the
// program's own reader where the caller gives one (sequences), else every object, attribute
// and dataset. A child that crashes or overruns the limit marks the file corrupt, and the
// program refuses it with an error naming it instead of crashing or hanging.
// Each file (path, size, modification time) is checked once per process; a file the child
// reads to the end costs one extra read (docs/decisions.md, "Corrupt HDF5 files").
#include <cstdint>
#include <functional>
#include <span>
#include <string>

namespace layersnet::dataset::h5 {

// Seconds the child may take per file before the file counts as hanging libhdf5 (a clean
// 5.5 MB sequence takes about 0.03 s); LAYERSNET_HDF5_GUARD_SECONDS overrides it.
inline constexpr int kGuardSeconds = 20;

// Throws DatasetError(path, "/", ...) when reading `path` crashes or hangs libhdf5. Errors that
// libhdf5 reports normally pass: the caller's own reader reports them with its context.
// Skipped when the environment sets LAYERSNET_TRUST_HDF5=1.
// `read` (run in the child; its exceptions are ignored there) replaces the generic walk.
void guard_file(const std::string& path, const std::function<void()>& read = nullptr);
// The same for an HDF5 file image in memory (`name` is used in messages only).
void guard_image(std::span<const uint8_t> bytes, const std::string& name, const std::function<void()>& read = nullptr);

}  // namespace layersnet::dataset::h5
