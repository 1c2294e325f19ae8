// `layersnet inspect DATASET`: what a data set holds (inspect/inspect.h), with patches and world
// edges at the patch size and world radius of a config or the options.
#include "cli/command_registry.h"
#include "inspect/inspect.h"
#include "model/sample_input.h"
#include "run/config.h"

#include <memory>

namespace {

struct InspectCli {
  layersnet::eval::InspectOptions options;
  std::string config;  // model.patch_size, model.world_radius (and the rest of [model]) from here
  double patch_size = -1, world_radius = -1;  // < 0: from the config (or the code defaults)
};

int run_inspect(const InspectCli& o) {
  layersnet::Config config = layersnet::load_config(o.config.empty() ? std::vector<std::string>{}
                                                                     : std::vector<std::string>{o.config});
  if (o.patch_size >= 0) config.model.patch_size = o.patch_size;
  if (o.world_radius >= 0) config.model.world_radius = o.world_radius;
  layersnet::eval::inspect_dataset(o.options, layersnet::model::sample_options_for(config.model));
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(inspect, "Summarise a D-LAYERS-H5 data set (sequences, garments, frames, patches, wind)",
                  [](CLI::App& sub) {
                    auto opts = std::make_shared<InspectCli>();
                    sub.add_option("dataset", opts->options.root, "data-set folder holding dataset.json")->required();
                    sub.add_flag("--check", opts->options.check, "also read every frame and check all values");
                    sub.add_flag("--brief", opts->options.brief, "totals only");
                    sub.add_option("--config,-c", opts->config,
                                   "take model.patch_size and model.world_radius from this config (resolved, with its includes)");
                    sub.add_option("--patch-size", opts->patch_size, "UV patch size (default: the config's, else 0.04)");
                    sub.add_flag("--margins", opts->options.margins,
                                 "measure the training split's ground-truth collision distances (for loss.collision_eps)");
                    sub.add_flag("--physics", opts->options.physics,
                                 "how far the validation split's frames are from stationary for the physics energy: "
                                 "each term's gradient at Blender's next frame against the inertia's, and the term "
                                 "weights that fit best");
                    sub.add_flag("--pins", opts->options.pins,
                                 "measure how closely pinned vertices carried with the body (eval.pins), and rigged from "
                                 "it as simulate rigs them, follow the ground truth");
                    sub.add_flag("--motion", opts->options.motion,
                                 "per split: body speed and turn rate, share of frames with wind, garment speed "
                                 "against the body on calm and windy frames (reads every frame after the ramp)");
                    sub.add_option("--world-radius", opts->world_radius,
                                   "patch-to-patch world-edge radius, scene units (default: the config's, else 0.4)");
                    return [opts] { return run_inspect(*opts); };
                  });
