// The driver of `layersnet generate` (see generate.h).
#include "dataset/generate.h"

#include "dataset/file_io.h"
#include "dataset/manifest.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::dataset {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

json read_json(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw GenerateError(path.string() + ": cannot open (check the path)");
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw GenerateError(path.string() + ": invalid JSON: " + e.what());
  }
}

// Unknown recipe keys are errors (a misspelt key would silently keep a default).
void check_keys(const json& obj, const std::vector<std::string>& known, const std::string& where) {
  if (!obj.is_object()) throw GenerateError(where + ": must be a JSON object");
  for (const auto& [key, value] : obj.items()) {
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      throw GenerateError(where + ": unknown key '" + key + "' (known: " + list + ")");
    }
  }
}

// Single-quoted for /bin/sh.
std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// splitmix64: well-spread per-sequence seeds from (data set seed, index, attempt).
std::uint64_t mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

std::string fmt_duration(double s) {
  char buf[32];
  const int m = static_cast<int>(s) / 60;
  std::snprintf(buf, sizeof(buf), "%d:%02d", m, static_cast<int>(s) - 60 * m);
  return buf;
}

}  // namespace

long long sequence_seed(long long seed, int index, int attempt) {
  const std::uint64_t h = mix(mix(static_cast<std::uint64_t>(seed)) ^ mix(static_cast<std::uint64_t>(index) + 1000003ull * static_cast<std::uint64_t>(attempt)));
  return static_cast<long long>(h & 0x7FFFFFFFull);
}

// Contiguous blocks; see generate.h.
std::vector<std::string> split_names(int count, double val_fraction, double test_fraction) {
  int n_test = static_cast<int>(std::lround(count * test_fraction));
  int n_val = static_cast<int>(std::lround(count * val_fraction));
  if (count >= 3) n_test = std::max(n_test, 1), n_val = std::max(n_val, 1);
  if (count < 3) n_test = n_val = 0;
  std::vector<std::string> out(count, "train");
  for (int i = 0; i < n_test; ++i) out[count - 1 - i] = "test";
  for (int i = 0; i < n_val; ++i) out[count - 1 - n_test - i] = "val";
  return out;
}

// Listed index ranges; see generate.h.
std::vector<std::string> split_names_from_ranges(int count, const json& ranges, const std::string& where) {
  if (!ranges.is_object()) throw GenerateError(where + ": must be an object such as {\"val\": [[36, 40]], \"test\": [[40, 48]]}");
  std::vector<std::string> out(count, "train");
  std::vector<bool> listed(count, false);
  for (const auto& [split, list] : ranges.items()) {
    if (split != "val" && split != "test")
      throw GenerateError(where + ": unknown split '" + split + "' (list val and test; every other index is train)");
    if (!list.is_array()) throw GenerateError(where + "/" + split + ": must be a list of [first, end) index pairs");
    for (const json& range : list) {
      if (!range.is_array() || range.size() != 2 || !range[0].is_number_integer() || !range[1].is_number_integer())
        throw GenerateError(where + "/" + split + ": " + range.dump() + " is not a [first, end) pair of indices");
      const int first = range[0].get<int>(), end = range[1].get<int>();
      if (first < 0 || end > count || first >= end)
        throw GenerateError(where + "/" + split + ": " + range.dump() + " must satisfy 0 <= first < end <= count (" +
                            std::to_string(count) + ")");
      for (int i = first; i < end; ++i) {
        if (listed[i]) throw GenerateError(where + ": index " + std::to_string(i) + " is listed twice");
        listed[i] = true;
        out[i] = split;
      }
    }
  }
  return out;
}

std::vector<std::string> failed_gates(const json& report, const Gates& g) {
  std::vector<std::string> failed;
  if (!report.value("finite", false)) failed.push_back("non-finite positions");
  const json& q = report.at("quality");
  auto check = [&](const char* key, double limit) {
    const double v = q.at(key).get<double>();
    if (!(v <= limit)) {
      std::ostringstream s;
      s << key << " " << v << " > " << limit;
      failed.push_back(s.str());
    }
  };
  check("inside_body_share", g.max_inside_body_share);
  check("outer_inside_inner_share", g.max_outer_inside_inner_share);
  check("max_edge_stretch", g.max_edge_stretch);
  check("p99_edge_stretch", g.max_p99_edge_stretch);
  return failed;
}

