#include "eval/machine.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>

namespace layersnet::eval {

bool gnuplot_available() { return std::system("command -v gnuplot >/dev/null 2>&1") == 0; }

bool run_gnuplot(const std::filesystem::path& script, const std::filesystem::path& log) {
  const std::string cmd = "gnuplot '" + script.string() + "' > '" + log.string() + "' 2>&1";
  return std::system(cmd.c_str()) == 0;
}

std::string load_averages() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

double load_average_1min() {
  std::ifstream in("/proc/loadavg");
  double a = -1;
  in >> a;
  return a;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace layersnet::eval
