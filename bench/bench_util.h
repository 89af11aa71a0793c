#pragma once
/// What the micro-benchmarks share: wall-clock milliseconds and the median of repeats (the
/// benchmarks report medians and ranges, never single runs).

#include <algorithm>
#include <chrono>
#include <vector>

namespace rcb::bench {

using Clock = std::chrono::steady_clock;

inline double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

inline double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace rcb::bench
