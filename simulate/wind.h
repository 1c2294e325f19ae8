#pragma once
// The text of a user's inputs to simulate: numbers and comma lists of --garment options, and the
// wind, given as "none", "constant:dx,dy,dz,strength" or a CSV file of rows
// "frame,dx,dy,dz,strength" (frames strictly increasing, each row holding until the next; a
// header line and '#' comments allowed). Errors are SimulateError naming the file and line.
#include <Eigen/Core>

#include <string>
#include <vector>

namespace layersnet::eval {

// A finite number, all of `text`; else SimulateError "<what>: '<text>' is not a finite number".
float parse_number(const std::string& text, const std::string& what);
std::vector<std::string> split(const std::string& text, char sep);
std::string trim(const std::string& s);

struct WindRow {
  int frame;                  // body frame from which the row holds
  Eigen::Vector3f direction;  // in the input axes, any length (0 only with strength 0)
  float strength;             // as D-LAYERS' Blender wind field, >= 0
};

// The --wind specification read and checked; empty for "none".
std::vector<WindRow> read_wind(const std::string& spec);

}  // namespace layersnet::eval