std::string generate_report_markdown(const json& rep) {
  std::ostringstream md;
  const json& s = rep.at("summary");
  md << "# Generation report\n\n" << rep.at("source").get<std::string>() << "\n\n";
  md << "accepted " << s.at("accepted") << ", dropped " << s.at("dropped") << ", regenerated "
     << s.at("regenerated") << "; Blender s/frame mean " << s.at("mean_blender_s_per_frame")
     << "; wall time of this run " << s.at("run_seconds") << " s\n\n";
  if (s.contains("kept_blender_job_seconds")) {
    char buf[256];
    std::snprintf(buf, sizeof(buf),
                  "The accepted sequences' Blender jobs, over every run that made them: %.1f h summed over jobs "
                  "(%.1f h of wall time at %d at once), %.1f h of Blender CPU\n\n",
                  s.at("kept_blender_job_seconds").get<double>() / 3600,
                  s.at("kept_blender_job_seconds").get<double>() / 3600 / std::max(1, s.value("jobs", 1)),
                  s.value("jobs", 1), s.at("kept_blender_cpu_seconds").get<double>() / 3600);
    md << buf;
  }
  md << "| id | split | tags | attempts | inside body | outer in inner | max stretch | p99 stretch | "
        "s/frame | body V | cloth V | status |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const json& e : rep.at("sequences")) {
    md << "| " << e.at("id").get<std::string>() << " | " << e.at("split").get<std::string>() << " | ";
    if (e.contains("report")) {
      const json& r = e.at("report");
      const json& q = r.at("quality");
      char buf[256];
      std::snprintf(buf, sizeof(buf), "%s/%s | %d | %.4f | %.4f | %.2f | %.2f | %.3f | %d | %d | ",
                    r.at("tags").at("inner").get<std::string>().c_str(), r.at("tags").at("wind").get<std::string>().c_str(),
                    e.at("attempts").get<int>(), q.at("inside_body_share").get<double>(),
                    q.at("outer_inside_inner_share").get<double>(), q.at("max_edge_stretch").get<double>(),
                    q.at("p99_edge_stretch").get<double>(), r.at("timing").at("blender_s_per_frame").get<double>(),
                    r.at("body_vertices").get<int>(), r.at("cloth_vertices").get<int>());
      md << buf;
    } else {
      md << " | " << e.at("attempts") << " | | | | | | | | ";
    }
    md << e.at("status").get<std::string>() << " |\n";
  }
  std::ostringstream failed;
  for (const json& e : rep.at("sequences"))
    for (const json& r : e.value("reasons", json::array())) failed << "- " << e.at("id").get<std::string>() << ": " << r.get<std::string>() << "\n";
  md << "\n## Failed attempts (regenerated with the next seed, or dropped after max_attempts)\n\n"
     << (failed.str().empty() ? std::string("none\n") : failed.str());
  return md.str();
}

namespace {

// dataset.json of the finished entries (index order): splits, tags, the Table-1 subsets
// (T, T+W, L, L+W) and, for recipes that tag outfits or motions, the named test subsets.
void write_dataset_manifest(const fs::path& out, const std::string& source, const std::vector<json>& entries) {
  DatasetManifest manifest;
  manifest.root = out.string();
  json tags = json::object();
  json subsets = {{"T", json::array()}, {"T+W", json::array()}, {"L", json::array()}, {"L+W", json::array()}};
  bool named = false;
  for (const json& e : entries) {
    if (e.is_null() || !e.contains("report")) continue;
    const std::string id = e.at("id");
    const std::string split = e.at("split");
    (split == "train" ? manifest.train : split == "val" ? manifest.val : manifest.test).push_back(id);
    const json& t = e.at("report").at("tags");
    tags[id] = t;
    const std::string base = t.at("inner") == "tight" ? "T" : "L";
    if (t.at("wind") == "calm") subsets[base].push_back(id);
    if (t.at("wind") == "windy") subsets[base + "+W"].push_back(id);
    if (split == "test" && (t.contains("outfit") || t.contains("motion"))) {
      named = true;
      if (t.value("outfit", std::string("seen")) == "seen") subsets["test_seen_outfit"].push_back(id);
      else subsets["test_unseen_outfit"].push_back(id);
      if (t.at("wind") == "windy") subsets["test_windy"].push_back(id);
      if (t.at("wind") == "calm") subsets["test_calm"].push_back(id);
      if (t.value("motion", std::string()) == "procedural") subsets["test_procedural_motion"].push_back(id);
    }
  }
  manifest.source = source;
  std::string rule =
      "T/L: tight (pants) / loose (skirt, dress, loose trousers) inner layer; +W: max wind strength > 250; "
      "without +W: max wind strength <= 50";
  if (named)
    rule += ". test_seen_outfit: test sequences (motion blocks no other split uses) whose garment kinds all occur in "
            "training; test_unseen_outfit: with a kind held out of training (scene key heldout_kinds); test_windy / "
            "test_calm: max wind strength > 250 / <= 50; test_procedural_motion: with spins, hops or arm swings";
  manifest.extra = {{"tags", tags}, {"subsets", subsets}, {"subset_rule", rule}};
  write_manifest(manifest);
}

}  // namespace

