// The sweep of `layersnet bench trade` (see trade.h).
#include "bench/trade.h"

#include "dataset/file_io.h"
#include "eval/machine.h"
#include "bench/pareto.h"
#include "model/params_layout.h"
#include "run/config.h"

#include <nlohmann/json.hpp>
#include <sys/resource.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

namespace layersnet::eval {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

// Width keeps the official proportions (encoder FFN, decoder MLP): FFN hidden = 2·width,
// decoder MLP = its input width 12 + 2·width. Heads (8) divide every width here.
TradeVariant width_variant(int w) {
  return {"width_" + std::to_string(w), "model.width", std::to_string(w),
          {"model.width=" + std::to_string(w), "model.ffn_width=" + std::to_string(2 * w),
           "model.decoder_width=" + std::to_string(12 + 2 * w)}};
}

TradeVariant one_key(const std::string& name, const std::string& key, const std::string& value) {
  return {name, key, value, {key + "=" + value}};
}

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}


// The last non-empty line of a log (progress of a running child).
std::string last_line(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return "";
  in.seekg(0, std::ios::end);
  const auto size = static_cast<std::streamoff>(in.tellg());
  in.seekg(std::max<std::streamoff>(0, size - 4096));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  const auto nl = text.find_last_of("\n\r");
  return nl == std::string::npos ? text : text.substr(nl + 1);
}

struct ChildResult {
  int exit_code = -1;
  double wall_s = 0, peak_mb = 0;  // peak = the child's ru_maxrss
};

// fork + exec of the program with `args`, stdout and stderr to `log`; prints the log's last
// line every minute so a long training shows progress.
ChildResult run_child(const std::string& exe, const std::vector<std::string>& args, const fs::path& log,
                      const std::string& label) {
  std::vector<char*> argv;
  char name[] = "layersnet";
  argv.push_back(name);
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::fflush(stdout);
  const auto t0 = Clock::now();
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("bench trade: fork failed for " + label);
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  ChildResult r;
  int status = 0;
  struct rusage ru {};
  auto last_print = Clock::now();
  for (;;) {
    const pid_t w = wait4(pid, &status, WNOHANG, &ru);
    if (w == pid) break;
    if (w < 0) throw std::runtime_error("bench trade: wait4 failed for " + label);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    if (Clock::now() - last_print > std::chrono::seconds(60)) {
      last_print = Clock::now();
      std::printf("      %s (%.0f s): %s\n", label.c_str(), std::chrono::duration<double>(Clock::now() - t0).count(),
                  last_line(log).substr(0, 150).c_str());
      std::fflush(stdout);
    }
  }
  r.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  r.peak_mb = static_cast<double>(ru.ru_maxrss) / 1024.0;  // Linux: kilobytes
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  return r;
}

// Training throughput and updates from the run's metrics.jsonl: the last "stop" event with
// a rate (a resumed run that had nothing left to do logs 0).
void read_train_metrics(const fs::path& run, json& train) {
  std::ifstream in(run / "metrics.jsonl");
  std::string line;
  while (std::getline(in, line)) {
    const json e = json::parse(line, nullptr, false);
    if (e.is_discarded() || e.value("event", "") != "stop") continue;
    train["updates"] = e.value("updates", 0);
    train["epochs"] = e.value("epoch", 0);
    if (e.value("samples_per_s", 0.0) > 0) train["samples_per_s"] = e["samples_per_s"];
  }
}

// The model row of an eval.json, flattened into the numbers the table needs.
json read_eval(const fs::path& eval_json) {
  const json j = json::parse(slurp(eval_json));
  json m;
  for (const auto& method : j.at("methods"))
    if (method.value("kind", "") == "model") {
      m = method;
      break;
    }
  if (m.is_null()) throw std::runtime_error(eval_json.string() + ": no model row (kind \"model\"); rerun the eval");
  const json& s = m.at("summary");
  auto mean = [&](const char* k) { return s.contains(k) ? s[k].value("mean", NAN) : NAN; };
  json r = {{"error_mm", mean("error_mm")}, {"error_mm_std", s.contains("error_mm") ? s["error_mm"].value("std", NAN) : NAN},
            {"h_collision_percent", mean("h_collision_percent")},
            {"l_collision_outer_percent", mean("l_collision_outer_percent")},
            {"l_collision_near_percent", mean("l_collision_near_percent")},
            {"ms_per_frame_1thread", m.value("ms_per_frame_1thread", NAN)},
            {"ms_per_frame_2threads", m.value("ms_per_frame_2threads", NAN)},
            {"diverged_sequences", m.value("diverged_sequences", 0)}, {"sequences", m["sequences"].size()},
            {"load_average_1min", j["speed"].value("load_average_1min", -1.0)}, {"name", m.value("name", "")}};
  for (const auto& method : j.at("methods"))
    if (method.value("kind", "") == "baseline")
      r["baselines"][method.value("name", "")] = method["summary"]["error_mm"].value("mean", NAN);
  // A diverged rollout is left out of the mean; a variant with one is not comparable.
  if (r["diverged_sequences"].get<int>() > 0) r["error_mm"] = NAN;
  return r;
}

