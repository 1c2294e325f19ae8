#pragma once
// The one exception type of the data layer. Its message always reads
//   "<file>: <object path>: <what is wrong>"
// (the same shape as the format's validator check_dlayers_h5.py) so that a user can go straight
// to the offending file and HDF5 object.
#include <stdexcept>
#include <string>

namespace layersnet::dataset {

class DatasetError : public std::runtime_error {
 public:
  DatasetError(std::string file, std::string object, std::string problem)
      : std::runtime_error(file + ": " + object + ": " + problem),
        file_(std::move(file)),
        object_(std::move(object)),
        problem_(std::move(problem)) {}
  const std::string& file() const { return file_; }
  const std::string& object() const { return object_; }
  const std::string& problem() const { return problem_; }

 private:
  std::string file_, object_, problem_;
};

}  // namespace layersnet::dataset
