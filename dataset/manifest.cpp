// dataset.json: parsed with nlohmann::json; every rule of the spec checked with a message
// "dataset.json: /json/pointer: problem".
#include "dataset/manifest.h"

#include "dataset/error.h"
#include "dataset/file_io.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace layersnet::dataset {
namespace fs = std::filesystem;

bool valid_sequence_id(const std::string& id) {
  return !id.empty() && id.find('/') == std::string::npos && id.find('\0') == std::string::npos &&
         id != "." && id != "..";
}

const std::vector<std::string>& DatasetManifest::split(const std::string& name) const {
  if (name == "train") return train;
  if (name == "val") return val;
  if (name == "test") return test;
  throw DatasetError(manifest_path(), "/splits/" + name, "unknown split name (allowed: train, val, test)");
}

std::vector<std::string> DatasetManifest::all_ids() const {
  std::vector<std::string> all = train;
  all.insert(all.end(), val.begin(), val.end());
  all.insert(all.end(), test.begin(), test.end());
  return all;
}

std::string DatasetManifest::sequence_path(const std::string& id) const { return (fs::path(root) / (id + ".h5")).string(); }
std::string DatasetManifest::manifest_path() const { return (fs::path(root) / "dataset.json").string(); }
std::string DatasetManifest::stats_path() const { return (fs::path(root) / "stats.h5").string(); }

DatasetManifest parse_manifest(std::string_view text, const std::string& name) {
  auto fail = [&](const std::string& obj, const std::string& msg) { throw DatasetError(name, obj, msg); };
  nlohmann::json m;
  try {
    m = nlohmann::json::parse(text.begin(), text.end());
  } catch (const nlohmann::json::exception& e) {
    fail("/", std::string("is not valid JSON (") + e.what() + ")");
  }
  if (!m.is_object()) fail("/", "must be a JSON object");
  if (!m.contains("format") || m["format"] != "dlayers-h5")
    fail("/format", "is " + (m.contains("format") ? m["format"].dump() : std::string("missing")) +
                        ", must be 'dlayers-h5'");
  if (!m.contains("version") || !m["version"].is_number_integer() || m["version"] != 1)
    fail("/version", "is " + (m.contains("version") ? m["version"].dump() : std::string("missing")) +
                         ", must be the integer 1");
  if (!m.contains("source") || !m["source"].is_string()) fail("/source", "missing or not a string");
  if (!m.contains("splits") || !m["splits"].is_object()) fail("/splits", "missing or not an object");
  DatasetManifest out;
  out.source = m["source"].get<std::string>();
  for (const auto& [key, value] : m.items())
    if (key != "format" && key != "version" && key != "source" && key != "splits") out.extra[key] = value;
  std::map<std::string, std::string> seen;  // id -> split
  for (const auto& [split, list] : m["splits"].items()) {
    const std::string where = "/splits/" + split;
    if (split != "train" && split != "val" && split != "test")
      fail(where, "unknown split name (allowed: train, val, test)");
    if (!list.is_array()) fail(where, "must be a list of sequence ids");
    std::vector<std::string>& dst = split == "train" ? out.train : split == "val" ? out.val : out.test;
    for (const auto& item : list) {
      if (!item.is_string() || !valid_sequence_id(item.get<std::string>()))
        fail(where, "invalid sequence id " + item.dump());
      const std::string id = item.get<std::string>();
      if (auto it = seen.find(id); it != seen.end())
        fail(where, "sequence id '" + id + "' appears " +
                        (it->second == split ? std::string("twice in this split")
                                             : "also in split '" + it->second + "'"));
      seen[id] = split;
      dst.push_back(id);
    }
  }
  return out;
}

DatasetManifest read_manifest(const std::string& root) {
  const std::string path = (fs::path(root) / "dataset.json").string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw DatasetError(path, "/", "missing dataset.json (is '" + root + "' a data-set folder?)");
  std::stringstream ss;
  ss << in.rdbuf();
  DatasetManifest m = parse_manifest(ss.str(), path);
  m.root = root;
  for (const char* split : {"train", "val", "test"})
    for (const auto& id : m.split(split))
      if (!fs::is_regular_file(m.sequence_path(id)))
        throw DatasetError(path, std::string("/splits/") + split,
                           "sequence '" + id + "': file " + m.sequence_path(id) + " is missing");
  return m;
}

void write_manifest(const DatasetManifest& m) {
  nlohmann::json j = m.extra.is_object() ? m.extra : nlohmann::json::object();
  j["format"] = "dlayers-h5";
  j["version"] = 1;
  j["source"] = m.source;
  j["splits"] = nlohmann::json::object();
  for (const char* split : {"train", "val", "test"}) j["splits"][split] = m.split(split);
  // Round-trip through the parser: the same checks as on read.
  parse_manifest(j.dump(), m.manifest_path());
  fs::create_directories(m.root);
  io::write_file_atomic(m.manifest_path(), j.dump(2) + "\n");
}

}  // namespace layersnet::dataset