GenerateSummary generate_dataset(const GenerateOptions& opt) {
  const auto t_run = std::chrono::steady_clock::now();
  const fs::path script = opt.script;
  const fs::path recipe_path = opt.recipe;
  json recipe = read_json(recipe_path);
  check_keys(recipe, {"comment", "count", "seed", "val_fraction", "test_fraction", "split_ranges", "max_attempts", "gates",
                      "scene"},
             recipe_path.string());
  if (recipe.contains("split_ranges") && (recipe.contains("val_fraction") || recipe.contains("test_fraction")))
    throw GenerateError(recipe_path.string() + ": split_ranges and val_fraction/test_fraction both set; keep one of them");
  if (recipe.contains("gates"))
    check_keys(recipe["gates"], {"max_inside_body_share", "max_outer_inside_inner_share", "max_edge_stretch",
                                 "max_p99_edge_stretch"}, recipe_path.string() + ": /gates");
  if (opt.jobs < 1) throw GenerateError("--jobs " + std::to_string(opt.jobs) + ": give at least 1 Blender process");
  const int count = opt.count >= 0 ? opt.count : recipe.value("count", 8);
  const long long seed = opt.seed >= 0 ? opt.seed : recipe.value("seed", 1LL);
  const int max_attempts = opt.max_attempts > 0 ? opt.max_attempts : recipe.value("max_attempts", 3);
  json scene = recipe.value("scene", json::object());
  if (opt.frames > 0) scene["frames"] = opt.frames;
  Gates gates;
  if (recipe.contains("gates")) {
    const json& g = recipe["gates"];
    gates.max_inside_body_share = g.value("max_inside_body_share", gates.max_inside_body_share);
    gates.max_outer_inside_inner_share = g.value("max_outer_inside_inner_share", gates.max_outer_inside_inner_share);
    gates.max_edge_stretch = g.value("max_edge_stretch", gates.max_edge_stretch);
    gates.max_p99_edge_stretch = g.value("max_p99_edge_stretch", gates.max_p99_edge_stretch);
  }
  const std::string& checker = opt.checker;

  const fs::path out = opt.out;
  fs::create_directories(out / "reports");
  fs::create_directories(out / "logs");
  const fs::path scene_json = out / "scene.json";
  io::write_file_atomic(scene_json, scene.dump(1));
  const auto splits =
      recipe.contains("split_ranges")
          ? split_names_from_ranges(count, recipe["split_ranges"], recipe_path.string() + ": /split_ranges")
          : split_names(count, recipe.value("val_fraction", 0.125), recipe.value("test_fraction", 0.125));
  std::ostringstream source_text;
  const bool solved = scene.value("cloth", std::string("blender")) == "blender";
  source_text << "layersnet generate: "
              << (solved ? "Blender cloth" : "garments carried by the body, no cloth solver (not simulated cloth)")
              << " (generate/make_sequence.py), recipe " << recipe_path.string()
              << ", seed " << seed << ", count " << count << ", scene " << scene.dump();
  const std::string source = source_text.str();

  // entries[i]: null until sequence i is kept, made or dropped (index order, whatever finishes first).
  std::vector<json> entries(count);
  std::vector<int> todo;
  int accepted = 0, dropped = 0, regenerated = 0, generated_now = 0, finished_now = 0;
  double spent = 0.0, s_per_frame_sum = 0.0;
  auto id_of = [](int i) {
    char idbuf[16];
    std::snprintf(idbuf, sizeof(idbuf), "%05d", i);
    return std::string(idbuf);
  };
  int train_index = -1;
  for (int i = 0; i < count; ++i) {
    const std::string id = id_of(i);
    const fs::path h5 = out / (id + ".h5");
    const fs::path final_report = out / "reports" / (id + ".json");
    if (splits[i] == "train") ++train_index;
    if (fs::exists(h5) && fs::exists(final_report)) {
      json kept = read_json(final_report);
      // Keep it only if it was made for the same data set seed, split and scene settings.
      if (kept.value("accepted", false) && kept.value("dataset_seed", -1LL) == seed &&
          kept.value("split", std::string()) == splits[i] && kept.value("dataset_scene", json()) == scene) {
        entries[i] = {{"id", id}, {"split", splits[i]}, {"attempts", kept.value("attempts", 1)}, {"status", "kept"},
                      {"report", kept}};
        s_per_frame_sum += kept.at("timing").at("blender_s_per_frame").get<double>();
        ++accepted;
        continue;
      }
    }
    if (!opt.only_splits.empty() &&
        std::find(opt.only_splits.begin(), opt.only_splits.end(), splits[i]) == opt.only_splits.end())
      continue;
    if (opt.train_limit >= 0 && splits[i] == "train" && train_index >= opt.train_limit) continue;
    todo.push_back(i);
  }
  std::printf("generate: %d of %d sequences kept (resume), %d to simulate with %d Blender process%s of %d thread%s\n",
              accepted, count, static_cast<int>(todo.size()), opt.jobs, opt.jobs == 1 ? "" : "es", opt.threads,
              opt.threads == 1 ? "" : "s");
  std::fflush(stdout);

  std::mutex mutex;  // guards entries, the counters, stdout and the periodic manifest
  std::atomic<std::size_t> next{0};
  std::atomic<bool> stop{false};
  std::exception_ptr error;
  auto simulate = [&](int i) {
    const std::string id = id_of(i);
    const fs::path h5 = out / (id + ".h5");
    const fs::path final_report = out / "reports" / (id + ".json");
    json entry = {{"id", id}, {"split", splits[i]}};
    std::vector<std::string> reasons;
    bool ok = false;
    int attempt = 0;
    double seconds = 0.0, s_per_frame = 0.0;
    int runs = 0;
    for (; attempt < max_attempts && !ok; ++attempt) {
      const long long sseed = sequence_seed(seed, i, attempt);
      const fs::path rep_path = out / "reports" / (id + ".attempt" + std::to_string(attempt) + ".json");
      const fs::path log = out / "logs" / (id + ".log");
      fs::remove(h5);
      fs::remove(rep_path);
      const std::string cmd = quote(opt.blender) + " -b --factory-startup -t " + std::to_string(opt.threads) +
                              " --python " + quote(script.string()) + " -- --out " + quote(h5.string()) + " --report " +
                              quote(rep_path.string()) + " --seed " + std::to_string(sseed) + " --split " + splits[i] +
                              " --config " + quote(scene_json.string()) + " > " + quote(log.string()) + " 2>&1";
      const auto t0 = std::chrono::steady_clock::now();
      const int rc = std::system(cmd.c_str());
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ++runs;
      if (rc != 0 || !fs::exists(rep_path)) {
        reasons.push_back("attempt " + std::to_string(attempt) + ": Blender failed (exit " + std::to_string(rc) +
                          "), see " + log.string());
        if (rc != 0 && attempt == 0 && !fs::exists(rep_path) &&
            std::system((quote(opt.blender) + " --version > /dev/null 2>&1").c_str()) != 0)
          throw GenerateError("cannot run '" + opt.blender + "': install Blender (scripts/setup.sh) or pass --blender PATH");
        continue;
      }
      json rep = read_json(rep_path);
      std::vector<std::string> failed = failed_gates(rep, gates);
      if (failed.empty() && !checker.empty()) {
        const std::string ccmd = "/usr/bin/python3 " + quote(checker) + " " + quote(h5.string()) + " >> " + quote(log.string()) + " 2>&1";
        if (std::system(ccmd.c_str()) != 0) failed.push_back("check_dlayers_h5.py rejected the file (see " + log.string() + ")");
      }
      rep["attempts"] = attempt + 1;
      rep["dataset_seed"] = seed;
      rep["dataset_scene"] = scene;
      rep["blender_threads"] = opt.threads;  // the solver's trajectory depends on it (re-simulations must match)
      rep["accepted"] = failed.empty();
      rep["failed_gates"] = failed;
      io::write_file_atomic(rep_path, rep.dump(1));
      if (failed.empty()) {
        ok = true;
        io::write_file_atomic(final_report, rep.dump(1));
        entry.update({{"attempts", attempt + 1}, {"status", attempt ? "regenerated" : "generated"}, {"report", rep}});
        s_per_frame = rep.at("timing").at("blender_s_per_frame").get<double>();
      } else {
        std::string why;
        for (const auto& f : failed) why += (why.empty() ? "" : "; ") + f;
        reasons.push_back("attempt " + std::to_string(attempt) + " (seed " + std::to_string(sseed) + "): " + why);
        fs::remove(h5);
      }
    }
    if (!ok) entry.update({{"attempts", attempt}, {"status", "dropped"}});
    entry["reasons"] = reasons;
    entry["blender_seconds"] = seconds;

    std::lock_guard<std::mutex> lock(mutex);
    entries[i] = entry;
    spent += seconds;
    generated_now += runs;
    ++finished_now;
    if (ok) {
      ++accepted;
      s_per_frame_sum += s_per_frame;
      regenerated += attempt > 1;
    } else {
      ++dropped;
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_run).count();
    const int left = static_cast<int>(todo.size()) - finished_now;
    const double eta = wall / finished_now * left;  // wall time per finished sequence at this many jobs
    std::printf("[%d/%d] %s %s %s (%d attempt%s, %.1f s Blender); %d left, ETA %s\n", finished_now,
                static_cast<int>(todo.size()), id.c_str(), splits[i].c_str(), entry["status"].get<std::string>().c_str(),
                attempt, attempt == 1 ? "" : "s", seconds, left, fmt_duration(eta).c_str());
    std::fflush(stdout);
    // An interrupted run leaves a usable dataset.json of what is finished.
    if (opt.manifest_every > 0 && finished_now % opt.manifest_every == 0 && left > 0)
      write_dataset_manifest(out, source, entries);
  };
  auto worker = [&] {
    while (!stop) {
      const std::size_t k = next++;
      if (k >= todo.size()) return;
      try {
        simulate(todo[k]);
      } catch (...) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!error) error = std::current_exception();
        stop = true;
      }
    }
  };
  {
    std::vector<std::thread> pool;
    const int n = std::min<int>(opt.jobs, std::max<int>(1, static_cast<int>(todo.size())));
    for (int j = 0; j < n; ++j) pool.emplace_back(worker);
    for (auto& t : pool) t.join();
  }
  if (error) std::rethrow_exception(error);

  std::vector<json> sequences;
  for (const json& e : entries)
    if (!e.is_null()) sequences.push_back(e);
  write_dataset_manifest(out, source, entries);
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_run).count();
  // What the whole set cost, over every run that made it: each accepted sequence's Blender job
  // (wall and CPU; attempts that failed a gate are not in the reports).
  double kept_job_s = 0, kept_cpu_s = 0;
  for (const json& e : sequences) {
    if (!e.contains("report")) continue;
    const json& timing = e.at("report").at("timing");
    kept_job_s += timing.value("total_s", 0.0);
    kept_cpu_s += timing.value("blender_cpu_s_per_frame", 0.0) * e.at("report").value("frames", 0);
  }
  json report = {{"source", source},
                 {"gates", {{"max_inside_body_share", gates.max_inside_body_share},
                            {"max_outer_inside_inner_share", gates.max_outer_inside_inner_share},
                            {"max_edge_stretch", gates.max_edge_stretch},
                            {"max_p99_edge_stretch", gates.max_p99_edge_stretch}}},
                 {"summary", {{"accepted", accepted}, {"dropped", dropped}, {"regenerated", regenerated},
                              {"blender_runs_this_run", generated_now}, {"blender_seconds_this_run", spent},
                              {"jobs", opt.jobs}, {"threads_per_job", opt.threads},
                              {"run_seconds", run_s},
                              {"mean_blender_s_per_frame", accepted ? s_per_frame_sum / accepted : 0.0},
                              {"kept_blender_job_seconds", kept_job_s}, {"kept_blender_cpu_seconds", kept_cpu_s}}},
                 {"sequences", sequences}};
  io::write_file_atomic(out / "generate_report.json", report.dump(1));
  io::write_file_atomic(out / "generate_report.md", generate_report_markdown(report));
  std::printf("generate: %d accepted, %d dropped, %d regenerated in %s (%.0f s of Blender over %d run%s, %d at once); report %s\n",
              accepted, dropped, regenerated, fmt_duration(run_s).c_str(), spent, generated_now,
              generated_now == 1 ? "" : "s", opt.jobs, (out / "generate_report.md").string().c_str());
  return {accepted, dropped, regenerated};
}


}  // namespace layersnet::dataset
