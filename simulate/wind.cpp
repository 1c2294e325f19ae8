// The text of a user's inputs: numbers, lists, and the wind CSV (see wind.h).
#include "simulate/wind.h"

#include "simulate/simulate.h"

#include <cmath>
#include <fstream>
#include <sstream>

namespace layersnet::eval {

float parse_number(const std::string& text, const std::string& what) {
  try {
    size_t used = 0;
    const float v = std::stof(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  throw SimulateError(what + ": '" + text + "' is not a finite number");
}

std::vector<std::string> split(const std::string& text, char sep) {
  std::vector<std::string> parts;
  std::stringstream s(text);
  std::string part;
  while (std::getline(s, part, sep)) parts.push_back(part);
  return parts;
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return {};
  return s.substr(b, s.find_last_not_of(" \t\r\n") + 1 - b);
}

namespace {

WindRow wind_row(const std::vector<std::string>& cells, const std::string& where) {
  WindRow r{};
  const float frame = parse_number(trim(cells[0]), where + ": frame");
  if (frame < 0 || frame != std::floor(frame) || frame > 1e7f)
    throw SimulateError(where + ": the frame must be a whole number from 0 to 10,000,000");
  r.frame = static_cast<int>(frame);
  for (int c = 0; c < 3; ++c) r.direction[c] = parse_number(trim(cells[1 + c]), where + ": direction");
  r.strength = parse_number(trim(cells[4]), where + ": strength");
  if (r.strength < 0) throw SimulateError(where + ": the strength must be >= 0");
  if (!std::isfinite(r.direction.norm()))
    throw SimulateError(where + ": the direction is too long to normalise; give it in ordinary units (e.g. 1,0,0)");
  if (r.strength > 0 && r.direction.norm() == 0)
    throw SimulateError(where + ": the direction (0, 0, 0) has no way to blow; give dx,dy,dz or strength 0");
  return r;
}

}  // namespace

std::vector<WindRow> read_wind(const std::string& spec) {
  if (spec.empty() || spec == "none") return {};
  if (spec.rfind("constant:", 0) == 0) {
    const auto cells = split(spec.substr(9), ',');
    if (cells.size() != 4)
      throw SimulateError("--wind " + spec + ": use constant:dx,dy,dz,strength, e.g. constant:1,0,0,400");
    return {wind_row({"0", cells[0], cells[1], cells[2], cells[3]}, "--wind " + spec)};
  }
  std::ifstream in(spec);
  if (!in) throw SimulateError(spec + ": the wind CSV cannot be opened (--wind is none, constant:dx,dy,dz,strength or a CSV file)");
  std::vector<WindRow> rows;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    line = trim(line);
    if (line.empty() || line[0] == '#') continue;
    const auto cells = split(line, ',');
    const std::string where = spec + ": line " + std::to_string(line_no);
    const bool header = rows.empty() && line_no == 1 && !cells.empty() &&
                        trim(cells[0]).find_first_of("0123456789") == std::string::npos;
    if (header) continue;
    if (cells.size() != 5) throw SimulateError(where + ": expected 5 columns frame,dx,dy,dz,strength");
    WindRow r = wind_row(cells, where);
    if (!rows.empty() && r.frame <= rows.back().frame)
      throw SimulateError(where + ": frame " + std::to_string(r.frame) + " after frame " +
                          std::to_string(rows.back().frame) + ": frames must increase from row to row; sort the rows");
    rows.push_back(r);
  }
  if (rows.empty())
    throw SimulateError(spec + ": the wind CSV has no rows; give rows 'frame,dx,dy,dz,strength' or use --wind none");
  return rows;
}

}  // namespace layersnet::eval
