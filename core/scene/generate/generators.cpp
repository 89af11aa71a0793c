#include "core/scene/generate/generators.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <unordered_set>

#include "core/base/error.h"
#include "core/base/random.h"
#include "core/scene/generate/physics.h"
#include "core/scene/generate/stream.h"

namespace rcb {
namespace {

// Stream numbers for mix_seed: each kind of randomness has its own stream (see generators.h).
constexpr std::uint64_t kObjectStream = 1;
constexpr std::uint64_t kDynamicsStream = 1'000'000;
constexpr std::uint64_t kRayStream = 2'000'000;  // + frame, frames ≤ 1 000 000
constexpr std::uint64_t kShapeStream = 4'000'000;
constexpr std::uint64_t kQueryStream = 5'000'000;  // + frame

Aabb box_from(const Vec3d& min, const Vec3d& max) { return {min.as<float>(), max.as<float>()}; }

Aabb box_around(const Vec3d& center, const Vec3d& extent) {
    return box_from(center - extent * 0.5, center + extent * 0.5);
}

/// One box in each of n cells of a k×k×k lattice of 10-unit cells (k = ⌈∛n⌉, cells chosen at
/// random): per axis an extent of `min_fill` to `max_fill` of the cell, placed at random inside the
/// cell less a `margin` (a fraction of the cell) at each face. No two boxes overlap.
std::vector<Object> lattice_objects(std::uint32_t n, Random& rng, double min_fill, double max_fill, double margin) {
    std::uint64_t k = 1;
    while (k * k * k < n) ++k;
    constexpr double cell = 10.0;
    // Partial Fisher–Yates: the first n entries become a uniform random choice of n cells.
    std::vector<std::uint32_t> cells(k * k * k);
    std::iota(cells.begin(), cells.end(), 0u);
    std::vector<Object> objects(n);
    for (std::uint32_t i = 0; i < n; ++i) {
        std::swap(cells[i], cells[i + rng.below(cells.size() - i)]);
        const std::uint64_t c = cells[i];
        const Vec3d origin{double(c % k) * cell, double((c / k) % k) * cell, double(c / (k * k)) * cell};
        Vec3d extent, min;
        for (int a = 0; a < 3; ++a) {
            extent[a] = cell * rng.uniform(min_fill, max_fill);
            min[a] = origin[a] + margin * cell + rng.uniform(0.0, (1 - 2 * margin) * cell - extent[a]);
        }
        objects[i] = {i + 1, box_from(min, min + extent)};
    }
    return objects;
}

/// "uni" (thesis §6.1): similar-sized boxes evenly spread without overlap, each strictly inside its
/// own lattice cell (40 to 70% of the cell per axis, 5% from its faces).
std::vector<Object> uniform_objects(const SceneSettings& s, Random& rng) {
    return lattice_objects(s.objects, rng, 0.4, 0.7, 0.05);
}

/// "irreg" (thesis §6.1, exported from a game engine): a ground of terrain tiles, a few buildings,
/// most objects small and crowded into clusters (many inside buildings), some medium props
/// scattered over the ground. Sizes span four orders of magnitude. y is up.
std::vector<Object> irregular_objects(const SceneSettings& s, Random& rng) {
    const std::uint32_t n = s.objects;
    // The world grows with the object count so that density stays game-like across presets.
    const double world = std::max(128.0, 1024.0 * std::cbrt(double(n) / 14021.0));
    const double height = world / 4;
    std::vector<Object> objects;
    objects.reserve(n);
    Uid next = 1;
    auto add = [&](const Aabb& box) {
        if (objects.size() < n) objects.push_back({next++, box});
    };

    // Large objects: 0.4% of the scene, at least two (a terrain tile and a building).
    const std::uint32_t large = std::min<std::uint32_t>(n, std::max<std::uint32_t>(2, std::lround(n * 0.004)));
    const std::uint32_t tiles_per_side = std::max<std::uint32_t>(1, std::lround(std::sqrt(large / 4.0)));
    const double tile = world / tiles_per_side;
    for (std::uint32_t i = 0; i < tiles_per_side * tiles_per_side && objects.size() + 1 < large; ++i) {
        const double x = (i % tiles_per_side) * tile, z = (i / tiles_per_side) * tile;
        const double relief = height * rng.uniform(0.02, 0.08);
        add(box_from({x, -relief, z}, {x + tile, relief * rng.uniform(0.2, 1.0), z + tile}));
    }
    std::vector<Aabb> buildings;
    while (objects.size() < large) {
        const Vec3d extent{world * rng.uniform(0.03, 0.12), height * rng.uniform(0.1, 0.6),
                           world * rng.uniform(0.03, 0.12)};
        const Vec3d min{rng.uniform(0, world - extent.x), 0.0, rng.uniform(0, world - extent.z)};
        buildings.push_back(box_from(min, min + extent));
        add(buildings.back());
    }

    // Clusters of small objects; sizes of clusters follow a Zipf-like law (a few very dense ones).
    const std::uint32_t rest = n - static_cast<std::uint32_t>(objects.size());
    const std::uint32_t scattered = rest * 15 / 100;
    const std::uint32_t clustered = rest - scattered;
    const std::uint32_t cluster_count = std::max<std::uint32_t>(2, n / 400);
    struct Cluster {
        Vec3d center;
        double radius;
        double weight;
    };
    std::vector<Cluster> clusters(cluster_count);
    double total_weight = 0;
    for (std::uint32_t c = 0; c < cluster_count; ++c) {
        Cluster& k = clusters[c];
        if (!buildings.empty() && rng.uniform() < 0.6) {  // inside a building: small objects in large ones
            const Aabb& b = buildings[rng.below(buildings.size())];
            const Aabbd bd = b.as<double>();
            k.center = {rng.uniform(bd.min.x, bd.max.x), rng.uniform(bd.min.y, bd.max.y),
                        rng.uniform(bd.min.z, bd.max.z)};
            k.radius = 0.25 * std::min(bd.extent().x, bd.extent().z);
        } else {
            k.center = {rng.uniform(0, world), rng.uniform(0, 0.1 * height), rng.uniform(0, world)};
            k.radius = world * rng.uniform(0.005, 0.03);
        }
        k.weight = 1.0 / std::pow(c + 1.0, 0.8);
        total_weight += k.weight;
    }
    // Cluster sizes by largest remainder, so they add up to `clustered` exactly.
    std::vector<std::uint32_t> members(cluster_count);
    std::uint32_t assigned = 0;
    for (std::uint32_t c = 0; c < cluster_count; ++c) {
        members[c] = static_cast<std::uint32_t>(clustered * clusters[c].weight / total_weight);
        assigned += members[c];
    }
    for (std::uint32_t c = 0; assigned < clustered; c = (c + 1) % cluster_count, ++assigned) ++members[c];
    for (std::uint32_t c = 0; c < cluster_count; ++c) {
        for (std::uint32_t m = 0; m < members[c]; ++m) {
            const Cluster& k = clusters[c];
            Vec3d center{k.center.x + k.radius * rng.normal(), k.center.y + 0.5 * k.radius * rng.normal(),
                         k.center.z + k.radius * rng.normal()};
            center.y = std::max(center.y, 0.0);
            const double size = rng.log_uniform(0.05, 3.0);
            add(box_around(center,
                           {size * rng.uniform(0.5, 1.5), size * rng.uniform(0.5, 1.5), size * rng.uniform(0.5, 1.5)}));
        }
    }
    // Medium props (trees, vehicles, rocks) scattered over the whole ground.
    while (objects.size() < n) {
        const double size = rng.log_uniform(1.0, 15.0);
        const Vec3d extent{size * rng.uniform(0.5, 1.5), size * rng.uniform(0.5, 2.0), size * rng.uniform(0.5, 1.5)};
        const Vec3d min{rng.uniform(0, world), 0.0, rng.uniform(0, world)};
        add(box_from(min, min + extent));
    }
    return objects;
}

/// "jittered": the peer-comparison uniform scene: one box per lattice cell, 4 to 8 units per axis,
/// anywhere inside its cell. The boxes are larger than "uniform"'s and reach their cells' faces, so
/// a ray meets more of them.
std::vector<Object> jittered_objects(const SceneSettings& s, Random& rng) {
    return lattice_objects(s.objects, rng, 0.4, 0.8, 0.0);
}

/// "clusters": the peer-comparison irregular scene, harder than "irregular": 0.15% huge objects
/// (half floor slabs 110 to 300 units wide and 5 to 17 thick, half blocks 30 to 180 units per
/// axis) anywhere in the world; 5% of the objects inside them; 10% medium boxes spread uniformly;
/// the rest in n / 1500 gaussian clusters (σ 15 to 45 units, weights over a decade). Small sizes
/// are log-normal (median about 2.8 units on the longest edge). The world's edge is
/// 400·(n / 14021)^(1/3) while every size stays absolute, so the density, and the hits per unit of
/// ray length, are the same at every object count.
std::vector<Object> cluster_objects(const SceneSettings& s, Random& rng) {
    const std::uint32_t n = s.objects;
    const double world = 400.0 * std::cbrt(double(n) / 14021.0);
    std::vector<Object> objects;
    objects.reserve(n);
    Uid next = 1;
    auto add = [&](const Vec3d& center, const Vec3d& extent) {
        if (objects.size() < n) objects.push_back({next++, box_around(center, extent)});
    };
    auto in_world = [&] { return Vec3d{rng.uniform(0, world), rng.uniform(0, world), rng.uniform(0, world)}; };
    auto small = [&](double median, double sigma) {
        const double size = median * std::exp(sigma * rng.normal());
        return Vec3d{size * rng.uniform(0.4, 1.0), size * rng.uniform(0.4, 1.0), size * rng.uniform(0.4, 1.0)};
    };
    const auto huge = std::min<std::uint32_t>(n, std::max<std::uint32_t>(1, std::lround(n * 0.0015)));
    std::vector<Aabbd> huge_boxes;
    for (std::uint32_t i = 0; i < huge; ++i) {
        const Vec3d extent = rng.uniform() < 0.5
                                 ? Vec3d{rng.uniform(110, 300), rng.uniform(5, 17), rng.uniform(110, 300)}
                                 : Vec3d{rng.uniform(30, 180), rng.uniform(30, 180), rng.uniform(30, 180)};
        add(in_world(), extent);
        huge_boxes.push_back(objects.back().box.as<double>());
    }
    const std::uint32_t inside = std::min<std::uint32_t>(n - huge, std::lround(n * 0.05));
    for (std::uint32_t i = 0; i < inside; ++i) {
        const Aabbd& h = huge_boxes[rng.below(huge_boxes.size())];
        const Vec3d center{rng.uniform(h.min.x, h.max.x), rng.uniform(h.min.y, h.max.y), rng.uniform(h.min.z, h.max.z)};
        add(center, small(3.2, 0.75));
    }
    const std::uint32_t medium = std::min<std::uint32_t>(n - huge - inside, std::lround(n * 0.10));
    for (std::uint32_t i = 0; i < medium; ++i) add(in_world(), small(8.5, 0.8));
    struct Cluster {
        Vec3d center;
        double sigma;
    };
    const std::uint32_t cluster_count = std::max<std::uint32_t>(1, n / 1500);
    std::vector<Cluster> clusters(cluster_count);
    std::vector<double> weight(cluster_count);
    double total = 0;
    for (std::uint32_t c = 0; c < cluster_count; ++c) {
        clusters[c] = {{rng.uniform(0.1, 0.9) * world, rng.uniform(0.1, 0.9) * world, rng.uniform(0.1, 0.9) * world},
                       rng.uniform(15, 45)};
        total += weight[c] = rng.log_uniform(0.1, 1.0);
    }
    // Cumulative weights: each object picks its cluster by one uniform draw.
    for (std::uint32_t c = 1; c < cluster_count; ++c) weight[c] += weight[c - 1];
    while (objects.size() < n) {
        const double pick = rng.uniform(0, total);
        const auto c = std::min<std::size_t>(std::lower_bound(weight.begin(), weight.end(), pick) - weight.begin(),
                                             cluster_count - 1);
        const Cluster& k = clusters[c];
        add({k.center.x + k.sigma * rng.normal(), k.center.y + k.sigma * rng.normal(),
             k.center.z + k.sigma * rng.normal()},
            small(3.2, 0.75));
    }
    return objects;
}

// Failure-mode scenes: each one breaks an assumption some structure makes. Sizes are in
// the same units as "irregular" so that rays and dynamics behave alike.

/// "stadium" (the "teapot in a stadium", Haines 1988): one huge box around a tiny dense cluster of
/// n − 1 small boxes. A grid sized by the bounds puts the whole cluster in one cell.
std::vector<Object> stadium_objects(const SceneSettings& s, Random& rng) {
    std::vector<Object> objects;
    objects.reserve(s.objects);
    if (s.objects == 0) return objects;
    objects.push_back({1, box_around({0, 0, 0}, {2000, 2000, 2000})});
    for (Uid i = 2; i <= s.objects; ++i) {
        const Vec3d c{rng.normal() * 0.5, rng.normal() * 0.5, rng.normal() * 0.5};
        const double size = rng.log_uniform(0.005, 0.05);
        objects.push_back({i, box_around(c, {size, size, size})});
    }
    return objects;
}

/// Stacks of up to 1000 objects at random places of a world that grows with n: every object of a
/// stack is the same box ("identical") or has the same centroid with half-sizes from 0.005 to 50
/// ("same-centroid": equal Morton codes, grid cells that no split can relieve).
std::vector<Object> stacked_objects(const SceneSettings& s, Random& rng, bool same_size) {
    const std::uint32_t n = s.objects;
    const std::uint32_t stacks = std::max<std::uint32_t>(1, (n + 999) / 1000);
    const double world = 100.0 * std::cbrt(double(stacks));
    std::vector<Vec3d> centers(stacks);
    // Integer centres and half-sizes in steps of 2^-10: c ± h is exact in float (at most 23
    // significant bits below 2^13), so the centroids are identical in float too, not only in double.
    for (Vec3d& c : centers)
        c = {std::round(rng.uniform(0, world)), std::round(rng.uniform(0, world)), std::round(rng.uniform(0, world))};
    std::vector<Object> objects;
    objects.reserve(n);
    for (std::uint32_t i = 0; i < n; ++i) {
        const Vec3d& c = centers[i % stacks];
        const double h = same_size ? 0.5 : std::round(rng.log_uniform(0.005, 50.0) * 1024.0) / 1024.0;
        objects.push_back({i + 1, box_around(c, {2 * h, 2 * h, 2 * h})});
    }
    return objects;
}

/// "nested": all n objects share one centroid (one stack of every object, where "same-centroid"
/// caps a stack at 1000), cubes with half-sizes from 0.005 to 50 nested around the origin: every
/// cell, Morton code and subtree near the centre holds thousands of objects, and a ray starting at
/// the centre is inside all of them. Half-sizes in steps of 2^-10 keep the centroid exact in float.
std::vector<Object> nested_objects(const SceneSettings& s, Random& rng) {
    std::vector<Object> objects;
    objects.reserve(s.objects);
    for (std::uint32_t i = 0; i < s.objects; ++i) {
        const double h = std::round(rng.log_uniform(0.005, 50.0) * 1024.0) / 1024.0;
        objects.push_back({i + 1, box_around({0, 0, 0}, {2 * h, 2 * h, 2 * h})});
    }
    return objects;
}

/// "flat": every box in the plane y = 0 with zero thickness (a floor of decals).
std::vector<Object> flat_objects(const SceneSettings& s, Random& rng) {
    const double world = 10.0 * std::sqrt(double(std::max<std::uint32_t>(s.objects, 1)));
    std::vector<Object> objects;
    objects.reserve(s.objects);
    for (std::uint32_t i = 0; i < s.objects; ++i) {
        const double x = rng.uniform(0, world), z = rng.uniform(0, world);
        objects.push_back({i + 1, box_from({x, 0, z}, {x + rng.uniform(0.1, 3), 0, z + rng.uniform(0.1, 3)})});
    }
    return objects;
}

/// "slivers": long thin axis-aligned boxes (a tenth to half the world long, 10^-3 thick) and, for
/// every fourth object, a zero-volume box (a point, a line or a plane patch).
std::vector<Object> sliver_objects(const SceneSettings& s, Random& rng) {
    const double world = 10.0 * std::cbrt(double(std::max<std::uint32_t>(s.objects, 1)));
    std::vector<Object> objects;
    objects.reserve(s.objects);
    for (std::uint32_t i = 0; i < s.objects; ++i) {
        const Vec3d p{rng.uniform(0, world), rng.uniform(0, world), rng.uniform(0, world)};
        Vec3d extent{1e-3, 1e-3, 1e-3};
        const int axis = int(rng.below(3));
        if (i % 4 == 3) {
            const int flat_axes = int(rng.below(4));  // 0: a point … 3: a plane patch
            extent = {0, 0, 0};
            for (int k = 1; k < flat_axes; ++k) extent[(axis + k) % 3] = rng.uniform(0.1, 2);
        } else {
            extent[axis] = world * rng.uniform(0.1, 0.5);
        }
        objects.push_back({i + 1, box_from(p, p + extent)});
    }
    return objects;
}

/// "outlier": an irregular scene of n − 1 objects and one unit box 10^6 world sizes away, so the
/// bounds are stretched by 10^6 while the scene itself is unchanged.
std::vector<Object> outlier_objects(const SceneSettings& s, Random& rng);

/// The shape moved by `shift` (its points; radii, extents and rotation kept), in double, rounded
/// once to float.
Shape translated(Shape s, const Vec3d& shift) {
    int points = 0;
    switch (s.kind) {
        case ShapeKind::box:
            break;
        case ShapeKind::triangle:
            points = 3;
            break;
        case ShapeKind::obb:
        case ShapeKind::sphere:
            points = 1;  // the centre
            break;
        case ShapeKind::capsule:
            points = 2;
            break;
    }
    for (int p = 0; p < points; ++p)
        for (int a = 0; a < 3; ++a) s.v[3 * p + a] = float(double(s.v[3 * p + a]) + shift[a]);
    return s;
}

/// Picks `k` distinct indices below `n` (k much smaller than n: rejection is cheap).
std::vector<std::size_t> distinct_indices(std::size_t k, std::size_t n, Random& rng) {
    std::vector<std::size_t> out;
    std::unordered_set<std::size_t> used;
    k = std::min(k, n);
    if (2 * k > n) {  // dense choice: shuffle instead of rejecting
        std::vector<std::size_t> all(n);
        std::iota(all.begin(), all.end(), std::size_t{0});
        for (std::size_t i = 0; i < k; ++i) std::swap(all[i], all[i + rng.below(n - i)]);
        return {all.begin(), all.begin() + k};
    }
    while (out.size() < k) {
        std::size_t i = rng.below(n);
        if (used.insert(i).second) out.push_back(i);
    }
    return out;
}

Frame frame_changes(const LiveSet& live, const DynamicsSettings& d, Uid& next_uid, Random& rng) {
    Frame f;
    const std::size_t n = live.size();
    if (n == 0) return f;
    const auto changes = static_cast<std::size_t>(std::llround(d.change_fraction * n));
    const auto inserts = static_cast<std::size_t>(std::llround(changes * d.insert_share));
    const auto removes = std::min(n, static_cast<std::size_t>(std::llround(changes * d.remove_share)));
    const std::size_t moves = std::min(n - removes, changes - std::min(changes, inserts + removes));
    const auto& objects = live.objects();
    const std::vector<std::size_t> picked = distinct_indices(removes + moves, n, rng);
    for (std::size_t i = 0; i < removes; ++i) f.removes.push_back(objects[picked[i]].uid);
    for (std::size_t i = removes; i < picked.size(); ++i) {
        const Object& o = objects[picked[i]];
        const double reach = d.move_scale * double(o.box.longest_edge());
        const Vec3d shift{reach * rng.uniform(-1, 1), reach * rng.uniform(-1, 1), reach * rng.uniform(-1, 1)};
        if (o.shape.kind == ShapeKind::box)
            f.moves.push_back({o.uid, box_from(o.box.min.as<double>() + shift, o.box.max.as<double>() + shift)});
        else
            f.moves.push_back(shaped_object(o.uid, translated(o.shape, shift)));
    }
    // An insert copies the size of a random live object and lands near another one, so inserts
    // follow the scene's own size and position distribution, whatever the scene.
    // A shaped object's copy keeps its kind and rotation, its bounds centred where a box would be.
    for (std::size_t i = 0; i < inserts; ++i) {
        const Object& model = objects[rng.below(n)];
        const Aabbd shape = model.box.as<double>();
        const Aabbd anchor = objects[rng.below(n)].box.as<double>();
        Vec3d center = anchor.center();
        for (int a = 0; a < 3; ++a) center[a] += rng.uniform(-1, 1) * std::max(anchor.extent()[a], shape.extent()[a]);
        if (model.shape.kind == ShapeKind::box)
            f.inserts.push_back({next_uid++, box_around(center, shape.extent())});
        else
            f.inserts.push_back(shaped_object(next_uid++, translated(model.shape, center - shape.center())));
    }
    return f;
}

/// The densest cell of a 16³ grid over the bounds: `dense` rays aim there.
Aabbd densest_region(const std::vector<Object>& live, const Aabbd& bounds) {
    constexpr int k = 16;
    std::vector<std::uint32_t> count(k * k * k, 0);
    const Vec3d size = bounds.extent();
    auto cell_of = [&](double v, int a) {
        if (size[a] <= 0) return 0;
        return std::clamp(int((v - bounds.min[a]) / size[a] * k), 0, k - 1);
    };
    for (const Object& o : live) {
        const Vec3d c = o.box.as<double>().center();
        ++count[(cell_of(c.z, 2) * k + cell_of(c.y, 1)) * k + cell_of(c.x, 0)];
    }
    const int best = int(std::max_element(count.begin(), count.end()) - count.begin());
    const Vec3d cell = size * (1.0 / k);
    const Vec3d min = bounds.min + Vec3d{cell.x * (best % k), cell.y * ((best / k) % k), cell.z * (best / (k * k))};
    return {min, min + cell};
}

Segment segment_from(const Vec3d& p0, const Vec3d& p1) { return {p0.as<float>(), p1.as<float>()}; }

}  // namespace

std::vector<std::string> ray_mode_names() {
    return {"center", "dense", "los", "ground", "shots", "faces", "inside", "fire", "sight", "sensor"};
}

std::vector<std::string> scene_generators() {
    std::vector<std::string> generators{"uniform",       "irregular", "jittered", "clusters", "stadium", "identical",
                                        "same-centroid", "flat",      "slivers",  "outlier",  "nested"};
    for (const std::string& g : physics_generators()) generators.push_back(g);
    return generators;
}

std::vector<std::string> failure_mode_generators() {
    return {"stadium", "identical", "same-centroid", "flat", "slivers", "outlier", "nested"};
}

std::vector<std::string> preset_names() {
    std::vector<std::string> names{"uni-s",    "uni-m",      "uni-l",      "irreg-s",    "irreg-m",    "irreg-l",
                                   "irreg-xl", "jittered-m", "jittered-l", "clusters-m", "clusters-l", "clusters-xl"};
    for (const std::string& g : failure_mode_generators())
        for (const char* size : {"-s", "-m"}) names.push_back(g + size);
    return names;
}

SceneSettings preset_settings(std::string_view name) {
    SceneSettings s;
    s.preset = std::string(name);
    const std::string n(name);
    // Failure-mode presets: "<generator>-s" has 1 000 objects, "<generator>-m" 10 000.
    for (const std::string& g : failure_mode_generators()) {
        if (n == g + "-s" || n == g + "-m") {
            s.generator = g;
            s.objects = n.back() == 's' ? 1000 : 10000;
            return s;
        }
    }
    s.generator.clear();  // "x-l" is not a preset (SceneSettings' default generator must not make it one)
    if (n.rfind("uni-", 0) == 0)
        s.generator = "uniform";
    else if (n.rfind("irreg-", 0) == 0)
        s.generator = "irregular";
    else if (n.rfind("jittered-", 0) == 0 && n != "jittered-s")
        s.generator = "jittered";
    else if (n.rfind("clusters-", 0) == 0 && n != "clusters-s")
        s.generator = "clusters";
    const std::string size = n.substr(n.find('-') + 1);
    if (size == "s")
        s.objects = 99;
    else if (size == "m")
        s.objects = 5104;
    else if (size == "l")
        s.objects = 14021;
    else if (size == "xl" && (s.generator == "irregular" || s.generator == "clusters"))
        s.objects = 1'000'000;
    else
        s.generator.clear();
    if (n.find('-') == std::string::npos || s.generator.empty()) {
        throw InputError("unknown preset '" + n + "' (known: " + join(preset_names()) + ")");
    }
    return s;
}

namespace {

/// "a,b:0.5": names with non-negative weights (1 when left out), every name one of `known`, the
/// weights adding up to more than zero. `what` ("ray mix") and `item` ("mode") name them in errors.
std::vector<std::pair<std::string, double>> parse_weighted(const std::string& text, const std::string& what,
                                                           const std::string& item,
                                                           const std::vector<std::string>& known) {
    std::vector<std::pair<std::string, double>> mix;
    std::size_t start = 0;
    while (start <= text.size()) {
        std::size_t comma = text.find(',', start);
        std::string entry = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        std::size_t colon = entry.find(':');
        std::string name = entry.substr(0, colon);
        double weight = 1;
        if (colon != std::string::npos) {
            const std::string w = entry.substr(colon + 1);
            char* end = nullptr;
            weight = std::strtod(w.c_str(), &end);
            if (w.empty() || *end != '\0' || !std::isfinite(weight) || weight < 0)
                throw InputError(what + " '" + text + "': weight '" + w + "' of " + name +
                                 " is not a non-negative number");
        }
        if (std::find(known.begin(), known.end(), name) == known.end())
            throw InputError(what + " '" + text + "': unknown " + item + " '" + name + "' (known: " + join(known) +
                             ")");
        mix.emplace_back(name, weight);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    double total = 0;
    for (const auto& m : mix) total += m.second;
    if (!(total > 0)) throw InputError(what + " '" + text + "': the weights add up to zero");
    return mix;
}

/// `n` split by `weights` with largest remainders, so the split is exact and in a fixed order.
std::vector<std::uint32_t> split_by_weight(std::uint32_t n, const std::vector<double>& weights) {
    double total = 0;
    for (double w : weights) total += w;
    std::vector<std::uint32_t> counts;
    std::uint32_t assigned = 0;
    for (double w : weights) {
        counts.push_back(static_cast<std::uint32_t>(n * (w / total)));
        assigned += counts.back();
    }
    for (std::size_t i = 0; assigned < n; i = (i + 1) % counts.size())
        if (weights[i] > 0) ++counts[i], ++assigned;
    return counts;
}

}  // namespace

std::vector<RayMode> parse_ray_mix(const std::string& text) {
    std::vector<RayMode> mix;
    for (auto& [mode, weight] : parse_weighted(text, "ray mix", "mode", ray_mode_names()))
        mix.push_back({mode, weight});
    return mix;
}

std::vector<QueryShare> parse_query_mix(const std::string& text) {
    const std::vector<std::string> known(std::begin(kQueryKindNames), std::end(kQueryKindNames));
    std::vector<QueryShare> mix;
    for (auto& [name, weight] : parse_weighted(text, "query mix", "kind", known))
        mix.push_back({QueryKind(std::find(known.begin(), known.end(), name) - known.begin()), weight});
    return mix;
}

bool asks_all_only(const std::vector<QueryShare>& mix) {
    return std::all_of(mix.begin(), mix.end(),
                       [](const QueryShare& q) { return q.kind == QueryKind::all || q.weight == 0; });
}

std::vector<QueryKind> generate_kinds(std::size_t rays, const std::vector<QueryShare>& mix, std::uint64_t seed,
                                      std::uint32_t frame) {
    std::vector<QueryKind> kinds;
    if (asks_all_only(mix) || rays == 0) return kinds;
    std::vector<double> weights;
    for (const QueryShare& q : mix) weights.push_back(q.weight);
    const std::vector<std::uint32_t> counts = split_by_weight(std::uint32_t(rays), weights);
    for (std::size_t m = 0; m < mix.size(); ++m) kinds.insert(kinds.end(), counts[m], mix[m].kind);
    // Shuffled from the query stream, so kinds fall on every ray mode alike and neither the rays
    // nor the dynamics change when a mix is added.
    Random rng(mix_seed(seed, kQueryStream + frame));
    rng.shuffle(kinds);
    if (std::all_of(kinds.begin(), kinds.end(), [](QueryKind k) { return k == QueryKind::all; })) kinds.clear();
    return kinds;
}

std::vector<QueryKind> ray_kinds(std::size_t rays, const RaySettings& settings, std::uint64_t seed,
                                 std::uint32_t frame) {
    check_ray_settings(settings);
    const bool own_kinds =
        std::any_of(settings.mix.begin(), settings.mix.end(), [](const RayMode& m) { return m.kind.has_value(); });
    if (!own_kinds) return generate_kinds(rays, settings.query_mix, seed, frame);
    std::vector<QueryKind> kinds;
    if (rays == 0) return kinds;
    // generate_rays makes exactly these counts per mode, in the mix's order (or none at all).
    std::vector<double> weights;
    for (const RayMode& m : settings.mix) weights.push_back(m.weight);
    const std::vector<std::uint32_t> counts = split_by_weight(settings.per_frame, weights);
    for (std::size_t m = 0; m < settings.mix.size(); ++m)
        kinds.insert(kinds.end(), counts[m], settings.mix[m].kind.value_or(QueryKind::all));
    if (kinds.size() != rays) throw std::logic_error("ray_kinds: the rays do not follow the mix");
    if (std::all_of(kinds.begin(), kinds.end(), [](QueryKind k) { return k == QueryKind::all; })) kinds.clear();
    return kinds;
}

std::vector<std::string> query_preset_names() { return {"shots", "visibility", "sensors", "game"}; }

std::vector<RayMode> query_preset_mix(std::string_view name) {
    const RayMode fire{"fire", 1, QueryKind::closest}, sight{"sight", 1, QueryKind::any},
        sensor{"sensor", 1, QueryKind::all};
    if (name == "shots") return {fire};
    if (name == "visibility") return {sight};
    if (name == "sensors") return {sensor};
    if (name == "game") {
        std::vector<RayMode> mix{fire, sight, sensor};
        mix[0].weight = 0.5, mix[1].weight = 0.3, mix[2].weight = 0.2;
        return mix;
    }
    throw InputError("unknown query preset " + quoted_excerpt(name) + " (known: " + join(query_preset_names()) + ")");
}

RaySettings with_query_preset(RaySettings rays, std::string_view name) {
    rays.mix = query_preset_mix(name);
    rays.query_mix.clear();
    rays.queries = std::string(name);
    return rays;
}

void check_ray_settings(const RaySettings& rays) {
    const bool own_kinds =
        std::any_of(rays.mix.begin(), rays.mix.end(), [](const RayMode& m) { return m.kind.has_value(); });
    if (own_kinds && !asks_all_only(rays.query_mix))
        throw InputError("a query preset sets each ray mode's kind; it takes no query mix");
}

nlohmann::json rays_json(const RaySettings& rays) {
    nlohmann::json mix = nlohmann::json::array();
    for (const RayMode& m : rays.mix) {
        nlohmann::json e = {{"mode", m.mode}, {"weight", m.weight}};
        if (m.kind) e["kind"] = query_kind_name(*m.kind);  // only with a preset: older bytes stay
        mix.push_back(std::move(e));
    }
    nlohmann::json j = {{"per_frame", rays.per_frame}, {"mix", mix}};
    // Only when some ray is not `all`, so that an all-hits scene's meta and bytes stay as they were.
    if (!asks_all_only(rays.query_mix)) j["query_mix"] = query_mix_json(rays.query_mix);
    if (!rays.queries.empty()) j["queries"] = rays.queries;
    return j;
}

nlohmann::json query_mix_json(const std::vector<QueryShare>& mix) {
    nlohmann::json j = nlohmann::json::array();
    for (const QueryShare& q : mix) j.push_back({{"kind", query_kind_name(q.kind)}, {"weight", q.weight}});
    return j;
}

namespace {

std::vector<Object> generate_boxes(const SceneSettings& s) {
    Random rng(mix_seed(s.seed, kObjectStream));
    if (s.generator == "uniform") return uniform_objects(s, rng);
    if (s.generator == "irregular") return irregular_objects(s, rng);
    if (s.generator == "jittered") return jittered_objects(s, rng);
    if (s.generator == "clusters") return cluster_objects(s, rng);
    if (s.generator == "stadium") return stadium_objects(s, rng);
    if (s.generator == "identical") return stacked_objects(s, rng, true);
    if (s.generator == "same-centroid") return stacked_objects(s, rng, false);
    if (s.generator == "flat") return flat_objects(s, rng);
    if (s.generator == "slivers") return sliver_objects(s, rng);
    if (s.generator == "outlier") return outlier_objects(s, rng);
    if (s.generator == "nested") return nested_objects(s, rng);
    throw InputError("unknown scene generator '" + s.generator + "' (known: " + join(scene_generators()) + ")");
}

}  // namespace

std::array<float, 4> random_rotation(Random& rng) {
    const double u1 = rng.uniform(), u2 = 2 * std::numbers::pi * rng.uniform(),
                 u3 = 2 * std::numbers::pi * rng.uniform();
    const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
    return {float(b * std::cos(u3)), float(a * std::sin(u2)), float(a * std::cos(u2)), float(b * std::sin(u3))};
}

SceneSettings with_generator(const SceneSettings& settings) {
    SceneSettings s = settings;
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
    if (!s.kind.empty()) s.generator = std::move(s.kind), s.kind.clear();
#pragma GCC diagnostic pop
    return s;
}

std::vector<Object> generate_objects(const SceneSettings& settings) {
    const SceneSettings s = with_generator(settings);
    check_shapes(s.shapes);
    if (is_physics_generator(s.generator)) {
        SceneSettings still = s;
        still.frames = 0;
        return generate_physics_scene(still).initial;
    }
    std::vector<Object> objects = generate_boxes(s);
    if (!s.shapes.any()) return objects;
    return apply_shapes(std::move(objects), s.shapes, s.seed);
}

std::vector<Object> apply_shapes(std::vector<Object> objects, const ShapeSettings& shapes, std::uint64_t seed) {
    check_shapes(shapes);
    const std::size_t n = objects.size();
    Random rng(mix_seed(seed, kShapeStream));
    // Exact counts in a fixed order (rotated, spheres, capsules), capped so they never exceed n
    // when rounding adds up past it.
    std::size_t counts[3], total = 0;
    const double shares[3] = {shapes.rotated_share, shapes.sphere_share, shapes.capsule_share};
    for (int k = 0; k < 3; ++k) {
        counts[k] = std::min(n - total, static_cast<std::size_t>(std::llround(shares[k] * double(n))));
        total += counts[k];
    }
    // Partial Fisher–Yates: the first `total` indices are a uniform random choice.
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), std::size_t{0});
    for (std::size_t i = 0; i < total; ++i) std::swap(order[i], order[i + rng.below(n - i)]);
    std::size_t next = 0;
    for (int k = 0; k < 3; ++k)
        for (std::size_t i = 0; i < counts[k]; ++i) {
            Object& o = objects[order[next++]];
            const Vec3d c = o.box.as<double>().center();
            const Vec3d h = o.box.as<double>().extent() * 0.5;
            if (k == 0) {
                o = shaped_object(o.uid, Shape::obb(c.as<float>(), h.as<float>(), random_rotation(rng)));
            } else if (k == 1) {
                o = shaped_object(o.uid, Shape::sphere(c.as<float>(), float(std::min({h.x, h.y, h.z}))));
            } else {
                const int axis = h.x >= h.y && h.x >= h.z ? 0 : (h.y >= h.z ? 1 : 2);
                const double r = std::min(h[(axis + 1) % 3], h[(axis + 2) % 3]);
                Vec3d p0 = c, p1 = c;
                p0[axis] -= h[axis] - r, p1[axis] += h[axis] - r;
                o = shaped_object(o.uid, Shape::capsule(p0.as<float>(), p1.as<float>(), float(r)));
            }
        }
    return objects;
}