double num(const json& j, const char* k) {
  return j.contains(k) && j[k].is_number() ? j[k].get<double>() : NAN;
}

std::string cell(double v, const char* f) { return std::isfinite(v) ? fmt(f, v) : "–"; }

// Progress line: "[3/12] width_256 ..." with a rough ETA (mean of the variants run so far).
void progress(std::size_t i, std::size_t n, const std::string& name, const std::string& what, double spent_s,
              int ran) {
  std::string eta = "ETA unknown";
  if (ran > 0) eta = "ETA ~" + fmt("%.0f", spent_s / ran * static_cast<double>(n - i) / 60.0) + " min";
  std::printf("[%zu/%zu] %s: %s (%s)\n", i + 1, n, name.c_str(), what.c_str(), eta.c_str());
  std::fflush(stdout);
}

// Runs (or reuses) one variant; returns its record (also written to variant.json).
json run_variant(const TradeVariant& v, const TradeOptions& o, const fs::path& out, int budget, double* ran_s) {
  const fs::path dir = out / "variants" / v.name;
  const fs::path record_path = dir / "variant.json";
  json rec = {{"name", v.name}, {"knob", v.knob}, {"value", v.value}, {"sets", v.sets}, {"bf16", v.bf16}};
  if (fs::exists(record_path)) {
    const json old = json::parse(slurp(record_path), nullptr, false);
    if (!old.is_discarded()) rec = old;
  }
  // A record of a smaller budget: continue that training to this budget (exact resume: the
  // same parameters as training this budget from scratch) and evaluate again.
  int had = rec.value("budget_epochs", -1);
  if (had < 0 && fs::exists(dir / "metrics.jsonl")) {  // a record of an older layersnet: ask the run
    json m;
    read_train_metrics(dir, m);
    had = m.value("epochs", budget);
  }
  if (had < 0) had = budget;
  if (had > budget)
    throw std::runtime_error((dir / "variant.json").string() + ": trained for " + std::to_string(had) +
                             " epochs, more than --budget-epochs " + std::to_string(budget) + "; use another --out");
  if (had < budget) {  // (bf16: the default variant's checkpoint changed, evaluate again)
    if (rec.contains("train") && !v.bf16) rec["train_before"] = rec["train"];
    rec.erase("train");
    rec.erase("eval");
    rec.erase("status");
  }
  rec["budget_epochs"] = budget;
  if (rec.contains("eval") && fs::exists(dir / "eval" / "eval.json")) {
    rec["reused"] = true;
    rec["result"] = read_eval(dir / "eval" / "eval.json");
    std::printf("      reused: %s (delete %s to measure again)\n", (dir / "eval" / "eval.json").string().c_str(),
                dir.string().c_str());
    return rec;
  }
  rec["reused"] = false;
  fs::create_directories(dir);
  const auto t0 = Clock::now();
  fs::path run = dir;
  if (v.bf16) {
    run = out / "variants" / "default";
    rec["train"] = {{"note", "no training: the default variant's checkpoint"}};
  } else if (!rec.contains("train")) {
    std::vector<std::string> args;
    if (fs::exists(dir / "config.toml")) {
      // Interrupted earlier, or trained for a smaller budget: continue it.
      args = {"train", "--resume", dir.string(), "--set", "train.epochs=" + std::to_string(budget)};
      rec["train_resumed"] = true;
    } else {
      args = {"train", "--config", o.config, "--set", "train.epochs=" + std::to_string(budget)};
      for (const auto& s : o.overrides) args.insert(args.end(), {"--set", s});
      for (const auto& s : v.sets) args.insert(args.end(), {"--set", s});
      args.insert(args.end(), {"--run", dir.string()});
    }
    std::printf("      train: layersnet");
    for (const auto& a : args) std::printf(" %s", a.c_str());
    std::printf("\n");
    const ChildResult c = run_child(o.program, args, dir / "train.log", v.name + " train");
    json train = {{"wall_s", c.wall_s}, {"peak_mb", c.peak_mb}, {"exit_code", c.exit_code}};
    read_train_metrics(dir, train);
    if (c.exit_code != 0) {
      rec["status"] = "failed";
      rec["message"] = "training exited with " + std::to_string(c.exit_code) + "; see " + (dir / "train.log").string();
      std::printf("      FAILED: %s\n", rec["message"].get<std::string>().c_str());
      layersnet::io::write_file_atomic(record_path, rec.dump(2));  // no "train" key: the next run retries (resumes)
      return rec;
    }
    if (rec.contains("train_before")) {  // the whole training: earlier part + this one
      const json& b = rec["train_before"];
      train["wall_s"] = c.wall_s + num(b, "wall_s");
      train["peak_mb"] = std::max(c.peak_mb, num(b, "peak_mb"));
      train["note"] = "continued from a smaller budget; samples_per_s of the continued part";
    }
    rec["train"] = train;
    layersnet::io::write_file_atomic(record_path, rec.dump(2));
    std::printf("      trained in %.0f s, %.3g samples/s, peak %.0f MB\n", c.wall_s, num(train, "samples_per_s"),
                c.peak_mb);
  }
  std::vector<std::string> args = {"eval", "--run", run.string(), "--out", (dir / "eval").string()};
  if (v.bf16) args.insert(args.end(), {"--precision", "bf16"});
  if (o.frames > 0) args.insert(args.end(), {"--frames", std::to_string(o.frames)});
  if (o.speed_frames > 0) args.insert(args.end(), {"--speed-frames", std::to_string(o.speed_frames)});
  if (o.max_sequences >= 0) args.insert(args.end(), {"--max-sequences", std::to_string(o.max_sequences)});
  if (o.eval_threads > 0) args.insert(args.end(), {"--threads", std::to_string(o.eval_threads)});
  const ChildResult c = run_child(o.program, args, dir / "eval.log", v.name + " eval");
  rec["eval"] = {{"wall_s", c.wall_s}, {"peak_mb", c.peak_mb}, {"exit_code", c.exit_code}};
  *ran_s += std::chrono::duration<double>(Clock::now() - t0).count();
  if (c.exit_code != 0 || !fs::exists(dir / "eval" / "eval.json")) {
    rec["status"] = "failed";
    rec["message"] = "eval exited with " + std::to_string(c.exit_code) + "; see " + (dir / "eval.log").string();
    rec.erase("eval");
    std::printf("      FAILED: %s\n", rec["message"].get<std::string>().c_str());
    layersnet::io::write_file_atomic(record_path, rec.dump(2));
    return rec;
  }
  rec["status"] = "ok";
  rec.erase("message");
  layersnet::io::write_file_atomic(record_path, rec.dump(2));
  rec["result"] = read_eval(dir / "eval" / "eval.json");
  std::printf("      error %.1f mm, %.3g ms/frame (1 thread), eval %.0f s, peak %.0f MB\n",
              num(rec["result"], "error_mm"), num(rec["result"], "ms_per_frame_1thread"), c.wall_s, c.peak_mb);
  return rec;
}

