#include "accel/grid/grid.h"

#include <algorithm>

#include "accel/common/outlier_trim.h"

namespace rcb {

namespace grid {

std::array<int, 3> resolution(const Aabb& bounds, double size, int max_per_axis) {
    std::array<int, 3> res{1, 1, 1};
    for (int a = 0; a < 3; ++a) {
        const double extent = double(bounds.max[a]) - double(bounds.min[a]);
        const double cells = std::ceil(extent / size);
        res[a] = cells >= 1 ? int(std::min(cells, double(max_per_axis))) : 1;
    }
    return res;
}

Aabb lattice_bounds(std::span<const Object> objects, bool outlier_guard, bool* trimmed) {
    if (trimmed) *trimmed = false;
    Aabb b = Aabb::empty();
    for (const Object& o : objects) b = merge(b, o.box);
    if (b.is_empty()) return {{-1, -1, -1}, {1, 1, 1}};
    if (!outlier_guard) return b;
    const bool trim = trim_outliers(
        b, objects.size(), [&](std::size_t i, int a) { return objects[i].box.min[a]; },
        [&](std::size_t i, int a) { return objects[i].box.max[a]; });
    if (trimmed) *trimmed = trim;
    return b;
}

}  // namespace grid

}  // namespace rcb