void check_shapes(const ShapeSettings& s) {
    auto share = [](const char* name, double v) {
        if (!(v >= 0 && v <= 1))  // NaN fails too
            throw InputError(std::string(name) + ": expected a number in 0..1, got " + std::to_string(v));
    };
    share("rotated_share", s.rotated_share);
    share("sphere_share", s.sphere_share);
    share("capsule_share", s.capsule_share);
    if (s.rotated_share + s.sphere_share + s.capsule_share > 1)
        throw InputError("rotated_share + sphere_share + capsule_share exceeds 1");
}

namespace {

std::vector<Object> outlier_objects(const SceneSettings& s, Random& rng) {
    if (s.objects == 0) return {};
    SceneSettings rest = s;
    rest.objects = s.objects - 1;
    std::vector<Object> objects = irregular_objects(rest, rng);
    const Aabb b = objects.empty() ? Aabb{{0, 0, 0}, {1, 1, 1}} : bounds_of(objects);
    const double far = 1e6 * std::max(1.0, double(b.longest_edge()));
    const Vec3d at{double(b.max.x) + far, double(b.max.y), double(b.max.z) + far};
    objects.push_back({s.objects, box_from(at, at + Vec3d{1, 1, 1})});
    return objects;
}

}  // namespace

namespace {

/// Half the box's diagonal (its bounding sphere's radius) and a little more: a point this far from
/// the centre lies outside the box, so the query presets' rays never meet their own agent.
double clearance(const Aabbd& box) {
    const Vec3d e = box.extent();
    return 0.5 * std::sqrt(e.x * e.x + e.y * e.y + e.z * e.z) * 1.01 + 1e-6 * (1 + box.longest_edge());
}

/// The query presets' rays from agent `a` (generators.h, RayMode): `fire`, `sight` (towards a second
/// agent drawn by `another`) and `sensor`. A sight line between agents whose spheres overlap has
/// no length left; it becomes the zero-length segment at the middle of the two clearances.
template <class Another>
Segment agent_ray(const std::string& mode, const Aabbd& a, Another&& another, Random& rng, double diagonal) {
    const Vec3d from = a.center();
    if (mode == "sight") {
        // Another agent, not one at the same place (a few draws; a stack of identical boxes may
        // have no other place, and its sight line is then a point just outside the agent).
        Aabbd b = another();
        Vec3d d = b.center() - from;
        for (int draw = 0; draw < 8 && d.x == 0 && d.y == 0 && d.z == 0; ++draw) b = another(), d = b.center() - from;
        const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
        const double s0 = clearance(a), s1 = len - clearance(b);
        if (!(len > 0)) {
            const Vec3d point = from + Vec3d{s0, 0, 0};
            return segment_from(point, point);
        }
        if (s1 <= s0) {
            const Vec3d mid = from + d * (0.5 * (s0 + std::max(s1, 0.0)) / len);
            return segment_from(mid, mid);
        }
        return segment_from(from + d * (s0 / len), from + d * (s1 / len));
    }
    const Vec3d dir = rng.direction();
    const Vec3d start = from + dir * clearance(a);
    const double len = mode == "fire" ? 0.25 * diagonal : 3.0 * a.longest_edge();
    return segment_from(start, start + dir * std::max(len, 1e-6));
}

}  // namespace