// "model.width=64" -> section "model", line "width = 64".
std::string preset_toml(const std::string& preset, const json& rec, const std::string& base, const std::string& why) {
  std::ostringstream o;
  o << "# Preset \"" << preset << "\" from `layersnet bench trade` (variant " << rec["name"].get<std::string>()
    << "): " << why << "\n# See eval/README.md, \"Speed against accuracy\".\ninclude = \"" << base << "\"\n";
  std::map<std::string, std::vector<std::string>> sections;
  for (const auto& s : rec["sets"]) {
    const std::string a = s.get<std::string>();
    const auto dot = a.find('.'), eq = a.find('=');
    sections[a.substr(0, dot)].push_back(a.substr(dot + 1, eq - dot - 1) + " = " + a.substr(eq + 1));
  }
  for (const auto& [sec, lines] : sections) {
    o << "[" << sec << "]\n";
    for (const auto& l : lines) o << l << "\n";
  }
  if (rec.value("bf16", false))
    o << "# Inference in bfloat16 matrix products: `layersnet eval --precision bf16` (training stays float32).\n";
  return o.str();
}

std::string plot_trade(const fs::path& out, const std::vector<layersnet::eval::TradePoint>& pts,
                       const std::vector<std::size_t>& front, const std::string& title, const json& baselines) {
  std::ostringstream all, fr;
  double lo = INFINITY, hi = 0;
  for (const auto& p : pts)
    if (layersnet::eval::trade_point_valid(p)) {
      all << fmt("%.6g", p.ms) << "\t" << fmt("%.6g", p.error) << "\t\"" << p.name << "\"\n";
      lo = std::min(lo, p.ms), hi = std::max(hi, p.ms);
    }
  for (std::size_t i : front) fr << fmt("%.6g", pts[i].ms) << "\t" << fmt("%.6g", pts[i].error) << "\n";
  layersnet::io::write_file_atomic(out / "trade_points.dat", all.str());
  layersnet::io::write_file_atomic(out / "trade_front.dat", fr.str());
  std::ostringstream gp;
  gp << "set terminal png size 1000,620\nset output '" << (out / "trade.png").string() << "'\n"
     << "set termoption noenhanced\nset title '" << title << "'\nset ylabel 'rollout error (mm)'\nset grid\nset key top right\n"
     << "set offsets graph 0.08, graph 0.15, graph 0.08, graph 0.08\n";
  // Baselines (no model) as dashed horizontal lines: a variant above them has not learnt much.
  int tag = 1;
  for (const auto& [name, e] : baselines.items()) {
    if (!e.is_number() || !std::isfinite(e.get<double>())) continue;
    const std::string y = fmt("%.6g", e.get<double>());
    gp << "set arrow " << tag << " from graph 0, first " << y << " to graph 1, first " << y
       << " nohead dt 2 lc rgb '#777777'\nset label " << tag << " '" << name << "' at graph 0.01, first " << y
       << " offset 0,0.6 tc rgb '#777777' font ',9'\n";
    ++tag;
  }
  if (hi > 4 * lo) gp << "set logscale x\nset xlabel 'ms per frame, 1 thread (log scale)'\n";
  else gp << "set xlabel 'ms per frame, 1 thread'\n";
  gp << "plot '" << (out / "trade_front.dat").string() << "' using 1:2 with linespoints lw 2 pt 7 ps 2 lc rgb '#d62728' "
     << "title 'Pareto front', '" << (out / "trade_points.dat").string()
     << "' using 1:2 with points pt 7 ps 1.2 lc rgb '#1f77b4' title 'variant', '' using 1:2:3 with labels offset 0.8,0.8 "
        "left font ',9' notitle\n";
  layersnet::io::write_file_atomic(out / "trade.gp", gp.str());
  if (!gnuplot_available()) return "gnuplot not found: no trade.png (apt-get install gnuplot-nox)";
  if (!run_gnuplot(out / "trade.gp", out / "gnuplot.log")) return "gnuplot failed: see " + (out / "gnuplot.log").string();
  return "";
}

