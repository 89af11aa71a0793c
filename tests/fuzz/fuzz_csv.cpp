/// libFuzzer target: the CSV importers (core/scene/import/csv.h). The first byte picks boxes or rays; any text
/// must parse or throw InputError, and parsed boxes and rays must be valid (finite, min <= max).
#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/scene/import/csv.h"
#include "core/base/error.h"
#include "core/scene/recording_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
    try {
        if (data[0] & 1) {
            for (const rcb::Segment& s : rcb::parse_rays_csv(text, "fuzz.csv"))
                if (!rcb::segment_problem(s).empty()) std::abort();
        } else {
            for (const rcb::Object& o : rcb::parse_boxes_csv(text, "fuzz.csv"))
                if (!rcb::box_problem(o.box).empty()) std::abort();
        }
    } catch (const rcb::InputError&) {
    }
    return 0;
}