std::vector<Segment> generate_rays(const std::vector<Object>& live, const RaySettings& settings, std::uint64_t seed,
                                   std::uint32_t frame) {
    std::vector<Segment> rays;
    if (live.empty() || settings.per_frame == 0) return rays;
    Random rng(mix_seed(seed, kRayStream + frame));
    const Aabbd bounds = bounds_of(live).as<double>();
    const Vec3d center = bounds.center();
    const Vec3d ext = bounds.extent();
    const double diagonal = std::sqrt(ext.x * ext.x + ext.y * ext.y + ext.z * ext.z);
    const double reach = std::max(0.55 * diagonal, 1e-3);  // from the centre, past every face
    // Rays per mode by largest remainder, so the mix is exact and in a fixed order.
    std::vector<double> weights;
    for (const RayMode& m : settings.mix) weights.push_back(m.weight);
    const std::vector<std::uint32_t> counts = split_by_weight(settings.per_frame, weights);

    const Aabbd dense = densest_region(live, bounds);
    auto random_object = [&]() -> Aabbd { return live[rng.below(live.size())].box.as<double>(); };
    for (std::size_t m = 0; m < settings.mix.size(); ++m) {
        const std::string& mode = settings.mix[m].mode;
        for (std::uint32_t i = 0; i < counts[m]; ++i) {
            if (mode == "center") {
                rays.push_back(segment_from(center, center + rng.direction() * reach));
            } else if (mode == "dense") {
                const Vec3d target{rng.uniform(dense.min.x, dense.max.x), rng.uniform(dense.min.y, dense.max.y),
                                   rng.uniform(dense.min.z, dense.max.z)};
                Vec3d d = target - center;
                const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
                d = len > 0 ? d * (1.0 / len) : rng.direction();
                rays.push_back(segment_from(center, center + d * reach));
            } else if (mode == "los") {
                // Two statements: the order of a call's arguments is unspecified (GCC and clang differ),
                // and the same seed must give the same bytes with both.
                const Vec3d from = random_object().center();
                rays.push_back(segment_from(from, random_object().center()));
            } else if (mode == "ground") {
                const Aabbd o = random_object();
                const Vec3d top{0.5 * (o.min.x + o.max.x), o.max.y, 0.5 * (o.min.z + o.max.z)};
                const double depth = o.extent().y + 0.02 * ext.y;
                rays.push_back(segment_from(top, top - Vec3d{0, depth, 0}));
            } else if (mode == "faces") {
                // Axis-parallel through the whole bounds, lying in a box's face plane (half of them
                // along an edge line too), or in a plane of a dyadic lattice over the bounds (the
                // planes where grid and Morton cells meet when the lattice starts at the bounds).
                const int axis = int(rng.below(3)), u = (axis + 1) % 3, w = (axis + 2) % 3;
                Vec3d p;
                if (rng.below(2) == 0) {
                    const Aabbd o = random_object();
                    p = o.center();
                    p[u] = rng.below(2) ? o.min[u] : o.max[u];
                    p[w] = rng.below(2) ? rng.uniform(o.min[w], o.max[w]) : (rng.below(2) ? o.min[w] : o.max[w]);
                } else {
                    const double cells = double(std::uint64_t(1) << (1 + rng.below(10)));
                    for (int a : {u, w})
                        p[a] = bounds.min[a] + ext[a] * double(rng.below(std::uint64_t(cells) + 1)) / cells;
                }
                Vec3d q = p;
                p[axis] = bounds.min[axis] - 0.01 * ext[axis];
                q[axis] = bounds.max[axis] + 0.01 * ext[axis];
                if (rng.below(2)) std::swap(p, q);
                rays.push_back(segment_from(p, q));
            } else if (mode == "inside") {
                // From a uniform point inside a random object's box, in a uniform direction, long
                // enough to leave the scene: rays that start among a crowd (inside every box of a
                // nested stack) and cross the rest of the scene.
                const Aabbd o = random_object();
                Vec3d p;
                for (int a = 0; a < 3; ++a) p[a] = rng.uniform(o.min[a], o.max[a]);
                rays.push_back(segment_from(p, p + rng.direction() * 2.0 * reach));
            } else if (mode == "shots") {
                const Aabbd o = random_object();
                const double len = std::clamp(20.0 * std::max({o.extent().x, o.extent().y, o.extent().z}),
                                              0.01 * diagonal, 0.2 * diagonal);
                rays.push_back(segment_from(o.center(), o.center() + rng.direction() * len));
            } else {
                rays.push_back(agent_ray(mode, random_object(), random_object, rng, diagonal));
            }
        }
    }
    return rays;
}