std::string keys_of(const json& rec) {
  std::string s;
  const auto add = [&s](const std::string& part) {
    if (!s.empty()) s += ' ';
    s += part;
  };
  for (const auto& k : rec["sets"]) add("--set " + k.get<std::string>());
  if (rec.value("bf16", false)) add("(eval --precision bf16)");
  return s.empty() ? "(the base config itself)" : s;
}

std::string now_utc() {
  const std::time_t t = std::time(nullptr);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%d %H:%M UTC", std::gmtime(&t));
  return b;
}

// trade.md: settings, the table (front marked), the presets and why, caveats.
std::string trade_markdown(const json& t) {
  std::ostringstream o;
  const json& s = t["settings"];
  o << "# Speed against accuracy: `layersnet bench trade`\n\n"
    << "Base config `" << s["config"].get<std::string>() << "` (data `" << s["dataset"].get<std::string>()
    << "`), one knob changed per variant. Budget: **" << s["budget_epochs"].get<int>()
    << " epoch(s)** of training per variant (the same samples for every variant)";
  for (const auto& x : s["overrides"]) o << ", `--set " << x.get<std::string>() << "`";
  o << ". Error: mean vertex error of the " << s["split"].get<std::string>()
    << "-split rollouts (eval/README.md), mm; collision rates in %; ms/frame: median rollout step at 1 / 2 threads. "
    << "Peak memory: the child process's maximum resident set (wait4 ru_maxrss). Started " << s["started"].get<std::string>()
    << ", finished " << t["finished"].get<std::string>() << ", " << fmt("%.1f", t["wall_s"].get<double>() / 60.0)
    << " min wall in this invocation (reused variants keep the times of the run that made them); load average " << s["load_average_start"].get<std::string>() << " at the start, "
    << t["load_average_end"].get<std::string>() << " at the end"
    << " (ms/frame measured on a shared machine are noisy: compare them within one run).";
  if (t.contains("speed"))
    o << " ms/frame: the fastest of " << t["speed"]["passes"].get<int>()
      << " passes that time all variants back to back after the sweep (`speed/`; each variant's own eval ran minutes "
         "apart under a different load: its figure is kept in trade.json as `*_variant_eval`).";
  o << "\n\n";
  o << "| variant | change | params | error mm | H-coll % | L-coll % ÷ outer | L-near % | ms/f 1 thr | ms/f 2 thr | "
       "train samples/s | train s | train peak MB | eval peak MB | front |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& v : t["variants"]) {
    const json r = v.value("result", json::object());
    const json tr = v.value("train", json::object()), ev = v.value("eval", json::object());
    std::string change = v["knob"].get<std::string>().empty() ? "–" : v["knob"].get<std::string>() + " = " + v["value"].get<std::string>();
    o << "| " << v["name"].get<std::string>() << (v.value("reused", false) ? " (reused)" : "") << " | " << change << " | "
      << (v.contains("params") ? fmt("%.3g", v["params"].get<double>()) : "–") << " | ";
    if (v.value("status", "") != "ok" && !v.value("reused", false)) {
      o << v.value("status", "") << ": " << v.value("message", "") << " |||||||||||\n";
      continue;
    }
    o << cell(num(r, "error_mm"), "%.1f") << (std::isfinite(num(r, "error_mm_std")) ? " ± " + fmt("%.1f", num(r, "error_mm_std")) : "")
      << (r.value("diverged_sequences", 0) > 0 ? " (diverged)" : "") << " | " << cell(num(r, "h_collision_percent"), "%.2f")
      << " | " << cell(num(r, "l_collision_outer_percent"), "%.2f") << " | " << cell(num(r, "l_collision_near_percent"), "%.2f")
      << " | " << cell(num(r, "ms_per_frame_1thread"), "%.3g") << " | " << cell(num(r, "ms_per_frame_2threads"), "%.3g")
      << " | " << cell(num(tr, "samples_per_s"), "%.3g") << " | " << cell(num(tr, "wall_s"), "%.3g") << (v.value("train_resumed", false) ? " †" : "") << " | "
      << cell(num(tr, "peak_mb"), "%.0f") << " | " << cell(num(ev, "peak_mb"), "%.0f") << " | "
      << (v.value("on_front", false) ? "**●**" : "") << " |\n";
  }
  o << "\n† training continued with `--resume` (an interrupted run, or a smaller earlier budget extended exactly): "
       "train s is the sum of both parts, samples/s that of the continued part.\n";
  if (t.contains("baselines") && !t["baselines"].empty()) {
    o << "\nBaselines on the same rollouts (no training):";
    for (const auto& [k, e] : t["baselines"].items()) o << " " << k << " " << fmt("%.1f", e.get<double>()) << " mm;";
    o << "\n";
  }
  o << "\n**Pareto front** (● above; lower error and lower ms/frame are both better, a variant is on it when no "
       "other variant is at least as good in both and better in one), by speed:";
  for (const auto& f : t["front"]) o << " `" << f.get<std::string>() << "`";
  o << ". Plot: `trade.png` (x: ms/frame at 1 thread).\n\n## Recommendation (generated from the numbers above)\n\n";
  const json& p = t["presets"];
  if (p.empty()) {
    o << "No variant has a finite error and speed: no recommendation.\n";
    return o.str();
  }
  o << "- **fast** = the fastest front variant whose error is within " << fmt("%.0f", 100 * s["tolerance"].get<double>())
    << " % of the default's; **accurate** = the lowest error; **balanced** = the knee between them: of the front variants from fast to "
       "accurate, the one farthest below the straight line fast–accurate on log–log axes (when none is below it, the "
       "lowest error × ms/frame).\n";
  for (const char* name : {"fast", "balanced", "accurate"}) {
    const json& c = p[name];
    o << "- **" << name << "**: `" << c["variant"].get<std::string>() << "` — " << c["why"].get<std::string>()
      << "; keys: " << c["keys"].get<std::string>() << " → `configs/" << name << ".toml`.\n";
  }
  o << "\nCaveats: one training per variant (no seeds repeated), a short budget, and " << t["sequences"].get<int>()
    << " evaluation sequence(s): differences of a few % in error are within the noise of a single run. "
       "Reproduce: `" << t["command"].get<std::string>() << "`.\n";
  return o.str();
}

