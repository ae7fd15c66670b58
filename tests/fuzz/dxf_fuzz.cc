// libFuzzer target for the DXF reader (tests/fuzz/vector_reader.h says what is checked). A
// coarse tolerance: flattening is not what is fuzzed, the parser is.
#include "vector_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return insitu::fuzz::FuzzVectorReader(data, size, "fuzz.dxf", [](const std::string& t,
                                                                   const std::string& o) {
    return insitu::pattern::ParseDxf(t, o, 0.05);
  });
}