void check_dynamics(const DynamicsSettings& d) {
    auto in_range = [](const char* name, double v, double lo, double hi) {
        if (!(v >= lo && v <= hi))  // NaN fails too
            throw InputError(std::string(name) + ": expected a number in " + std::to_string(lo) + ".." +
                             std::to_string(hi) + ", got " + std::to_string(v));
    };
    in_range("change_fraction", d.change_fraction, 0, 1);
    in_range("insert_share", d.insert_share, 0, 1);
    in_range("remove_share", d.remove_share, 0, 1);
    in_range("move_scale", d.move_scale, 0, 1000);
    if (d.insert_share + d.remove_share > 1) throw InputError("insert_share + remove_share exceeds 1");
}

void stream_dynamics(std::vector<Object> initial, const DynamicsSettings& dynamics, const RaySettings& rays,
                     std::uint32_t frames, std::uint64_t seed, nlohmann::json meta, SceneSink& sink) {
    check_dynamics(dynamics);
    check_ray_settings(rays);
    check_streamed_scene_size(double(initial.size()), frames, rays.per_frame,
                              double(initial.size()) * dynamics.change_fraction, "scene");
    meta["frames"] = frames;
    meta["seed"] = seed;
    meta["dynamics"] = {{"change_fraction", dynamics.change_fraction},
                        {"insert_share", dynamics.insert_share},
                        {"remove_share", dynamics.remove_share},
                        {"move_scale", dynamics.move_scale}};
    meta["rays"] = rays_json(rays);
    sink.begin(meta.dump(), initial);
    LiveSet live(initial);
    Uid next_uid = 0;
    for (const Object& o : initial) next_uid = std::max(next_uid, o.uid + 1);
    initial = {};  // the live set holds them now
    for (std::uint32_t f = 1; f <= frames; ++f) {
        Random rng(mix_seed(seed, kDynamicsStream + f));
        Frame frame = frame_changes(live, dynamics, next_uid, rng);
        live.apply(frame);
        frame.rays = generate_rays(live.objects(), rays, seed, f);
        frame.kinds = ray_kinds(frame.rays.size(), rays, seed, f);
        sink.frame(frame);
    }
}

