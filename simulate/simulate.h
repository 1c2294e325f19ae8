#pragma once
// A user's scene for the learned simulator: garments given as OBJ meshes (with UVs, posed on
// the body's first frame, innermost first) animated on a body motion that has no ground truth.
//
// The scene becomes an ordinary in-memory dataset::Sequence, so the one rollout (eval::rollout)
// and the one writer (dataset::write_sequence) serve it:
//   frames 0 .. kSceneRestFrames-1   the body's first frame, the garments at their OBJ positions
//                                   (zero velocity: the garments start at rest);
//   frame kSceneRestFrames-1 + k     body frame k (k = 0 .. K-1 of the user's K body frames).
// The rollout starts at input frame kSceneRestFrames-1 and predicts body frames 1 .. K-1.
// Garment frames after the rest frames hold the start positions until predictions replace them.
//
// Units and axes: the model works in the D-LAYERS convention, z up and 10 scene units per metre.
// Input files are in `scale` units per metre with `up_axis` up; they are converted on reading
// (x_model = 10/scale * R x_input, R = identity for z up, (x, y, z) -> (x, -z, y) for y up) and
// the OBJ and PC2 outputs converted back, so they line up with the inputs. The D-LAYERS-H5
// output holds the scene as the model saw it (scale 10, z up).
//
// Body root: the model reads the body's root translation per frame. A D-LAYERS-H5 body brings
// its own; for OBJ and PC2 bodies it is the mean of the frame's body vertices
// (estimated_root_translation).
#include "eval/rollout.h"
#include "simulate/thread_choice.h"

#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace layersnet::eval {

inline constexpr int kSceneRestFrames = 3;  // the rollout's three input frames, all at rest
inline constexpr float kModelScale = 10.f;  // scene units per metre the model was trained in

// A user input that cannot make a scene; the message names the file and the fix.
class SimulateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// How a garment's vertices are held: none, the vertices of a file (0-based indices separated by
// spaces, commas or new lines; '#' starts a comment), or the rule "top-ring" (the open border
// loop highest along the up axis, e.g. a skirt's waist). The pinned vertices become the
// garment's pin weights (also in scene.h5) and are rigged from the body: at every frame, their
// rest positions moved rigidly with the body inside their loop (dataset::rig_pins), as the data's
// rig drives its pinned waistbands. A model whose rollouts take recorded pins (eval.recorded_pins)
// holds them there; another carries them through its cloth constraints (eval.pins).
struct GarmentInput {
  std::string obj;   // OBJ with vt, posed on the body's first frame
  std::string name;  // empty: the file's stem (made unique)
  std::string type = "garment";
  dataset::GarmentAttributes attributes;  // the data's mid-range values when not given
  std::string pins;  // "" | "top-ring" | index file
};
// "PATH[,key=value...]" with keys name, type, pins, tension, bending, mass, friction
// (e.g. "coat.obj,type=jacket,pins=top-ring,mass=0.4"); throws SimulateError on an unknown key.
GarmentInput parse_garment_spec(const std::string& spec);

// The body motion, one of three sources.
struct BodyInput {
  std::string obj_folder;  // a folder of OBJ files, one per frame in file-name order, same topology
  std::string pc2;         // or a PC2 point cache ...
  std::string topology;    // ... with one OBJ giving its faces (and vertex count)
  std::string h5;          // or the body of a D-LAYERS-H5 file (its own fps, scale, up axis, root)
};

struct SceneInputs {
  BodyInput body;
  std::vector<GarmentInput> garments;  // innermost first
  // "none" | "constant:dx,dy,dz,strength" | a CSV file of rows "frame,dx,dy,dz,strength"
  // (frames strictly increasing; each row holds until the next; a header line is allowed).
  // Direction in the input axes, strength as D-LAYERS' Blender wind field (0 = calm).
  std::string wind = "none";
  float fps = 30.f;        // frames per second of the body motion (a D-LAYERS-H5 body: its own)
  float scale = kModelScale;  // input units per metre (a D-LAYERS-H5 body: its own)
  char up_axis = 'z';      // 'z' or 'y' (a D-LAYERS-H5 body: its own)
  int max_frames = 0;      // use only the first body frames (0 = all)
};

struct Scene {
  dataset::Sequence sequence;            // see the top of this file; model units
  int body_frames = 0;                   // K
  std::vector<std::vector<int32_t>> pins;  // per garment, local vertex indices
  float scale = kModelScale;             // of the inputs, units per metre
  char up_axis = 'z';                    // of the inputs
  // Input-unit positions of model-unit rows (the inverse of the reading conversion).
  Points to_input_units(const Eigen::Ref<const Points>& x) const;
};

// Reads and checks everything; throws SimulateError or dataset::DatasetError naming the file.
Scene build_scene(const SceneInputs& inputs);

// Mean of each frame's body vertices: (T, 3) from body (T*B, 3).
Points estimated_root_translation(const Points& body, int num_body_vertices);

// Called after each predicted frame with (frames done, frames in all).
using ProgressFn = std::function<void(int, int)>;

// The rollout settings simulate gives a model, the user's `--set` last. A model whose rollouts take
// recorded pins (eval.recorded_pins: the large model, on data without post-processing) gets the
// collision steps of its cloth constraints and nothing else: with the scene's rigged pins, on large
// val, 36.4 mm and no outer vertex near the inner layer inside it, against 35.8 mm and 7 % alone;
// the edge limits and contact friction cost more than they give (docs/decisions.md, "Pins rigged
// from the body" and "Pins rigged from the body, chosen at rest").
std::vector<std::string> simulate_rollout_settings(const EvalConfig& model_eval, const std::vector<std::string>& user);

// Rolls `model` over the scene from rest (eval::rollout; recorded_pins: the pinned rows held where
// the scene's rig puts them, as eval.recorded_pins) and writes the predictions into the scene's
// garment frames; `threads`, when given, sets each step's OpenMP thread count (the positions do not
// depend on it). A rollout that leaves the finite numbers throws SimulateError naming the frame.
Rollout simulate_scene(Predictor& model, Scene& scene, const ProgressFn& progress = {}, bool recorded_pins = false,
                       ThreadChoice* threads = nullptr);

struct SimulateOutputs {
  int strip_frames = 4;   // panels of strip.png (0 = none)
  int panel_size = 256;   // pixels
  std::string sequence_id = "scene";
};
// Writes into `dir` (created): <garment>/<garment>_NNNN.obj (UVs and normals, body frame NNNN),
// <garment>.pc2, body.obj + body.pc2, <id>.h5 with dataset.json (a one-sequence data set, test
// split), strip.png. Everything goes to a temporary folder inside `dir` first and is renamed
// into place at the end; on failure the temporary folder is removed. Returns the file count.
int write_simulation(const std::string& dir, const Scene& scene, const SimulateOutputs& options = {});

// Throws SimulateError naming --out when `dir` cannot hold the outputs: it (or a folder on its
// path) is an existing file, or the nearest existing folder is not writable. Creates nothing.
void check_output_folder(const std::string& dir);

}  // namespace layersnet::eval
