// The scenes of the conformance suite (testing/conformance.h): hand-made hard cases and small
// generated presets, every ray cast as each query kind, and the seeded fuzz scene.
#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "testing/conformance.h"

namespace rcb::test {
namespace {

Aabb box(float x0, float y0, float z0, float x1, float y1, float z1) { return {{x0, y0, z0}, {x1, y1, z1}}; }

/// Rays that probe the places structures get wrong: along axes through box faces, edges and
/// corners; starting inside, on and outside the bounds; ending mid-scene; of zero length.
std::vector<Segment> probe_rays(const std::vector<Object>& live, std::uint64_t seed, std::size_t count) {
    std::vector<Segment> rays;
    if (live.empty()) {
        rays.push_back({{-1, -1, -1}, {1, 1, 1}});
        return rays;
    }
    Random rng(seed);
    const Aabb b = bounds_of(live);
    const Vec3 lo = b.min, hi = b.max, c = b.center();
    const Vec3 pad = (hi - lo) * 0.25f + Vec3{1, 1, 1};
    auto pick = [&]() -> const Aabb& { return live[rng.below(live.size())].box; };
    auto point_in = [&](const Aabb& a) {
        return Vec3{float(rng.uniform(a.min.x, a.max.x)), float(rng.uniform(a.min.y, a.max.y)),
                    float(rng.uniform(a.min.z, a.max.z))};
    };
    const Aabb around{lo - pad, hi + pad};
    for (std::size_t i = 0; i < count; ++i) {
        switch (i % 8) {
            case 0:  // anywhere to anywhere, may start and end outside
                rays.push_back({point_in(around), point_in(around)});
                break;
            case 1: {  // axis-parallel through a box's face plane and edge lines
                const Aabb& o = pick();
                const int axis = int(rng.below(3));
                Vec3 p = rng.below(2) ? o.min : o.max;
                Vec3 q = p;
                p[axis] = around.min[axis];
                q[axis] = around.max[axis];
                rays.push_back({p, q});
                break;
            }
            case 2: {  // axis-parallel through a face's interior, starting inside the object
                const Aabb& o = pick();
                const int axis = int(rng.below(3));
                Vec3 p = point_in(o);
                p[(axis + 1) % 3] = o.min[(axis + 1) % 3];
                Vec3 q = p;
                q[axis] = rng.below(2) ? around.min[axis] : around.max[axis];
                rays.push_back({p, q});
                break;
            }
            case 3: {  // zero-length at a box corner or inside
                const Aabb& o = pick();
                const Vec3 p = rng.below(2) ? o.max : point_in(o);
                rays.push_back({p, p});
                break;
            }
            case 4: {  // from exactly a face of the bounds inwards, ending mid-scene
                const int axis = int(rng.below(3));
                Vec3 p = point_in(b);
                p[axis] = rng.below(2) ? lo[axis] : hi[axis];
                rays.push_back({p, point_in(b)});
                break;
            }
            case 5: {  // ending exactly on a box's face
                const Aabb& o = pick();
                Vec3 q = point_in(o);
                q.x = o.min.x;
                rays.push_back({point_in(around), q});
                break;
            }
            case 6:  // from the centre outwards (the thesis' rays)
                rays.push_back({c, c + (point_in(around) - c) * 4.0f});
                break;
            default: {  // diagonal through a box corner
                const Aabb& o = pick();
                const Vec3 d{1, 1, 1};
                rays.push_back({o.min - d * (hi.x - lo.x + 1), o.min + d * (hi.x - lo.x + 1)});
                break;
            }
        }
    }
    return rays;
}

/// A recording from explicit objects and per-frame changes, with probe rays in every frame.
Recording with_rays(std::vector<Object> initial, std::vector<Frame> frames, std::uint64_t seed, std::size_t rays = 64) {
    Recording r;
    r.meta = R"({"generator":"tests"})";
    r.initial = std::move(initial);
    r.frames = std::move(frames);
    LiveSet live(r.initial);
    for (std::size_t f = 0; f < r.frames.size(); ++f) {
        live.apply(r.frames[f]);
        r.frames[f].rays = probe_rays(live.objects(), seed * 1000 + f, rays);
    }
    refuse_invalid_recording(r, "test scene");
    return r;
}

/// Frames of random moves (and a few inserts/removes) for a hand-made object set.
std::vector<Frame> jiggle(const std::vector<Object>& initial, std::size_t frames, std::uint64_t seed) {
    std::vector<Frame> out;
    LiveSet live(initial);
    Random rng(seed);
    Uid next = 1'000'000;
    for (std::size_t f = 0; f < frames; ++f) {
        Frame fr;
        if (live.size() > 2) {
            fr.removes.push_back(live.objects()[rng.below(live.size())].uid);
            const Object& moved = live.objects()[rng.below(live.size())];
            if (moved.uid != fr.removes[0]) {
                const float s = std::max(0.5f, moved.box.longest_edge());
                const Vec3 d{float(rng.uniform(-s, s)), float(rng.uniform(-s, s)), float(rng.uniform(-s, s))};
                fr.moves.push_back({moved.uid, {moved.box.min + d, moved.box.max + d}});
            }
        }
        if (!live.objects().empty()) {
            const Aabb copy = live.objects()[rng.below(live.size())].box;
            fr.inserts.push_back({next++, copy});
        }
        live.apply(fr);
        out.push_back(std::move(fr));
    }
    return out;
}

}  // namespace

Recording generated_scene(const std::string& generator, std::uint32_t objects, std::uint32_t frames, std::uint64_t seed,
                          double change_fraction) {
    SceneSettings s;
    s.generator = generator;
    s.objects = objects;
    s.frames = frames;
    s.seed = seed;
    s.dynamics.change_fraction = change_fraction;
    s.rays.per_frame = 100;
    s.rays.mix = parse_ray_mix("center:2,dense:1,los:1,ground:1,shots:1");
    return generate_scene(s);
}

std::vector<NamedScene> hard_scenes() {
    std::vector<NamedScene> scenes;
    Random rng(7);

    // Empty, then objects arrive, then leave.
    {
        std::vector<Frame> frames(3);
        frames[0].inserts = {{1, box(0, 0, 0, 1, 1, 1)}, {2, box(2, 2, 2, 3, 3, 3)}};
        frames[1].moves = {{1, box(5, 0, 0, 6, 1, 1)}};
        frames[2].removes = {1, 2};
        scenes.push_back({"empty-then-some", with_rays({}, frames, 1)});
    }
    // One object.
    scenes.push_back(
        {"single", with_rays({{7, box(-1, -1, -1, 1, 1, 1)}}, jiggle({{7, box(-1, -1, -1, 1, 1, 1)}}, 3, 2), 2)});
    // Identical boxes.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 300; ++i) objs.push_back({i, box(1, 2, 3, 2, 3, 4)});
        scenes.push_back({"identical", with_rays(objs, jiggle(objs, 4, 3), 3)});
    }
    // Identical centroids, sizes from 0.01 to 100.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 300; ++i) {
            const float h = float(0.005 * std::pow(10000.0, i / 299.0));
            objs.push_back({i, box(5 - h, 5 - h, 5 - h, 5 + h, 5 + h, 5 + h)});
        }
        scenes.push_back({"same-centroid", with_rays(objs, jiggle(objs, 4, 4), 4)});
    }
    // A crowd: 400 cubes nested around one centre (sizes over four orders of magnitude), rays
    // starting at the centre (inside every box) and in between; boxes grow past the grids' large-
    // object limit and shrink back; a crowd loses its common point and regains it.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 400; ++i) {
            const float h = float(0.005 * std::pow(10000.0, double((i * 37) % 400) / 399.0));
            objs.push_back({i, box(-h, -h, -h, h, h, h)});
        }
        std::vector<Frame> frames(4);
        // uid 5 grows from small to huge, then shrinks back; uid 7 leaves the common point, then returns.
        frames[0].moves = {{5, box(-60, -60, -60, 60, 60, 60)}, {9, box(-0.2f, -0.1f, -0.1f, 0.0f, 0.1f, 0.1f)}};
        frames[0].inserts = {{1000, box(-3, -3, -3, 3, 3, 3)}, {1001, box(-3, -3, -3, 3, 3, 3)}};
        frames[1].moves = {{5, box(-0.01f, -0.01f, -0.01f, 0.01f, 0.01f, 0.01f)}, {7, box(30, 30, 30, 31, 31, 31)}};
        frames[1].removes = {1000, 11};
        frames[2].moves = {{7, box(-1, -1, -1, 1, 1, 1)}};
        frames[2].inserts = {{1002, box(-100, -100, -100, 100, 100, 100)}};
        frames[3].removes = {1002, 1001};
        frames[3].moves = {{9, box(-0.1f, -0.1f, -0.1f, 0.1f, 0.1f, 0.1f)}};
        Recording r = with_rays(objs, frames, 14);
        Random dirs(15);
        for (Frame& f : r.frames)
            for (int k = 0; k < 24; ++k) {
                const Vec3 d =
                    Vec3{float(dirs.uniform(-1, 1)), float(dirs.uniform(-1, 1)), float(dirs.uniform(-1, 1))} * 80.0f;
                const Vec3 from =
                    k % 3 == 0 ? Vec3{0, 0, 0} : Vec3{float(dirs.uniform(-2, 2)), float(dirs.uniform(-2, 2)), 0};
                f.rays.push_back({from, from + d});
            }
        scenes.push_back({"nested-crowd", std::move(r)});
    }
    // Flat: every box in the plane y = 0, zero thickness.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 400; ++i) {
            const float x = float(rng.uniform(0, 100)), z = float(rng.uniform(0, 100));
            objs.push_back({i, box(x, 0, z, x + float(rng.uniform(0.1, 3)), 0, z + float(rng.uniform(0.1, 3)))});
        }
        scenes.push_back({"flat", with_rays(objs, jiggle(objs, 4, 5), 5, 96)});
    }
    // Zero-volume: points and lines.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 300; ++i) {
            const Vec3 p{float(rng.uniform(0, 20)), float(rng.uniform(0, 20)), float(rng.uniform(0, 20))};
            Vec3 q = p;
            if (i % 2) q[int(i % 3)] += float(rng.uniform(0, 5));
            objs.push_back({i, {p, q}});
        }
        scenes.push_back({"zero-volume", with_rays(objs, jiggle(objs, 4, 6), 6, 96)});
    }
    // Teapot in a stadium: a huge box around a tiny dense cluster.
    {
        std::vector<Object> objs{{0, box(-1000, -1000, -1000, 1000, 1000, 1000)}};
        for (Uid i = 1; i < 500; ++i) {
            const Vec3 p{float(rng.normal() * 0.5), float(rng.normal() * 0.5), float(rng.normal() * 0.5)};
            objs.push_back({i, {p, p + Vec3{0.01f, 0.01f, 0.01f}}});
        }
        scenes.push_back({"stadium", with_rays(objs, jiggle(objs, 4, 7), 7)});
    }
    // Unit boxes on an integer lattice, touching each other: rays along shared faces and edges.
    {
        std::vector<Object> objs;
        Uid uid = 0;
        for (int x = 0; x < 8; ++x)
            for (int y = 0; y < 8; ++y)
                for (int z = 0; z < 8; ++z)
                    objs.push_back({uid++, box(float(x), float(y), float(z), x + 1.f, y + 1.f, z + 1.f)});
        Recording r = with_rays(objs, jiggle(objs, 3, 8), 8);
        for (Frame& f : r.frames)
            for (int k = 0; k <= 8; ++k) {
                f.rays.push_back({{float(k), -1, float(k)}, {float(k), 9, float(k)}});  // along an edge line
                f.rays.push_back({{-1, float(k), 0.5f}, {9, float(k), 0.5f}});          // along a face plane
                f.rays.push_back({{float(k), float(k), float(k)}, {8, 8, 8}});          // diagonal through corners
            }
        scenes.push_back({"lattice-faces", std::move(r)});
    }
    // Inserts and moves far outside the initial bounds.
    {
        std::vector<Object> objs;
        for (Uid i = 0; i < 200; ++i) {
            const Vec3 p{float(rng.uniform(0, 10)), float(rng.uniform(0, 10)), float(rng.uniform(0, 10))};
            objs.push_back({i, {p, p + Vec3{0.5f, 0.5f, 0.5f}}});
        }
        std::vector<Frame> frames(4);
        frames[0].inserts = {{500, box(1000, 1000, 1000, 1001, 1001, 1001)}, {501, box(-2000, 5, 5, -1990, 6, 6)}};
        frames[1].moves = {{3, box(5, 5000, 5, 6, 5001, 6)}, {500, box(-50, -50, -50, 50, 50, 50)}};
        frames[2].inserts = {{502, box(-1e5f, -1e5f, -1e5f, 1e5f, 1e5f, 1e5f)}};
        frames[3].removes = {502, 501};
        scenes.push_back({"outside-bounds", with_rays(objs, frames, 9)});
    }
    scenes.push_back({"uniform-small", generated_scene("uniform", 600, 4, 11)});
    scenes.push_back({"irregular-small", generated_scene("irregular", 1500, 4, 12)});
    scenes.push_back({"irregular-churn", generated_scene("irregular", 400, 40, 13, 0.3)});
    // The peer-comparison generators: boxes filling their cells to the faces; huge slabs over clusters.
    scenes.push_back({"jittered-small", generated_scene("jittered", 700, 4, 14)});
    scenes.push_back({"clusters-small", generated_scene("clusters", 2000, 4, 15)});
    return scenes;
}