// Front, presets, trade.json/md/png over the variants so far; `final` prints the summary.
void write_reports(json& t, const TradeOptions& o, const fs::path& out, int budget, Clock::time_point t0, bool final) {
  // Front and presets over the finished variants.
  std::vector<layersnet::eval::TradePoint> pts;
  int reference = -1;
  for (auto& v : t["variants"]) {
    v["on_front"] = false;
    const json r = v.value("result", json::object());
    if (v["name"] == "default") reference = static_cast<int>(pts.size());
    pts.push_back({v["name"].get<std::string>(), num(r, "ms_per_frame_1thread"), num(r, "error_mm")});
    if (r.contains("baselines") && !t.contains("baselines")) t["baselines"] = r["baselines"];
    t["sequences"] = r.value("sequences", t.value("sequences", 0));
  }
  if (!t.contains("sequences")) t["sequences"] = 0;
  const auto front = layersnet::eval::pareto_front(pts);
  t["front"] = json::array();
  for (std::size_t i : front) {
    t["front"].push_back(pts[i].name);
    t["variants"][i]["on_front"] = true;
  }
  const auto choice = layersnet::eval::choose_presets(pts, reference, o.tolerance);
  t["presets"] = json::object();
  const fs::path presets_dir = out / "presets";
  fs::create_directories(presets_dir);
  const std::string base_name = fs::path(o.config).filename().string();
  for (auto [name, idx] : {std::pair<const char*, int>{"fast", choice.fast}, {"balanced", choice.balanced},
                           {"accurate", choice.accurate}}) {
    if (idx < 0) continue;
    const auto& p = pts[static_cast<std::size_t>(idx)];
    std::string why = fmt("%.3g ms/frame", p.ms) + ", error " + fmt("%.1f mm", p.error);
    if (reference >= 0 && layersnet::eval::trade_point_valid(pts[static_cast<std::size_t>(reference)])) {
      const auto& d = pts[static_cast<std::size_t>(reference)];
      why += " (default: " + fmt("%.3g ms/frame", d.ms) + ", " + fmt("%.1f mm", d.error) + "; speed ×" +
             fmt("%.2f", d.ms / p.ms) + ", error " + fmt("%+.1f %%", 100 * (p.error / d.error - 1)) + ")";
    }
    const json& rec = t["variants"][static_cast<std::size_t>(idx)];
    t["presets"][name] = {{"variant", p.name}, {"why", why}, {"keys", keys_of(rec)}, {"sets", rec["sets"]}};
    const std::string measured = why + "\n# Measured " + now_utc() + ", " + std::to_string(budget) + " epoch(s) per variant: `" +
                                 t["command"].get<std::string>() + "`";
    layersnet::io::write_file_atomic(presets_dir / (std::string(name) + ".toml"), preset_toml(name, rec, base_name, measured));
  }
  t["finished"] = now_utc();
  t["wall_s"] = std::chrono::duration<double>(Clock::now() - t0).count();
  t["load_average_end"] = load_averages();
  const std::string plot_msg = plot_trade(out, pts, front,
                                          "Rollout error against speed, " + std::to_string(budget) + " epoch(s) per variant",
                                          t.value("baselines", json::object()));
  layersnet::io::write_file_atomic(out / "trade.json", t.dump(2));
  std::string md = trade_markdown(t);
  if (!plot_msg.empty()) md += "\n" + plot_msg + "\n";
  layersnet::io::write_file_atomic(out / "trade.md", md);
  if (!final) return;
  std::printf("\n%s\n", md.c_str());
  std::printf("recommended presets (written to %s; copy them to configs/ to ship):\n", presets_dir.string().c_str());
  for (const auto& [name, c] : t["presets"].items())
    std::printf("  %-9s %-11s %s\n", name.c_str(), c["variant"].get<std::string>().c_str(), c["keys"].get<std::string>().c_str());
  std::printf("wrote %s, %s%s in %.1f min\n", (out / "trade.json").string().c_str(), (out / "trade.md").string().c_str(),
              plot_msg.empty() ? (", " + (out / "trade.png").string()).c_str() : "", t["wall_s"].get<double>() / 60.0);
}

