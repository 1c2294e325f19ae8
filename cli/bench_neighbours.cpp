// `layersnet bench neighbours`: cost of the per-frame neighbourhood work on synthetic scenes
// of 4 sizes (2 tube garments around a cylinder body, constant vertex density, growing
// height), to show that it grows linearly with the vertex count.
#include "cli/command_registry.h"
#include "dataset/neighbours.h"
#include "dataset/patches.h"
#include "dataset/synthetic.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace {
using namespace layersnet::dataset;

struct BenchOptions {
  int base_rings = 60;
  int repeats = 5;
  int threads = 1;
};

template <typename Fn>
double best_ms(int repeats, Fn&& fn) {
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    fn();
    best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  return best;
}

int run_bench(const BenchOptions& o) {
  omp_set_num_threads(std::max(1, o.threads));
  std::printf("bench neighbours: R = 0.4, R_b = 0.6, K = 16 (official first-in-index order), %d thread(s),\n"
              "best of %d; 2 garments + body, fixed density (0.147 units between vertices)\n\n",
              o.threads, o.repeats);
  std::printf("%8s %8s %6s %9s %9s %9s %9s %9s %9s %9s\n", "garm_N", "body_B", "P", "normals", "centres",
              "world", "body_knn", "nearest", "total_ms", "ns/vert");
  for (int scale : {1, 2, 4, 8}) {
    SyntheticOptions so;
    so.frames = 3;
    so.garments = 2;
    so.segments = 64;
    so.body_segments = 64;
    so.uv_per_unit = 0.1f;  // patch 0.04 UV = 0.4 units: ~9 vertices per patch
    so.rings = o.base_rings * scale;
    so.body_rings = o.base_rings * scale;
    so.height = 0.147f * static_cast<float>(so.rings - 1) / 0.8f;
    const Sequence seq = make_synthetic_sequence(so);
    std::vector<PatchStructure> per_garment;
    for (const auto& g : seq.info.garments) per_garment.push_back(build_patches(g));
    const PatchStructure all = concat_patches({&per_garment[0], &per_garment[1]});
    Points garments(all.num_vertices, 3);
    garments << seq.garment_at(0, 1), seq.garment_at(1, 1);
    const Points body = seq.body_at(2);
    Points normals, centres;
    Csr world;
    BodyNeighbours nb;
    NearestBody nv, np;
    const double t_norm = best_ms(o.repeats, [&] { normals = vertex_normals(body, seq.info.body_faces); });
    const double t_cent = best_ms(o.repeats, [&] { centres = patch_means(all, garments); });
    const double t_world = best_ms(o.repeats, [&] { world = world_edges(centres, all.adjacency, 0.4f); });
    const double t_body = best_ms(o.repeats, [&] { nb = body_neighbours(centres, body); });
    const double t_near = best_ms(o.repeats, [&] { nv = nearest_body(garments, body); np = nearest_body(centres, body); });
    const double total = t_norm + t_cent + t_world + t_body + t_near;
    const double n_all = static_cast<double>(all.num_vertices + body.rows());
    std::printf("%8d %8ld %6d %9.3f %9.3f %9.3f %9.3f %9.3f %9.3f %9.1f\n", all.num_vertices,
                static_cast<long>(body.rows()), all.num_patches, t_norm, t_cent, t_world, t_body, t_near, total,
                1e6 * total / n_all);
  }
  std::printf("\ncolumns in ms per frame; ns/vert = total / (garment + body vertices): flat = linear cost\n");
  return 0;
}

}  // namespace

LAYERSNET_BENCH(neighbours, "Neighbourhood search cost on 4 scene sizes (linear in vertices)", [](CLI::App& sub) {
  auto opts = std::make_shared<BenchOptions>();
  sub.add_option("--rings", opts->base_rings, "tube rows of the smallest size (x1, x2, x4, x8)");
  sub.add_option("--repeats", opts->repeats, "timed repetitions (best is shown)");
  sub.add_option("--threads", opts->threads, "OpenMP threads");
  return [opts] { return run_bench(*opts); };
});
