#pragma once
// Files that ship with the program (scripts, recipes, configs, the shipped model) live in
// <program>/../share/layersnet: an install prefix holds copies there (cmake --install), every
// build tree links there to its sources (CMakeLists.txt). So the one lookup works wherever the
// build or the install sits; the working directory is the last resort.
#include <filesystem>
#include <string>
#include <system_error>

namespace layersnet::cli {

inline std::filesystem::path program_dir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::current_path() : exe.parent_path();
}

inline std::filesystem::path program_files_dir() {
  return (program_dir() / ".." / "share" / "layersnet").lexically_normal();
}

// The first existing of <program>/../share/layersnet/REL, ./REL; empty when neither exists.
inline std::filesystem::path find_program_file(const std::string& relative) {
  for (const std::filesystem::path& c : {program_files_dir() / relative, std::filesystem::current_path() / relative})
    if (std::filesystem::exists(c)) return std::filesystem::weakly_canonical(c);
  return {};
}

// A file the user named: as given when it exists (or is absolute), else the program's own
// copy of that relative path (e.g. configs/default.toml from any folder); unchanged when
// neither exists, so the error names what the user typed.
inline std::string resolve_user_file(const std::string& given) {
  const std::filesystem::path p(given);
  if (given.empty() || p.is_absolute() || std::filesystem::exists(p)) return given;
  const std::filesystem::path own = program_files_dir() / p;
  return std::filesystem::exists(own) ? std::filesystem::weakly_canonical(own).string() : given;
}

}  // namespace layersnet::cli
