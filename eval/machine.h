#pragma once
// What the reports and benchmarks share about the machine they run on: gnuplot (every PNG
// plot), the load average (context for speed figures on a shared machine), and the median of
// timings.
#include <filesystem>
#include <string>
#include <vector>

namespace layersnet::eval {

// True when a `gnuplot` is on the PATH.
bool gnuplot_available();
// Runs gnuplot on `script` with its output in `log`; false when gnuplot failed.
bool run_gnuplot(const std::filesystem::path& script, const std::filesystem::path& log);

// The three load averages of /proc/loadavg as written there ("0.52 0.58 0.59"); empty when
// unreadable.
std::string load_averages();
// The 1-minute load average; -1 when unreadable.
double load_average_1min();

// Median of timings: the upper of the two middle values for an even count; 0 for none.
double median(std::vector<double> values);

}  // namespace layersnet::eval
