#pragma once
/// The outlier guard of the grids and the LBVH: one far object, or a "stadium" box around a small
/// cluster, would otherwise stretch the bounds a structure quantises (grid cells, Morton codes) so
/// far that the rest of the scene falls into a few cells or a few code bits. Per axis the bounds
/// shrink to the central 99% of the samples (0.5% quantile of the lows to 99.5% of the highs) when
/// the full extent exceeds that by kOutlierStretch; the objects outside stay in the structure (the
/// grids' unbounded border cells, the LBVH's clamped codes), so answers stay exact.

#include <algorithm>
#include <cstddef>
#include <vector>

#include "core/base/geometry.h"

namespace rcb {

/// How far the full bounds may exceed the central samples' bounds on an axis before the trim.
inline constexpr double kOutlierStretch = 8.0;

/// Trims `bounds` per axis as above over `samples` samples: `low(i, axis)` and `high(i, axis)` are
/// sample i's low and high coordinate (a box's min and max, or a centroid twice). Fewer than 200
/// samples (no 0.5% to cut) leave the bounds alone. Returns whether an axis was trimmed.
template <class Low, class High>
bool trim_outliers(Aabb& bounds, std::size_t samples, Low&& low, High&& high) {
    const std::size_t k = samples / 200;  // 0.5% on each side
    if (k == 0) return false;
    std::vector<float> lo(samples), hi(samples);
    bool trimmed = false;
    for (int a = 0; a < 3; ++a) {
        for (std::size_t i = 0; i < samples; ++i) lo[i] = low(i, a), hi[i] = high(i, a);
        std::nth_element(lo.begin(), lo.begin() + std::ptrdiff_t(k), lo.end());
        std::nth_element(hi.begin(), hi.begin() + std::ptrdiff_t(samples - 1 - k), hi.end());
        const float tlo = lo[k], thi = std::max(hi[samples - 1 - k], tlo);
        if (double(bounds.max[a]) - double(bounds.min[a]) > kOutlierStretch * (double(thi) - double(tlo))) {
            bounds.min[a] = tlo;
            bounds.max[a] = thi;
            trimmed = true;
        }
    }
    return trimmed;
}

}  // namespace rcb