// The per-variant evals run minutes apart, and on a shared machine the load changes in
// between (default measured 105 ms/frame, layers_6 with 1.4x its parameters 49). So after the
// sweep all finished variants are timed again back to back, `speed_passes` times (one
// `layersnet eval` child per pass over every float32 variant, one more for bf16, each on
// one sequence), and each variant keeps its fastest pass: the least disturbed measurement.
// Cached in OUT/speed/speed.json while the variants, budget and passes stay the same.
void speed_passes(json& t, const TradeOptions& o, const fs::path& out, int budget) {
  std::vector<std::string> names;
  std::vector<std::size_t> idx;
  std::size_t bf16 = SIZE_MAX;
  for (std::size_t i = 0; i < t["variants"].size(); ++i) {
    const json& v = t["variants"][i];
    if (!v.contains("result")) continue;
    if (v.value("bf16", false)) bf16 = i;
    else {
      names.push_back(v["name"].get<std::string>());
      idx.push_back(i);
    }
  }
  if (names.empty()) return;
  const fs::path dir = out / "speed";
  fs::create_directories(dir);
  json key = {{"variants", names}, {"bf16", bf16 != SIZE_MAX}, {"budget_epochs", budget}, {"passes", o.speed_passes},
              {"speed_frames", o.speed_frames}};
  json cache = fs::exists(dir / "speed.json") ? json::parse(slurp(dir / "speed.json"), nullptr, false) : json();
  bool reuse = cache.is_object() && cache.contains("key") && cache["key"] == key;
  for (const auto& v : t["variants"]) reuse = reuse && v.value("reused", false);  // a variant ran again: measure again
  if (!reuse) {
    cache = {{"key", key}, {"ms_1thread", json::object()}, {"ms_2threads", json::object()}};
    for (int p = 0; p < o.speed_passes; ++p) {
      for (int part = 0; part < (bf16 != SIZE_MAX ? 2 : 1); ++part) {
        const fs::path pass = dir / ("pass" + std::to_string(p + 1) + (part ? "_bf16" : ""));
        std::vector<std::string> args = {"eval"};
        const std::vector<std::string> runs = part ? std::vector<std::string>{"default"} : names;
        for (const auto& n : runs) args.insert(args.end(), {"--run", (out / "variants" / n).string()});
        if (part) args.insert(args.end(), {"--precision", "bf16"});
        args.insert(args.end(), {"--max-sequences", "1", "--frames", "1", "--threads", "1", "--out", pass.string()});
        if (o.speed_frames > 0) args.insert(args.end(), {"--speed-frames", std::to_string(o.speed_frames)});
        std::printf("speed pass %d/%d%s: %zu model(s)\n", p + 1, o.speed_passes, part ? " (bf16)" : "", runs.size());
        const ChildResult c = run_child(o.program, args, pass.string() + ".log", "speed pass");
        if (c.exit_code != 0) {
          std::printf("      speed pass failed (exit %d, see %s.log): keeping the per-variant figures\n", c.exit_code,
                      pass.string().c_str());
          return;
        }
        const json j = json::parse(slurp(pass / "eval.json"));
        std::size_t m = 0;
        for (const auto& method : j["methods"]) {
          if (method.value("kind", "") != "model") continue;
          const std::string n = part ? "bf16" : runs.at(m);
          ++m;
          for (const char* k : {"ms_1thread", "ms_2threads"})
            cache[k][n].push_back(method.value(std::string("ms_per_frame_") + (k[3] == '1' ? "1thread" : "2threads"), NAN));
        }
      }
    }
    cache["load_average_end"] = load_averages();
    layersnet::io::write_file_atomic(dir / "speed.json", cache.dump(2));
  } else {
    std::printf("speed: reused %s\n", (dir / "speed.json").string().c_str());
  }
  if (bf16 != SIZE_MAX) idx.push_back(bf16);
  for (std::size_t i : idx) {
    json& r = t["variants"][i]["result"];
    const std::string n = t["variants"][i]["name"];
    for (const char* k : {"ms_1thread", "ms_2threads"}) {
      if (!cache[k].contains(n)) continue;
      double best = INFINITY;
      for (const auto& x : cache[k][n])
        if (x.is_number() && x.get<double>() > 0) best = std::min(best, x.get<double>());
      const std::string field = std::string("ms_per_frame_") + (k[3] == '1' ? "1thread" : "2threads");
      r[field + "_variant_eval"] = r[field];
      r[field] = std::isfinite(best) ? best : NAN;
      r[field + "_passes"] = cache[k][n];
    }
  }
  t["speed"] = {{"passes", o.speed_passes}, {"estimator", "fastest of the back-to-back passes"},
                {"folder", dir.string()}};
}

}  // namespace

