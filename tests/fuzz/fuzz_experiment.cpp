/// libFuzzer target: the experiment-file parser (runner/experiment.h). Any text must parse or
/// throw InputError (never another exception, a crash or a hang). File references resolve
/// against a directory that does not exist, so nothing outside the input is read.
#include <cstdint>
#include <string>

#include "core/base/error.h"
#include "runner/experiment.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        (void)rcb::parse_experiment(text, "fuzz.json", "/nonexistent-rcbench-fuzz");
    } catch (const rcb::InputError&) {
    }
    return 0;
}
