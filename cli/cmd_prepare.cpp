// `layersnet prepare DATASET`: normalisation statistics of the training split -> stats.h5
// (see dataset/stats.h for what is pooled). Training refuses to start without it.
#include "cli/command_registry.h"
#include "dataset/manifest.h"
#include "dataset/stats.h"

#include <chrono>
#include <cstdio>

namespace {
using namespace layersnet::dataset;

struct PrepareOptions {
  std::string root;
  bool garments_only = false;
};

void print(const char* name, const MeanStd& q) {
  std::printf("  %-18s mean (%9.4g, %9.4g, %9.4g)  std (%9.4g, %9.4g, %9.4g)  n %ld\n", name, q.mean[0], q.mean[1],
              q.mean[2], q.std[0], q.std[1], q.std[2], static_cast<long>(q.count));
}

int run_prepare(const PrepareOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const DatasetManifest m = read_manifest(o.root);
  StatsOptions so;
  so.include_body = !o.garments_only;
  const NormalisationStats s = compute_stats(m, so);
  write_stats(m.stats_path(), s);
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("wrote %s from %zu training sequences in %.2f s (garment%s vertices, root-relative, per frame):\n",
              m.stats_path().c_str(), s.sequences.size(), sec, o.garments_only ? "" : " and body");
  print("position", s.position);
  print("velocity", s.velocity);
  print("acceleration", s.acceleration);
  print("root_position", s.root_position);
  print("root_velocity", s.root_velocity);
  print("root_acceleration", s.root_acceleration);
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(prepare, "Compute normalisation statistics of the training split (writes stats.h5)", [](CLI::App& sub) {
  auto opts = std::make_shared<PrepareOptions>();
  sub.add_option("dataset", opts->root, "data-set folder holding dataset.json")->required();
  sub.add_flag("--garments-only", opts->garments_only, "pool garment vertices only (official pools body too)");
  return [opts] { return run_prepare(*opts); };
});
