// `layersnet simulate --garment G.obj [--garment G2.obj ...] (--body-frames DIR | --body-pc2 F
// --body-topology OBJ | --body-h5 F | --motion CLIP.bvh) [--checkpoint C] [--wind W] [--fps F]
// [--scale S] [--up z|y] --out DIR`: the learned simulator on a user's outfit and motion
// (simulate/simulate.h; a BVH clip through Blender: simulate/motion.h).
#include "cli/command_registry.h"
#include "cli/model_option.h"
#include "cli/program_files.h"
#include "autodiff/arena.h"
#include "autodiff/bf16_gemm.h"
#include "eval/machine.h"
#include "simulate/motion.h"
#include "simulate/simulate.h"

#include <Eigen/Core>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <omp.h>

namespace {
using namespace layersnet;

struct SimulateCliOptions {
  eval::SceneInputs scene;
  std::vector<std::string> garments;  // "PATH[,key=value...]"
  cli::ModelOption model;
  std::string up = "z";
  std::vector<std::string> settings;  // "eval.KEY=VALUE"
  eval::SimulateOutputs outputs;
  std::string out;
  eval::MotionInput motion;  // --motion: a BVH clip retargeted by Blender
  std::string precision = "auto";  // of the model's linear products: auto | float32 | bf16
  int threads = 0;                    // OpenMP threads of the rollout (0 = chosen by timing, eval::ThreadChoice)
};

constexpr const char* kShippedModel = "models/large/model.h5";

// "frame 40/199, 0.21 s/frame, ETA 33 s" on stderr: in place on a terminal, else every 10 %.
eval::ProgressFn progress_reporter() {
  const auto start = std::chrono::steady_clock::now();
  const bool terminal = isatty(2);
  return [start, terminal, last_tenth = -1](int done, int total) mutable {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const int tenth = done * 10 / total;
    if (!terminal && tenth == last_tenth && done != total) return;
    last_tenth = tenth;
    std::fprintf(stderr, "%ssimulate: frame %d/%d, %.2f s/frame, ETA %.0f s%s", terminal ? "\r" : "", done, total,
                 elapsed / done, elapsed / done * (total - done), terminal && done != total ? "" : "\n");
    std::fflush(stderr);
  };
}

int run_simulate(SimulateCliOptions& o) {
  ad::keep_freed_memory_in_process();
  for (const std::string& spec : o.garments) o.scene.garments.push_back(eval::parse_garment_spec(spec));
  o.scene.up_axis = o.up.front();
  std::string checkpoint = o.model.path();
  if (checkpoint.empty()) {
    checkpoint = cli::find_program_file(kShippedModel).string();
    if (checkpoint.empty())
      throw std::runtime_error(std::string(kShippedModel) + " not found in " + cli::program_files_dir().string() +
                               " (where the program's files are installed) or the working directory; pass --checkpoint or --run");
  }
  eval::check_output_folder(o.out);
  std::filesystem::path motion_dir;  // Blender's body frames of --motion; removed once read
  if (!o.motion.bvh.empty()) {
    if (!o.scene.body.obj_folder.empty() || !o.scene.body.pc2.empty() || !o.scene.body.h5.empty())
      throw eval::SimulateError("--motion " + o.motion.bvh +
                                ": give the body motion once (--motion, --body-frames, --body-pc2 or --body-h5)");
    o.motion.script = cli::find_program_file("generate/retarget_bvh.py").string();
    o.motion.fps = o.scene.fps;
    o.motion.scale = o.scene.scale;
    o.motion.up_axis = o.scene.up_axis;
    o.motion.frames = o.scene.max_frames;
    motion_dir = std::filesystem::temp_directory_path() / ("layersnet-motion-" + std::to_string(getpid()));
    std::filesystem::remove_all(motion_dir);
    const auto t0 = std::chrono::steady_clock::now();
    std::fprintf(stderr, "simulate: retargeting %s onto the body rig in Blender (about a minute) ...\n",
                 o.motion.bvh.c_str());
    eval::retarget_bvh(o.motion, motion_dir.string());  // on failure the folder and its blender.log stay
    std::fprintf(stderr, "simulate: motion retargeted in %.0f s\n",
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    o.scene.body.pc2 = (motion_dir / "body.pc2").string();
    o.scene.body.topology = (motion_dir / "body.obj").string();
  }
  eval::Scene scene = eval::build_scene(o.scene);  // every input checked before the model loads
  if (!motion_dir.empty()) std::filesystem::remove_all(motion_dir);
  Eigen::setNbThreads(1);  // the model's ops own the threads; nested GEMM threads only contend
  if (o.threads > 0) omp_set_num_threads(o.threads);
  auto model = eval::load_model_predictor(checkpoint, checkpoint, nullptr);
  model->apply_eval_settings(eval::simulate_rollout_settings(model->config().eval, o.settings));
  // bf16 products cost no measurable accuracy and save a quarter of the step where they out-run
  // float32 (docs/decisions.md, "AMX tiles for the bf16 products", "bf16 products only where they
  // out-run float32"); elsewhere float32 is both faster and exact.
  if (o.precision == "auto") o.precision = ad::bf16_outruns_float32() ? "bf16" : "float32";
  model->set_matmul_precision(ad::parse_matmul_precision(o.precision));
  const auto& garments = scene.sequence.info.garments;
  const bool any_pins = std::any_of(garments.begin(), garments.end(), [](const auto& g) { return g.num_pinned() > 0; });
  const EvalConfig& rolled = model->config().eval;
  if (any_pins && !rolled.recorded_pins && !(rolled.constraints && rolled.pins))
    std::fprintf(stderr, "simulate: warning: the pinned vertices stay free, because the model's rollouts have %s; "
                         "add --set eval.recorded_pins=true (or --set eval.constraints=true --set eval.pins=true) to hold them\n",
                 rolled.constraints ? "eval.pins = false" : "neither recorded pins nor cloth constraints");
  std::fprintf(stderr, "simulate: %d garments, %d body frames at %g fps, model %s\n",
               scene.sequence.info.num_garments(), scene.body_frames, scene.sequence.info.fps, checkpoint.c_str());
  // Without --threads the steps time all the threads against one and keep the faster.
  std::unique_ptr<eval::ThreadChoice> choice;
  if (o.threads == 0) choice = std::make_unique<eval::ThreadChoice>(omp_get_max_threads());
  const eval::Rollout r = eval::simulate_scene(*model, scene, progress_reporter(), rolled.recorded_pins, choice.get());
  const int files = eval::write_simulation(o.out, scene, o.outputs);
  // The first step also builds the patch structure and the caches every later step reuses, so
  // the rate a user sees over a long motion is the later steps' median.
  const double first_ms = r.step_ms.empty() ? 0.0 : r.step_ms.front();
  const double median_ms = r.step_ms.size() > 1 ? eval::median({r.step_ms.begin() + 1, r.step_ms.end()}) : first_ms;
  const std::string threads =
      choice ? choice->summary() : std::to_string(o.threads) + (o.threads == 1 ? " thread" : " threads") + " (--threads)";
  std::printf("simulate: %d frames, first step %.0f ms, then %.1f ms/frame (median) = %.1f frames per second, "
              "%s products, %s -> %d files in %s\n",
              scene.body_frames, first_ms, median_ms, 1000.0 / median_ms, o.precision.c_str(), threads.c_str(), files,
              o.out.c_str());
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(
    simulate, "Animate your own garments (OBJ with UVs) on a body motion, no ground truth needed",
    [](CLI::App& sub) {
      auto o = std::make_shared<SimulateCliOptions>();
      sub.footer(
          "Units: the model works in the D-LAYERS x10 convention, 10 scene units per metre (a person about 18 units "
          "tall), z up. --scale gives the input files' units per metre (1 for metres, 100 for centimetres) and --up "
          "their up axis; inputs are converted on reading and the OBJ/PC2 outputs converted back. The garments start "
          "at rest on the body's first frame; output frame k is body frame k. Outputs in --out: "
          "<garment>/<garment>_NNNN.obj (UVs, normals), <garment>.pc2 and body.pc2 (Blender: Mesh Cache modifier), "
          "body.obj, scene.h5 + dataset.json (D-LAYERS-H5, scale 10, z up, the first frame repeated 3 times "
          "at rest: `inspect`, `eval`, `export`, `stress` read it), strip.png.");
      sub.add_option("--garment", o->garments,
                     "garment OBJ with UVs, posed on the body's first frame; repeat from the innermost to the "
                     "outermost layer. Options after commas: name=, type=, pins=top-ring|FILE (0-based vertex "
                     "indices), tension= (default 50), bending= (50), mass= (0.5), friction= (60), e.g. "
                     "coat.obj,type=jacket,mass=0.4")
          ->required();
      sub.add_option("--body-frames", o->scene.body.obj_folder, "folder of body OBJ files, one per frame (name order)");
      sub.add_option("--body-pc2", o->scene.body.pc2, "body motion as a PC2 point cache (with --body-topology)");
      sub.add_option("--body-topology", o->scene.body.topology, "OBJ giving the faces of --body-pc2");
      sub.add_option("--body-h5", o->scene.body.h5, "the body of a D-LAYERS-H5 file (its fps, scale, up axis, root)");
      sub.add_option("--motion", o->motion.bvh,
                     "a BVH motion-capture clip (CMU skeleton, e.g. the CMU library): Blender retargets it onto "
                     "the generator's body; frame 0 is the body's rest pose, then 15 frames ramp into the clip, "
                     "resampled to --fps; written in --scale / --up units");
      sub.add_option("--bvh-start", o->motion.bvh_start, "first BVH frame of --motion played (CMU frame 0 is a calibration pose)")
          ->default_val(1);
      sub.add_option("--bvh-yaw", o->motion.yaw_deg, "turn the --motion clip about the up axis (degrees)")->default_val(0.f);
      sub.add_option("--blender", o->motion.blender, "Blender executable for --motion")->default_val("blender");
      o->model.add_to(sub, std::string("model (default: the shipped ") + kShippedModel + ")");
      sub.add_option("--wind", o->scene.wind,
                     "none | constant:dx,dy,dz,strength | CSV of rows frame,dx,dy,dz,strength (frames increasing, "
                     "each row holds until the next); strength as D-LAYERS (Blender wind field, e.g. 400)")
          ->default_val("none");
      sub.add_option("--fps", o->scene.fps, "frames per second of the body motion")->default_val(30.f);
      sub.add_option("--scale", o->scene.scale,
                     "input units per metre: 10 = the D-LAYERS x10 convention, 1 = metres, 100 = centimetres")
          ->default_val(10.f);
      sub.add_option("--up", o->up, "up axis of the input files")->check(CLI::IsMember({"z", "y"}))->default_val("z");
      sub.add_option("--frames", o->scene.max_frames, "use only the first N body frames (0 = all)")->default_val(0);
      sub.add_option("--set", o->settings, "rollout setting of the model, e.g. --set eval.constraints=false");
      sub.add_option("--precision", o->precision,
                     "linear products of the model: float32, bf16 (bfloat16 inputs, float32 sums: faster, the "
                     "same accuracy within 0.1 %), or auto = bf16 where it out-runs float32 on this CPU (AMX "
                     "tiles, or AVX-512 BF16 on an AMD core; `layersnet bench linear` shows the rates)")
          ->check(CLI::IsMember({"auto", "float32", "fp32", "bf16", "bfloat16"}))
          ->default_val("auto");
      sub.add_option("--threads", o->threads, "OpenMP threads of the rollout (0 = all of them against 1, timed on the first steps and again every 100, the faster kept; the positions are the same at any count)")->check(CLI::NonNegativeNumber)->default_val(0);
      sub.add_option("--strip-frames", o->outputs.strip_frames, "panels in strip.png (0 = no strip)")->default_val(4);
      sub.add_option("--out", o->out, "output folder")->required();
      return [o] { return run_simulate(*o); };  // errors: reported by cli/main.cpp
    });