Recording with_every_query_kind(Recording r) {
    for (Frame& f : r.frames) {
        const std::vector<Segment> rays = std::move(f.rays);
        f.rays.clear();
        f.kinds.clear();
        for (const Segment& ray : rays)
            for (int k = 0; k < kQueryKinds; ++k) {
                f.rays.push_back(ray);
                f.kinds.push_back(QueryKind(k));
            }
    }
    return r;
}

namespace {

/// A coordinate on the 0.25 lattice in [-32, 32), one time in 24 a million times as far, one time
/// in 24 just off the lattice (tests/fuzz/fuzz_differential.cpp: coordinate).
float fuzz_coordinate(Random& rng) {
    const std::uint64_t kind = rng.below(24);
    const float v = float(std::int64_t(rng.below(256)) - 128) * 0.25f;
    if (kind == 0) return v * 1e6f;
    if (kind == 1) return v + float(rng.below(65536)) * 1e-5f;
    return v;
}

Vec3 fuzz_point(Random& rng) { return {fuzz_coordinate(rng), fuzz_coordinate(rng), fuzz_coordinate(rng)}; }

/// Flat on an axis one time in four, huge one time in 40, else up to 24 units per axis.
Aabb fuzz_box(Random& rng) {
    const Vec3 p = fuzz_point(rng);
    Vec3 e;
    for (int a = 0; a < 3; ++a) {
        const std::uint64_t b = rng.below(256);
        e[a] = b < 64 ? 0.0f : (b < 250 ? float(b - 63) * 0.125f : 1e5f);
    }
    return {p, p + e};
}

/// Zero-length one time in eight, axis-parallel (along a lattice line or face) three times in eight.
Segment fuzz_ray(Random& rng) {
    const Vec3 p = fuzz_point(rng);
    const std::uint64_t shape = rng.below(8);
    if (shape == 0) return {p, p};
    Vec3 q = fuzz_point(rng);
    if (shape < 4)
        for (int a = 0; a < 3; ++a)
            if (a != int(shape - 1)) q[a] = p[a];
    return {p, q};
}

/// One frame of up to 8 changes (each uid at most once) and 1 to 16 rays of random kinds.
Frame fuzz_frame(Random& rng, const LiveSet& live, Uid& next) {
    Frame frame;
    std::set<Uid> touched;
    const std::uint64_t changes = rng.below(9);
    for (std::uint64_t c = 0; c < changes; ++c) {
        const std::uint64_t what = rng.below(3);
        if (what == 0 || live.size() == 0) {
            if (live.size() + frame.inserts.size() < 48) frame.inserts.push_back({next++, fuzz_box(rng)});
            continue;
        }
        const Uid uid = live.objects()[rng.below(live.size())].uid;
        if (!touched.insert(uid).second) continue;
        if (what == 1)
            frame.removes.push_back(uid);
        else
            frame.moves.push_back({uid, fuzz_box(rng)});
    }
    const std::uint64_t rays = 1 + rng.below(16);
    for (std::uint64_t k = 0; k < rays; ++k) {
        frame.rays.push_back(fuzz_ray(rng));
        frame.kinds.push_back(QueryKind(rng.below(kQueryKinds)));
    }
    return frame;
}

}  // namespace

Recording fuzz_scene(std::uint64_t seed, std::uint32_t frames) {
    Random rng(seed);
    Recording r;
    r.meta = nlohmann::json{{"generator", "conformance fuzz"}, {"seed", seed}}.dump();
    Uid next = 1;
    const std::uint64_t objects = rng.below(49);
    for (std::uint64_t i = 0; i < objects; ++i) r.initial.push_back({next++, fuzz_box(rng)});
    LiveSet live(r.initial);
    for (std::uint32_t f = 0; f < frames; ++f) {
        Frame frame = fuzz_frame(rng, live, next);
        live.apply(frame);
        r.frames.push_back(std::move(frame));
    }
    refuse_invalid_recording(r, "conformance fuzz scene");
    return r;
}

}  // namespace rcb::test
