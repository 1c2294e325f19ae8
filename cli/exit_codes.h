#pragma once
// Exit statuses shared by every `layersnet` command; `layersnet --help` and the README list them.
#include <stdexcept>

namespace layersnet::cli {

// Thrown for an argument that parses but cannot work (e.g. a non-positive count); exits with
// kExitUsage before any work starts.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

inline constexpr int kExitOk = 0;
inline constexpr int kExitError = 1;            // bad input or a failed read/write: the message names the file
inline constexpr int kExitUsage = 2;            // bad arguments, before any work (CLI11's parse errors too)
inline constexpr int kExitTrainingStopped = 3;  // `train` stopped itself: losses stayed non-finite
inline constexpr int kExitCheckFailed = 4;      // the command ran and its verdict is "no": a `stress` bound broke

inline constexpr const char* kExitCodesHelp =
    "Exit status: 0 success; 1 error (bad input, unreadable or unwritable file; the message names it); "
    "2 bad arguments; 3 training stopped (non-finite losses); 4 a check failed (a stress run broke its bound).";

}  // namespace layersnet::cli
