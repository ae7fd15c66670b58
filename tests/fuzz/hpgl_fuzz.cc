// libFuzzer target for the HPGL/PLT reader (tests/fuzz/vector_reader.h says what is checked).
#include "vector_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return insitu::fuzz::FuzzVectorReader(data, size, "fuzz.plt", [](const std::string& t,
                                                                   const std::string& o) {
    return insitu::pattern::ParseHpgl(t, o);
  });
}