// Patch sizes around the default 0.1 (not the official 0.02–0.08): the default garments
// have ≈ 4.5 cm edges, so at 0.04 a patch holds ~1 vertex and the hierarchy is moot.
std::vector<TradeVariant> trade_variants() {
  // Roughly cheapest first, so an interrupted sweep already spans the range.
  return {{"default", "", "", {}},
          width_variant(64),
          one_key("layers_2", "model.layers", "2"),
          one_key("patch_0.2", "model.patch_size", "0.2"),
          one_key("k_8", "model.body_neighbors", "8"),
          one_key("cand_2", "model.decoder_patch_candidates", "2"),
          one_key("cand_8", "model.decoder_patch_candidates", "8"),
          one_key("k_32", "model.body_neighbors", "32"),
          // The official rank-3 decoder RET map against our default 8 channels (model/README.md).
          one_key("dec_ret_1", "model.decoder_ret_channels", "1"),
          one_key("patch_0.05", "model.patch_size", "0.05"),
          one_key("layers_6", "model.layers", "6"),
          width_variant(256),
          {"bf16", "precision", "bf16", {}, true}};
}

void run_trade(const TradeOptions& o) {
  std::vector<TradeVariant> variants = trade_variants();
  if (!o.variants.empty()) {
    std::vector<TradeVariant> chosen;
    for (const auto& n : o.variants) {
      auto it = std::find_if(variants.begin(), variants.end(), [&](const TradeVariant& v) { return v.name == n; });
      if (it == variants.end())
        throw std::runtime_error("bench trade --variants: unknown variant '" + n + "' (see `layersnet bench trade --list`)");
      chosen.push_back(*it);
    }
    // bf16 re-evaluates the default variant's checkpoint: train that first.
    const bool has_bf16 = std::any_of(chosen.begin(), chosen.end(), [](const TradeVariant& v) { return v.bf16; });
    const bool has_default = std::any_of(chosen.begin(), chosen.end(), [](const TradeVariant& v) { return v.name == "default"; });
    if (has_bf16 && !has_default) chosen.insert(chosen.begin(), variants.front());
    std::stable_partition(chosen.begin(), chosen.end(), [](const TradeVariant& v) { return !v.bf16; });
    variants = chosen;
  }
  const layersnet::Config base = layersnet::load_config({o.config}, o.overrides);
  const int budget = o.budget_epochs > 0 ? o.budget_epochs : base.train.epochs;
  const fs::path out(o.out);
  fs::create_directories(out / "variants");
  std::ostringstream cmd;
  cmd << "layersnet bench trade --config " << o.config << " --out " << o.out << " --budget-epochs " << budget;
  for (const auto& s : o.overrides) cmd << " --set " << s;
  if (!o.variants.empty()) {
    cmd << " --variants ";
    for (std::size_t i = 0; i < o.variants.size(); ++i) cmd << (i ? "," : "") << o.variants[i];
  }
  if (o.frames > 0) cmd << " --frames " << o.frames;
  if (o.speed_frames > 0) cmd << " --speed-frames " << o.speed_frames;
  if (o.max_sequences >= 0) cmd << " --max-sequences " << o.max_sequences;
  if (o.eval_threads > 0) cmd << " --eval-threads " << o.eval_threads;

  json t;
  t["command"] = cmd.str();
  t["settings"] = {{"config", o.config}, {"dataset", base.data.dataset}, {"split", base.eval.split},
                   {"budget_epochs", budget}, {"overrides", o.overrides}, {"tolerance", o.tolerance},
                   {"started", now_utc()}, {"load_average_start", load_averages()},
                   {"base_config_toml", layersnet::to_toml(base)}};
  std::printf("bench trade: %zu variant(s) around %s, %d epoch(s) each, data %s -> %s\n", variants.size(),
              o.config.c_str(), budget, base.data.dataset.c_str(), o.out.c_str());
  const auto t0 = Clock::now();
  double ran_s = 0;
  int ran = 0;
  t["variants"] = json::array();
  for (std::size_t i = 0; i < variants.size(); ++i) {
    const TradeVariant& v = variants[i];
    progress(i, variants.size(), v.name, v.sets.empty() ? (v.bf16 ? "default checkpoint, bf16 inference" : "base config") : keys_of({{"sets", v.sets}}), ran_s, ran);
    const double before = ran_s;
    json rec = run_variant(v, o, out, budget, &ran_s);
    if (ran_s > before) ++ran;
    std::vector<std::string> sets = o.overrides;
    sets.insert(sets.end(), v.sets.begin(), v.sets.end());
    layersnet::ad::ParamStore<float> ps;  // parameter count of the variant's model
    const layersnet::Config c = layersnet::load_config({o.config}, sets);
    layersnet::model::register_params(ps, c.model);
    rec["params"] = static_cast<double>(ps.total_size());
    t["variants"].push_back(rec);
    // Reports after every variant: an interrupted sweep still leaves its table and plot.
    write_reports(t, o, out, budget, t0, false);
  }
  if (o.speed_passes > 0) speed_passes(t, o, out, budget);
  write_reports(t, o, out, budget, t0, true);
}

}  // namespace layersnet::eval
