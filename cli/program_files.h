#pragma once
// Files that ship with the program (scripts, recipes, models), found from where the program
// runs: the source tree above a build folder (build/bin/layersnet), the folder above the
// program, then the working directory.
#include <filesystem>
#include <string>
#include <system_error>

namespace layersnet::cli {

inline std::filesystem::path program_dir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::current_path() : exe.parent_path();
}

// The first existing of <program>/../../REL, <program>/../REL, ./REL; empty when none exists.
inline std::filesystem::path find_program_file(const std::string& relative) {
  const std::filesystem::path dir = program_dir();
  for (const std::filesystem::path& c : {dir / "../.." / relative, dir / ".." / relative,
                                         std::filesystem::current_path() / relative})
    if (std::filesystem::exists(c)) return std::filesystem::weakly_canonical(c);
  return {};
}

}  // namespace layersnet::cli
