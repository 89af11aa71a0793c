/// libFuzzer target: the Quake III BSP importer (core/scene/import/bsp.h), both modes. Any bytes must
/// import or throw InputError; imported boxes must be valid (finite, min <= max).
#include <cstdint>
#include <cstdlib>
#include <span>

#include "core/base/error.h"
#include "core/scene/import/bsp.h"
#include "core/scene/recording_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::span<const std::uint8_t> bytes(data, size);
    for (const char* mode : {"brushes", "triangles"}) {
        try {
            for (const rcb::Object& o : rcb::parse_bsp(bytes, "fuzz.bsp", mode))
                if (!rcb::box_problem(o.box).empty()) std::abort();
        } catch (const rcb::InputError&) {
        }
    }
    return 0;
}
