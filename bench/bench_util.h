#pragma once
/// What the micro-benchmarks share: wall-clock milliseconds and argument checks. They report
/// medians and ranges of repeats, never single runs (the median: core/base/statistics.h).

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "core/base/error.h"
#include "core/base/statistics.h"

namespace rcb::bench {

using Clock = std::chrono::steady_clock;

inline double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// A whole-number argument in [low, high]; anything else is an InputError naming it.
inline std::uint64_t count_arg(const char* text, const char* name, std::uint64_t low, std::uint64_t high) {
    std::uint64_t v = 0;
    const std::string t = text;
    const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || end != t.data() + t.size() || v < low || v > high)
        throw InputError(std::string(name) + ": '" + t + "' is not a whole number from " + std::to_string(low) +
                         " to " + std::to_string(high));
    return v;
}

/// A benchmark's main: `run(argc, argv)`, with bad input a one-line error and exit 2, any other
/// failure a one-line error and exit 1.
template <class Run>
int main_of(const char* name, Run&& run, int argc, char** argv) {
    try {
        return run(argc, argv);
    } catch (const InputError& e) {
        std::fprintf(stderr, "%s: %s\n", name, e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", name, e.what());
        return 1;
    }
}

}  // namespace rcb::bench
