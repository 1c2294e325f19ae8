#pragma once
// Always-on checks (also in Release): a failed check throws with file:line and a hint,
// because a wrong shape deep in a model is otherwise a silent memory error.
#include <sstream>
#include <stdexcept>
#include <string>

namespace layersnet {

class CheckError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

[[noreturn]] inline void check_failed(const char* file, int line, const char* cond, const std::string& hint) {
  std::ostringstream msg;
  msg << file << ":" << line << ": check failed: " << cond;
  if (!hint.empty()) msg << "\n---> HINT: " << hint;
  throw CheckError(msg.str());
}

}  // namespace layersnet

// LAYERSNET_CHECK(rows == 3, "positions must be (N, 3), got " << rows)
#define LAYERSNET_CHECK(cond, hint_stream)                                   \
  do {                                                                       \
    if (!(cond)) [[unlikely]] {                                              \
      std::ostringstream layersnet_hint_;                                    \
      layersnet_hint_ << hint_stream;                                        \
      ::layersnet::check_failed(__FILE__, __LINE__, #cond, layersnet_hint_.str()); \
    }                                                                        \
  } while (0)
