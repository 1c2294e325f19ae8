// Writes the seed corpus for fuzz_reader: valid sequence images (float32/64, gzip, wind or
// not, 1-2 garments) and manifests, each prefixed with the mode byte.
#include "dataset/synthetic.h"

#include <filesystem>
#include <fstream>
#include <sstream>

using namespace layersnet::dataset;

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  const std::filesystem::path dir = argv[1];
  std::filesystem::create_directories(dir);
  int n = 0;
  for (int variant = 0; variant < 6; ++variant) {
    SyntheticOptions o;
    o.frames = 3 + variant % 2;
    o.rings = 3;
    o.segments = 4 + 2 * (variant % 3);
    o.body_rings = 2;
    o.body_segments = 4;
    o.garments = 1 + variant % 2;
    o.wind = variant % 3 == 0;
    SequenceWriteOptions w;
    w.float64 = variant == 2;
    w.int64 = variant == 3;
    w.gzip = variant == 4 ? 1 : 0;
    w.write_translation = variant != 5;
    const std::string tmp = (dir / "tmp.h5").string();
    write_sequence(tmp, make_synthetic_sequence(o), w);
    std::ifstream in(tmp, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    std::ofstream((dir / ("seq" + std::to_string(n++))), std::ios::binary) << '\0' << ss.str();
    std::filesystem::remove(tmp);
  }
  std::ofstream(dir / "manifest0") << '\1'
                                   << R"({"format":"dlayers-h5","version":1,"source":"s","splits":{"train":["a","b"],"val":["c"],"test":[]}})";
  std::ofstream(dir / "manifest1") << '\1' << R"({"format":"dlayers-h5","version":1,"source":"s","splits":{}})";
  // Structured mode (byte 0 = 2): a few arbitrary edit programs to start from.
  for (int k = 0; k < 8; ++k) {
    std::string prog(1, '\2');
    for (int i = 0; i < 48; ++i) prog += static_cast<char>((k * 37 + i * 11) & 0xff);
    std::ofstream(dir / ("structured" + std::to_string(k)), std::ios::binary) << prog;
  }
  return 0;
}
