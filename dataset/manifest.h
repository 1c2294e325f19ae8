#pragma once
// A data-set folder (spec "Layout of a data set"): <root>/dataset.json lists the sequence
// ids per split; <root>/<id>.h5 are the sequences; <root>/stats.h5 the statistics.
#include <nlohmann/json.hpp>

#include <string>
#include <string_view>
#include <vector>

namespace layersnet::dataset {

struct DatasetManifest {
  std::string root;    // folder holding dataset.json
  std::string source;  // free text: who wrote the data and how
  std::vector<std::string> train, val, test;  // sequence ids; each id in at most one split
  // Other top-level keys, kept as written (e.g. the tags and Table-1 subsets of `layersnet
  // generate`); an object.
  nlohmann::json extra = nlohmann::json::object();

  // "train" | "val" | "test"; throws DatasetError for any other name.
  const std::vector<std::string>& split(const std::string& name) const;
  std::vector<std::string> all_ids() const;  // train, then val, then test
  std::string sequence_path(const std::string& id) const;  // <root>/<id>.h5
  std::string manifest_path() const;                     // <root>/dataset.json
  std::string stats_path() const;                        // <root>/stats.h5
};

// Parses and checks dataset.json text (format, integer version 1, source string, split
// names, valid unique ids). `name` is used in messages. Does not touch the file system.
DatasetManifest parse_manifest(std::string_view json_text, const std::string& name);
// Reads <root>/dataset.json and checks that every listed sequence file exists.
DatasetManifest read_manifest(const std::string& root);
// Writes <root>/dataset.json (creating root if needed) with the extra keys. Checks ids first.
void write_manifest(const DatasetManifest& manifest);

// A sequence id is a non-empty file-name stem without '/', not "." or "..".
bool valid_sequence_id(const std::string& id);

}  // namespace layersnet::dataset
