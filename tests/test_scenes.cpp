#include "tests/test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "core/base/random.h"
#include "accel/registry.h"

namespace rcb::test {
SimulationResult expect_matches_ground_truth(const Recording& r, const std::string& structure,
                                             const nlohmann::json& params, const std::string& scene_name) {
    SimulationOptions o;
    o.verify = true;
    o.count = true;
    o.check = true;
    SimulationResult res = simulate(r, find_structure(structure), params, o);
    EXPECT_EQ(res.mismatches(), 0u) << structure << ' ' << params.dump() << " on scene " << scene_name
                                    << describe_mismatches(res, r, scene_name);
    return res;
}

bool reference_hit(const Segmentd& s, const Aabbd& b) {
    double lo = 0, hi = 1;
    for (int a = 0; a < 3; ++a) {
        const double p = s.p0[a], d = s.p1[a] - s.p0[a];
        if (d == 0) {
            if (p < b.min[a] || p > b.max[a]) return false;
            continue;
        }
        double t0 = (b.min[a] - p) / d, t1 = (b.max[a] - p) / d;
        if (t0 > t1) std::swap(t0, t1);
        lo = std::max(lo, t0), hi = std::min(hi, t1);
    }
    return lo <= hi;
}

Recording with_shapes(const Recording& r, std::uint64_t seed) {
    auto shaped = [seed](Object o) {
        std::mt19937_64 rng(seed * 0x9e3779b97f4a7c15ull + o.uid);
        const int kind = int(rng() % 5);
        const Vec3 lo = o.box.min, hi = o.box.max, c = o.box.center(), h = o.box.extent() * 0.5f;
        std::normal_distribution<float> n(0.0f, 1.0f);
        switch (kind) {
            case 1:
                return shaped_object(o.uid, Shape::triangle(lo, {hi.x, lo.y, hi.z}, {lo.x, hi.y, c.z}));
            case 2:
                return shaped_object(o.uid, Shape::obb(c, h * 0.6f, {n(rng), n(rng), n(rng), n(rng)}));
            case 3:
                return shaped_object(o.uid, Shape::sphere(c, std::min({h.x, h.y, h.z})));
            case 4: {
                const int axis = h.x >= h.y && h.x >= h.z ? 0 : (h.y >= h.z ? 1 : 2);
                const float r = std::min({h.x, h.y, h.z, 0.5f * h[axis]});
                Vec3 a = c, b = c;
                a[axis] = lo[axis] + r, b[axis] = hi[axis] - r;
                return shaped_object(o.uid, Shape::capsule(a, b, r));
            }
            default:
                return o;
        }
    };
    Recording out = r;
    for (Object& o : out.initial) o = shaped(o);
    for (Frame& f : out.frames) {
        for (Object& o : f.inserts) o = shaped(o);
        for (Object& o : f.moves) o = shaped(o);
    }
    return out;
}

std::vector<Uid> sorted_hits(Structure& s, const Segment& ray) {
    HitLists out;
    s.cast(std::span<const Segment>(&ray, 1), out);
    std::vector<Uid> v(out.uids.begin(), out.uids.end());
    std::sort(v.begin(), v.end());
    return v;
}

std::vector<Segment> rays_from_centre(const std::vector<Object>& objects, int n, std::uint64_t seed) {
    const Aabb world = bounds_of(objects);
    const Vec3 c = world.center();
    Random rng(seed);
    std::vector<Segment> rays;
    for (int i = 0; i < n; ++i) {
        const Vec3 d = Vec3{float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))};
        rays.push_back({c, c + d * world.extent().x});
    }
    return rays;
}

Aabb random_box(Random& rng, float world) {
    const Vec3 c{float(rng.uniform(0, world)), float(rng.uniform(0, world)), float(rng.uniform(0, world))};
    const Vec3 h{float(rng.log_uniform(0.01, 2)), float(rng.log_uniform(0.01, 2)), float(rng.log_uniform(0.01, 2))};
    return {c - h, c + h};
}

void random_change(Random& rng, std::vector<Object>& live, Uid& next, float world, bool jump,
                   std::initializer_list<Structure*> targets) {
    const int kind = int(rng.below(3));
    if (kind == 0 && live.size() > 1) {
        const std::size_t i = rng.below(live.size());
        for (Structure* s : targets) s->remove(live[i].uid);
        live[i] = live.back(), live.pop_back();
    } else if (kind == 1 || live.empty()) {
        const Object o{next++, random_box(rng, world)};
        for (Structure* s : targets) s->insert(o);
        live.push_back(o);
    } else {
        Object& o = live[rng.below(live.size())];
        if (jump) {
            o.box = random_box(rng, world);
        } else {
            const float reach = o.box.longest_edge();
            const Vec3 d{float(rng.uniform(-reach, reach)), float(rng.uniform(-reach, reach)),
                         float(rng.uniform(-reach, reach))};
            o.box = {o.box.min + d, o.box.max + d};
        }
        for (Structure* s : targets) s->move(o);
    }
}

SceneSpec generated_spec(const std::string& name, const std::string& generator, std::uint32_t objects,
                         std::uint32_t frames, std::uint32_t rays, const nlohmann::json& key) {
    SceneSpec s;
    s.name = name;
    s.source = SceneSpec::Source::generated;
    s.settings.generator = generator;
    s.settings.objects = objects;
    s.settings.frames = frames;
    s.settings.rays.per_frame = rays;
    s.key = key;
    return s;
}

Segment random_segment(Random& rng, float world) {
    auto coordinate = [&] { return float(rng.uniform(-5, world + 5)); };
    const Vec3 p0{coordinate(), coordinate(), coordinate()};
    const Vec3 p1{coordinate(), coordinate(), coordinate()};
    return {p0, p1};
}

}  // namespace rcb::test
