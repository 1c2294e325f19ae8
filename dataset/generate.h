#pragma once
// The driver of `layersnet generate`: makes a D-LAYERS-like data set with Blender's cloth solver.
//
// For each sequence id it runs a headless Blender process (`jobs` of them at once) on
// generate/make_sequence.py (which writes <id>.h5 and a JSON report), applies the quality
// gates to the report, regenerates a failing sequence with another seed (up to
// max_attempts) or drops it, validates accepted files with the D-LAYERS-H5 checker when one
// is given, and writes dataset.json (train/val/test + T/T+W/L/L+W subsets, write_manifest)
// and generate_report.{json,md}. Existing accepted sequences are kept (resume); a sequence
// interrupted mid-way is simulated again. dataset.json is also rewritten every
// `manifest_every` finished sequences, so an interrupted run leaves a usable manifest.
//
// Recipe (JSON; the options override it): see generate/recipes/default.json.
#include <nlohmann/json.hpp>

#include <stdexcept>
#include <string>
#include <vector>

namespace layersnet::dataset {

class GenerateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct GenerateOptions {
  std::string out;
  std::string recipe;   // recipe JSON
  std::string script;   // generate/make_sequence.py
  std::string checker;  // validator run on each accepted file (check_dlayers_h5.py); empty: none
  int count = -1;       // -1: from the recipe
  int frames = -1;
  long long seed = -1;
  int max_attempts = -1;
  int threads = 2;      // Blender threads per process
  int jobs = 1;         // Blender processes at once (each sequence's result does not depend on it)
  int manifest_every = 4;  // rewrite dataset.json after every this many finished sequences (0: only at the end)
  std::string blender = "blender";
  // Simulate only the sequences of these splits (empty: all). Sequences of other splits that
  // already exist are kept; the others are left out of the manifest until a later run makes them.
  std::vector<std::string> only_splits;
  // Simulate only the training sequences among the first this many of the training split (by
  // index; -1: all), so that a model trained on a split's first part can be made again without the rest.
  int train_limit = -1;
};

// Quality thresholds; why these values: generate/README.md ("Quality gates").
struct Gates {
  double max_inside_body_share = 0.02;
  double max_outer_inside_inner_share = 0.06;
  double max_edge_stretch = 8.0;
  double max_p99_edge_stretch = 1.0;
};

struct GenerateSummary {
  int accepted = 0, dropped = 0, regenerated = 0;
};

// Runs the whole driver (progress on stdout). Throws GenerateError for a bad recipe or a
// Blender that cannot run at all.
GenerateSummary generate_dataset(const GenerateOptions& options);

// The parts, for tests.
// Split of each index: contiguous blocks (train, then val, then test); at least one val and
// one test from 3 sequences on.
std::vector<std::string> split_names(int count, double val_fraction, double test_fraction);
// Split of each index from a recipe's "split_ranges": {"val": [[first, end), ...], "test": [...]};
// every index not listed is train. A set can so grow its training split while its val and test
// sequences keep their indices, hence their seeds and files. Throws GenerateError naming `where`
// for an unknown split, a bad or out-of-range pair, or an index listed twice.
std::vector<std::string> split_names_from_ranges(int count, const nlohmann::json& ranges, const std::string& where);
// The failed gates of a make_sequence.py report (empty: accepted).
std::vector<std::string> failed_gates(const nlohmann::json& report, const Gates& gates);
// Well-spread seed of a sequence from (data set seed, index, attempt).
long long sequence_seed(long long seed, int index, int attempt);
// generate_report.md from generate_report.json.
std::string generate_report_markdown(const nlohmann::json& report);

}  // namespace layersnet::dataset
