#include "sim/scene_features.h"

#include <algorithm>
#include <cmath>

#include "core/base/statistics.h"
#include "core/base/error.h"
#include "core/truth/ground_truth.h"

namespace rcb {

const std::array<std::string_view, kSceneFeatureCount>& scene_feature_names() {
    static const std::array<std::string_view, kSceneFeatureCount> names = {
        "log10_objects",  "size_p50",           "size_spread",         "flatness",   "occupancy",
        "log10_count_cv", "log10_hits_per_ray", "log10_cells_per_ray", "ray_length", "change_rate"};
    return names;
}

nlohmann::json SceneFeatures::to_json() const {
    nlohmann::json j = nlohmann::json::object();
    for (std::size_t i = 0; i < kSceneFeatureCount; ++i) j[std::string(scene_feature_names()[i])] = values[i];
    return j;
}

SceneFeatures SceneFeatures::from_json(const nlohmann::json& j, const std::string& where) {
    SceneFeatures f;
    if (!j.is_object()) throw InputError(where + ": scene features must be an object");
    for (std::size_t i = 0; i < kSceneFeatureCount; ++i) {
        const std::string name(scene_feature_names()[i]);
        if (!j.contains(name) || !j[name].is_number() || !std::isfinite(j[name].get<double>()))
            throw InputError(where + ": scene feature \"" + name + "\" is missing or not a finite number");
        f.values[i] = j[name].get<double>();
    }
    return f;
}

namespace {

/// The reference lattice: about one cubic cell per object over the bounds of frame 0 (thesis
/// §4.2's uniform grid at density 1), thin axes floored at 1/1000 of the longest so a flat map
/// still gets cubic cells.
struct Lattice {
    Vec3d lo, width;
    std::array<std::int64_t, 3> cells{1, 1, 1};

    Lattice(const Aabbd& bounds, std::size_t objects) {
        const double longest = std::max(bounds.longest_edge(), 1e-30);
        Vec3d extent = bounds.extent();
        for (int a = 0; a < 3; ++a) extent[a] = std::max(extent[a], 1e-3 * longest);
        const double target = double(std::clamp<std::size_t>(objects, 1, std::size_t(1) << 21));
        const double h = std::cbrt(extent.x * extent.y * extent.z / target);
        lo = bounds.min;
        for (int a = 0; a < 3; ++a) {
            cells[std::size_t(a)] = std::clamp<std::int64_t>(std::int64_t(std::ceil(extent[a] / h)), 1, 1 << 16);
            width[a] = extent[a] / double(cells[std::size_t(a)]);
        }
    }
    std::int64_t total() const { return cells[0] * cells[1] * cells[2]; }
    std::int64_t coordinate(double p, int a) const {
        const double c = std::floor((p - lo[a]) / width[a]);
        return std::clamp<std::int64_t>(std::isfinite(c) ? std::int64_t(std::clamp(c, -1.0, 1e9)) : 0, 0,
                                        cells[std::size_t(a)] - 1);
    }
    std::int64_t index(const Vec3d& p) const {
        return (coordinate(p.z, 2) * cells[1] + coordinate(p.y, 1)) * cells[0] + coordinate(p.x, 0);
    }
    /// Cells a 3D-DDA walk visits along the segment clipped to the lattice (0 when it misses).
    double cells_crossed(const Segmentd& s) const {
        double t0 = 0, t1 = 1;
        const Vec3d d = s.delta();
        for (int a = 0; a < 3; ++a) {
            const double hi = lo[a] + width[a] * double(cells[std::size_t(a)]);
            if (d[a] == 0) {
                if (s.p0[a] < lo[a] || s.p0[a] > hi) return 0;
                continue;
            }
            double ta = (lo[a] - s.p0[a]) / d[a], tb = (hi - s.p0[a]) / d[a];
            if (ta > tb) std::swap(ta, tb);
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        if (!(t0 <= t1)) return 0;
        const Vec3d a = s.at(t0), b = s.at(t1);
        double n = 1;
        for (int axis = 0; axis < 3; ++axis)
            n += double(std::llabs(coordinate(b[axis], axis) - coordinate(a[axis], axis)));
        return n;
    }
};

double length(const Vec3d& v) { return std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z); }

}  // namespace

SceneFeatures compute_scene_features(const Recording& r) {
    SceneFeatures f;
    FeatureValues& v = f.values;
    const std::size_t n = r.initial.size();
    v[0] = std::log10(double(std::max<std::size_t>(n, 1)));
    if (n == 0) return f;
    const Aabbd bounds = bounds_of(r.initial).as<double>();
    const double longest = bounds.longest_edge();

    // Sizes relative to the scene: the thesis' uniform scenes hold one size, irregular ones span
    // orders of magnitude (§6.1).
    std::vector<double> sizes(n);
    for (std::size_t i = 0; i < n; ++i)
        sizes[i] = std::log10(std::max(double(r.initial[i].box.longest_edge()) / std::max(longest, 1e-30), 1e-7));
    std::sort(sizes.begin(), sizes.end());
    v[1] = order_statistic(sizes, 0.5);
    v[2] = order_statistic(sizes, 0.9) - order_statistic(sizes, 0.1);
    const Vec3d e = bounds.extent();
    v[3] = longest > 0 ? std::max(std::log10(std::max(std::min({e.x, e.y, e.z}) / longest, 1e-6)), -6.0) : 0.0;

    // Spatial clustering: object centres binned on the reference lattice.
    const Lattice lattice(bounds, n);
    std::vector<std::uint32_t> counts(std::size_t(lattice.total()), 0);
    for (const Object& o : r.initial) ++counts[std::size_t(lattice.index(o.box.center().as<double>()))];
    std::size_t occupied = 0;
    double sum_sq = 0;
    const double mean = double(n) / double(counts.size());
    for (std::uint32_t c : counts) {
        occupied += c != 0;
        sum_sq += (double(c) - mean) * (double(c) - mean);
    }
    v[4] = double(occupied) / double(std::min<std::size_t>(n, counts.size()));
    const double cv = std::sqrt(sum_sq / double(counts.size())) / mean;
    v[5] = std::log10(std::max(cv, 1e-3));

    // Frame 0's rays, cast after frame 0's changes as the simulator casts them (§5.2.2).
    if (!r.frames.empty() && !r.frames[0].rays.empty()) {
        const std::vector<Segment>& rays = r.frames[0].rays;
        LiveSet live(r.initial);
        live.apply(r.frames[0]);
        const GroundTruth truth(live.objects());
        const std::size_t m = std::min(kFeatureRays, rays.size());
        std::vector<Uid> must, touch;
        double hits = 0;
        for (std::size_t i = 0; i < m; ++i) {
            truth.classify(rays[i * rays.size() / m], must, touch);
            hits += double(must.size());
        }
        v[6] = std::log10(1 + hits / double(m));
        double cells = 0;
        std::vector<double> lengths;
        lengths.reserve(rays.size());
        const double diagonal = length(e);
        for (const Segment& s : rays) {
            const Segmentd sd{s.p0.as<double>(), s.p1.as<double>()};
            cells += lattice.cells_crossed(sd);
            lengths.push_back(diagonal > 0 ? length(sd.delta()) / diagonal : 0.0);
        }
        v[7] = std::log10(1 + cells / double(rays.size()));
        std::sort(lengths.begin(), lengths.end());
        v[8] = order_statistic(lengths, 0.5);
    }
    double changes = 0;
    for (const Frame& fr : r.frames) changes += double(fr.change_count());
    v[9] = r.frames.empty() ? 0.0 : changes / double(r.frames.size()) / double(n);
    return f;
}

}  // namespace rcb
