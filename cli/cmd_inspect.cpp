// `layersnet inspect DATASET`: what a data set holds — sequences per split, frames, body and
// garment vertex/face/patch counts, wind segments, statistics. Reads headers only unless
// --check, which reads every frame and checks every value against the spec.
#include "cli/command_registry.h"
#include "dataset/manifest.h"
#include "dataset/patches.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"
#include "dataset/wind.h"

#include <cstdio>
#include <filesystem>
#include <set>

namespace {
using namespace layersnet::dataset;

struct InspectOptions {
  std::string root;
  bool check = false;
  bool brief = false;
  float patch_size = kDefaultPatchSize;
};

void print_wind(const SequenceInfo& info) {
  const auto segments = wind_segments(info);
  if (segments.empty()) {
    std::printf("    wind: none (no /wind group)\n");
    return;
  }
  std::printf("    wind: %zu segment(s):", segments.size());
  for (const auto& s : segments) {
    if (s.strength == 0.f)
      std::printf(" [%d,%d) calm;", s.begin, s.end);
    else
      std::printf(" [%d,%d) strength %.4g along (%.2f, %.2f, %.2f);", s.begin, s.end, s.strength, s.direction.x(),
                  s.direction.y(), s.direction.z());
  }
  std::printf("\n");
}

int run_inspect(const InspectOptions& o) {
  const DatasetManifest m = read_manifest(o.root);
  std::printf("data set %s: %zu sequences (train %zu, val %zu, test %zu)\nsource: %s\n", o.root.c_str(),
              m.all_ids().size(), m.train.size(), m.val.size(), m.test.size(), m.source.c_str());
  if (std::filesystem::exists(m.stats_path())) {
    const NormalisationStats s = read_stats(m.stats_path());
    std::printf("stats.h5: from %zu training sequences; position std (%.4g, %.4g, %.4g), velocity std (%.4g, %.4g, %.4g)\n",
                s.sequences.size(), s.position.std[0], s.position.std[1], s.position.std[2], s.velocity.std[0],
                s.velocity.std[1], s.velocity.std[2]);
  } else {
    std::printf("stats.h5: missing (create it with `layersnet prepare %s`)\n", o.root.c_str());
  }
  int64_t frames = 0, garments = 0, vertices = 0, patches = 0, with_wind = 0;
  std::set<std::string> types;
  for (const char* split : {"train", "val", "test"}) {
    for (const auto& id : m.split(split)) {
      const SequenceFile f(m.sequence_path(id));
      if (o.check) (void)f.read_all();
      const SequenceInfo& info = f.info();
      frames += info.num_frames;
      with_wind += info.has_wind;
      if (!o.brief)
        std::printf("%-12s %-5s %4d frames @ %g fps, body %d vertices / %ld faces, friction %.3g, %d garment(s)%s\n",
                    id.c_str(), split, info.num_frames, info.fps, info.num_body_vertices,
                    static_cast<long>(info.body_faces.rows()), info.body_friction, info.num_garments(),
                    o.check ? ", all values checked" : "");
      for (const auto& g : info.garments) {
        const PatchStructure p = build_patches(g, o.patch_size);
        ++garments;
        vertices += g.num_vertices;
        patches += p.num_patches;
        types.insert(g.type);
        if (!o.brief)
          std::printf("    garment %-16s type %-22s N %6d  F %6d  panels %3d  patches %5d  (tension %.3g, bending %.3g, "
                      "mass %.3g, self-friction %.3g)\n",
                      g.name.c_str(), g.type.c_str(), g.num_vertices, g.num_faces(),
                      static_cast<int>(std::set<int32_t>(g.panel.begin(), g.panel.end()).size()), p.num_patches,
                      g.attributes.tension_stiffness, g.attributes.bending_stiffness, g.attributes.mass,
                      g.attributes.self_friction);
      }
      if (!o.brief) print_wind(info);
    }
  }
  std::printf("total: %ld frames, %ld garments (%zu types), %ld garment vertices, %ld patches (size %g), %ld/%zu "
              "sequences with wind\n",
              static_cast<long>(frames), static_cast<long>(garments), types.size(), static_cast<long>(vertices),
              static_cast<long>(patches), o.patch_size, static_cast<long>(with_wind), m.all_ids().size());
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(inspect, "Summarise a D-LAYERS-H5 data set (sequences, garments, frames, patches, wind)",
                  [](CLI::App& sub) {
                    auto opts = std::make_shared<InspectOptions>();
                    sub.add_option("dataset", opts->root, "data-set folder holding dataset.json")->required();
                    sub.add_flag("--check", opts->check, "also read every frame and check all values");
                    sub.add_flag("--brief", opts->brief, "totals only");
                    sub.add_option("--patch-size", opts->patch_size, "UV patch size (default 0.04)");
                    return [opts] { return run_inspect(*opts); };
                  });
