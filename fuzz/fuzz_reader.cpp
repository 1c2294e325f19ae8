// libFuzzer target over the data layer's readers (scripts/fuzz.sh builds and runs it).
// Input byte 0 selects the reader:
//   even: the rest is an HDF5 file image -> SequenceFile (in memory, no disk) and read_all;
//         an accepted sequence must pass validate_sequence, and its patches, neighbourhoods
//         and a training sample are built (downstream code must survive any spec-valid input);
//   odd:  the rest is dataset.json text -> parse_manifest.
// Every rejection must be a DatasetError; anything else (crash, sanitizer report, other
// exception) is a finding.
#include "dataset/h5.h"
#include "dataset/manifest.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"

#include <cstdint>
#include <span>
#include <string_view>

using namespace layersnet::dataset;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  h5::set_max_elements(uint64_t{1} << 22);  // bounded allocations per dataset
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const std::span<const uint8_t> rest(data + 1, size - 1);
  try {
    if (data[0] % 2 == 0) {
      const SequenceFile file(rest, "fuzz.h5");
      const Sequence seq = file.read_all();
      validate_sequence(seq, "fuzz.h5");  // throws DatasetError = reader accepted a bad file
      if (seq.info.total_garment_vertices() <= 4096 && seq.info.num_body_vertices <= 4096) {
        const TrainingSample s = build_sample(seq.info, seq.frames, 2, NormalisationStats{}, nullptr);
        if (!s.state.allFinite() && seq.frames.garments[0].allFinite()) {
          // Finite inputs may still overflow float arithmetic; that is not a reader bug.
        }
      }
    } else {
      parse_manifest(std::string_view(reinterpret_cast<const char*>(rest.data()), rest.size()), "fuzz.json");
    }
  } catch (const DatasetError&) {
  }
  return 0;
}