Recording add_dynamics(std::vector<Object> initial, const DynamicsSettings& dynamics, const RaySettings& rays,
                       std::uint32_t frames, std::uint64_t seed, nlohmann::json meta) {
    check_dynamics(dynamics);
    check_ray_settings(rays);
    check_scene_size(double(initial.size()), frames, rays.per_frame, double(initial.size()) * dynamics.change_fraction,
                     "scene");
    RecordingCollector collector;
    stream_dynamics(std::move(initial), dynamics, rays, frames, seed, std::move(meta), collector);
    return std::move(collector.recording);
}

void add_rays(Recording& r, const RaySettings& rays, std::uint64_t seed) {
    LiveSet live(r.initial);
    for (std::uint32_t f = 1; f <= r.frames.size(); ++f) {
        live.apply(r.frames[f - 1]);
        r.frames[f - 1].rays = generate_rays(live.objects(), rays, seed, f);
        r.frames[f - 1].kinds = ray_kinds(r.frames[f - 1].rays.size(), rays, seed, f);
    }
}

nlohmann::json to_json(const SceneSettings& settings) {
    const SceneSettings s = with_generator(settings);
    nlohmann::json j = {{"generator", "rcbench"}, {"kind", s.generator}, {"objects", s.objects}};
    if (!s.preset.empty()) j["preset"] = s.preset;
    if (is_physics_generator(s.generator))
        j["time_step"] = physics_time_step(s);  // only there: other scenes' bytes stay
    if (is_broadmark_generator(s.generator)) {
        j["shape_set"] = s.shape_set.empty() ? "cubes" : s.shape_set;
        j["fill"] = s.fill > 0 ? s.fill : 0.1;
        j["arena"] = broadmark_arena_side(s.objects, s.fill);
    }
    // Only when set, so that a box scene's meta, and so its bytes, stay as they were.
    if (s.shapes.any())
        j["shapes"] = {{"rotated_share", s.shapes.rotated_share},
                       {"sphere_share", s.shapes.sphere_share},
                       {"capsule_share", s.shapes.capsule_share}};
    return j;
}

void stream_scene(const SceneSettings& settings, SceneSink& sink) {
    const SceneSettings s = with_generator(settings);
    if (is_physics_generator(s.generator)) return stream_physics_scene(s, sink);
    check_dynamics(s.dynamics);
    check_shapes(s.shapes);
    check_streamed_scene_size(s.objects, s.frames, s.rays.per_frame, s.objects * s.dynamics.change_fraction, "scene");
    stream_dynamics(generate_objects(s), s.dynamics, s.rays, s.frames, s.seed, to_json(s), sink);
}

Recording generate_scene(const SceneSettings& settings) {
    const SceneSettings s = with_generator(settings);
    if (is_physics_generator(s.generator)) return generate_physics_scene(s);
    check_dynamics(s.dynamics);
    check_shapes(s.shapes);
    check_scene_size(s.objects, s.frames, s.rays.per_frame, s.objects * s.dynamics.change_fraction, "scene");
    return add_dynamics(generate_objects(s), s.dynamics, s.rays, s.frames, s.seed, to_json(s));
}

}  // namespace rcb
