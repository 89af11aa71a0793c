// The Bullet recorder: a Bullet world of boxes and spheres falling on a ground box, recorded through
// rcb::BulletRecorder, replays faithfully. For every recorded closest-hit ray, rcbench's closest hit
// at the shapes level names the body Bullet's own rayTest with ClosestRayResultCallback named, except
// at the ties and grazes within Bullet's ray-cast tolerance that bullet_recorder.h documents (each
// checked to be one). And bad input: one-line errors, and no file written that was not asked for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <btBulletDynamicsCommon.h>

#include "accel/registry.h"
#include "core/base/error.h"
#include "core/base/random.h"
#include "core/scene/bullet/bullet_recorder.h"
#include "core/scene/recording_io.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// Bullet's ray-cast tolerance: btSubsimplexConvexCast::calcTimeOfImpact stops once the squared
/// distance of the ray's point to the shape is below 1e-4, i.e. within 0.01 units of it; twice that
/// here (its distance is the simplex's estimate, in float).
constexpr float kBulletTolerance = 0.02f;

/// A point uniform in the box [lo, hi), its coordinates drawn x, y, z (in that order, whatever the
/// compiler's order of evaluating arguments).
btVector3 uniform(Random& rng, const btVector3& lo, const btVector3& hi) {
    btVector3 p;
    for (int a = 0; a < 3; ++a) p[a] = float(rng.uniform(lo[a], hi[a]));
    return p;
}

/// A Bullet world like Bullet's BasicDemo (examples/BasicDemo/BasicExample.cpp): a static ground
/// box, and a lattice of boxes and spheres above it that fall, tumble and come to rest.
struct World {
    btDefaultCollisionConfiguration config;
    btCollisionDispatcher dispatcher{&config};
    btDbvtBroadphase broadphase;
    btSequentialImpulseConstraintSolver solver;
    btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &config};
    std::vector<std::unique_ptr<btCollisionShape>> shapes;
    std::vector<std::unique_ptr<btDefaultMotionState>> states;
    std::vector<std::unique_ptr<btRigidBody>> bodies;

    World() {
        world.setGravity(btVector3(0, -10, 0));
        add(std::make_unique<btBoxShape>(btVector3(50, 50, 50)), btVector3(0, -50, 0), 0);
        Random rng(7);
        for (int x = 0; x < 5; ++x)
            for (int y = 0; y < 4; ++y)
                for (int z = 0; z < 5; ++z) {
                    const btVector3 jitter = uniform(rng, {-0.3f, 0, -0.3f}, {0.3f, 0, 0.3f});
                    const btVector3 at =
                        btVector3(2.5f * float(x - 2), 2.0f + 2.5f * float(y), 2.5f * float(z - 2)) + jitter;
                    const btVector3 size = uniform(rng, {0.4f, 0.4f, 0.4f}, {1, 1, 1});
                    if ((x + y + z) % 2 == 0)
                        add(std::make_unique<btBoxShape>(size), at, 1);
                    else
                        add(std::make_unique<btSphereShape>(size.x()), at, 1);
                }
    }
    ~World() {
        for (auto& b : bodies) world.removeRigidBody(b.get());
    }
    void add(std::unique_ptr<btCollisionShape> shape, const btVector3& at, float mass) {
        btVector3 inertia(0, 0, 0);
        if (mass > 0) shape->calculateLocalInertia(mass, inertia);
        states.push_back(std::make_unique<btDefaultMotionState>(btTransform(btQuaternion::getIdentity(), at)));
        bodies.push_back(std::make_unique<btRigidBody>(mass, states.back().get(), shape.get(), inertia));
        bodies.back()->setRestitution(0.2f);
        world.addRigidBody(bodies.back().get());
        shapes.push_back(std::move(shape));
    }
};

/// Bullet's answer to one recorded closest-hit ray: the body it names, if any.
using BulletHit = std::optional<Uid>;

/// Per frame: closest rays from above and from the sides through the pile, each starting outside
/// every body; two all-hits rays.
void cast_rays(BulletRecorder& rec, Random& rng, std::vector<BulletHit>& answers) {
    for (int i = 0; i < 8; ++i) {
        const bool side = i % 2 == 1;
        btVector3 from =
            side ? uniform(rng, {-40, 0.05f, -8}, {-40, 4, 8}) : uniform(rng, {-20, 20, -20}, {20, 30, 20});
        const btVector3 to = uniform(rng, {-7, -1, -7}, {7, 5, 7});
        if (side && rng.uniform() < 0.5) from.setX(40);
        btCollisionWorld::ClosestRayResultCallback cb(from, to);
        rec.ray_test(from, to, cb);
        answers.push_back(cb.hasHit() ? rec.uid(cb.m_collisionObject) : std::nullopt);
    }
    for (int i = 0; i < 2; ++i) {
        const btVector3 from = uniform(rng, {-10, 30, -10}, {10, 30, 10}), to(from.x(), -1, from.z());
        btCollisionWorld::AllHitsRayResultCallback all(from, to);
        rec.ray_test(from, to, all);
    }
}

/// The shape grown (or shrunk, for negative `by`) by `by` units: Bullet's tolerance around it.
Shape grown(Shape s, float by) {
    if (s.kind == ShapeKind::obb)
        for (int a = 3; a < 6; ++a) s.v[a] = std::max(0.0f, s.v[a] + by);
    if (s.kind == ShapeKind::sphere) s.v[3] = std::max(0.0f, s.v[3] + by);
    if (s.kind == ShapeKind::capsule) s.v[6] = std::max(0.0f, s.v[6] + by);
    return s;
}
std::optional<float> entry(const Segment& s, const Shape& shape) {
    float t;
    if (!segment_hits_shape(s, shape, &t)) return std::nullopt;
    return t;
}

/// How far the segment passes from the shape: 0 when it meets it, else the least growth (to 1e-4
/// units, by bisection) that makes it meet it, +inf beyond 1 unit.
float miss_distance(const Segment& s, const Shape& shape) {
    if (entry(s, shape)) return 0;
    if (!entry(s, grown(shape, 1))) return std::numeric_limits<float>::infinity();
    float lo = 0, hi = 1;
    while (hi - lo > 1e-4f) (entry(s, grown(shape, 0.5f * (lo + hi))) ? hi : lo) = 0.5f * (lo + hi);
    return hi;
}

/// A Bullet hit farther than Bullet's tolerance from the exact shape: its cast ended before it
/// converged and reported the point it had reached (btSubsimplexConvexCast::calcTimeOfImpact's loop
/// also ends after MAX_ITERATIONS, 32, or when its simplex solver finds no closer point, which sets
/// the distance to 0, and neither exit checks the distance). With Debian's Bullet 3.24, of 12 000
/// random rays passing 0.02 to 0.1 units from a box 0.4% were reported as hits, none passing
/// farther; 0.1 units is a tenth of this scene's smallest body, and a wrongly recorded shape would
/// put Bullet's hits farther away.
constexpr float kUnconverged = 0.1f;

struct Agreement {
    std::size_t rays = 0, same = 0, ties = 0, grazes = 0, unconverged = 0, starts_inside = 0, differ = 0;
    std::string first_difference;
};

/// Whether Bullet's `b` and rcbench's `r` (different) differ only as bullet_recorder.h documents;
/// "" and the category counted, or what differs.
std::string classify(const Segment& s, const LiveSet& live, std::optional<Uid> b, std::optional<Uid> r, Agreement& a) {
    const float tol_t = kBulletTolerance / std::sqrt(dot(s.delta(), s.delta()));
    if (r && segment_hits_shape({s.p0, s.p0}, live.object(*r).shape)) return ++a.starts_inside, "";
    const std::optional<float> t_r = r ? entry(s, live.object(*r).shape) : std::nullopt;
    if (b) {
        const Shape& shape = live.object(*b).shape;
        const float miss = miss_distance(s, shape);
        if (miss > kBulletTolerance && miss <= kUnconverged) return ++a.unconverged, "";
        const std::optional<float> t_b = entry(s, grown(shape, kBulletTolerance));
        if (miss > 0 && t_b && (!t_r || *t_b <= *t_r + tol_t)) return ++a.grazes, "";
        if (miss == 0 && t_r && *t_b <= *t_r + tol_t) return ++a.ties, "";
    } else if (r && !entry(s, grown(live.object(*r).shape, -kBulletTolerance))) {
        return ++a.grazes, "";
    }
    ++a.differ;
    return "Bullet names " + (b ? "uid " + std::to_string(*b) : std::string("nothing")) + ", rcbench " +
           (r ? "uid " + std::to_string(*r) + " at t " + std::to_string(*t_r) : std::string("nothing"));
}

/// Replays `path` with brute force at the shapes level and compares every closest-hit ray's
/// answer with Bullet's, in recording order.
Agreement replay(const std::string& path, const std::vector<BulletHit>& bullet) {
    const Recording rec = read_recording(path);
    std::unique_ptr<Structure> s = find_structure("bf").make({{"query", "shapes"}}, "test");
    s->build(rec.initial);
    LiveSet live(rec.initial);
    Agreement a;
    std::size_t next = 0;
    HitLists out;
    for (const Frame& f : rec.frames) {
        for (Uid uid : f.removes) s->remove(uid);
        for (const Object& o : f.inserts) s->insert(o);
        for (const Object& o : f.moves) s->move(o);
        s->commit();
        live.apply(f);
        s->cast(f.rays, f.kinds, out);
        for (std::size_t i = 0; i < f.rays.size(); ++i) {
            if (f.kind(i) != QueryKind::closest) continue;
            const std::optional<Uid> r = out.of(i).empty() ? std::nullopt : std::optional<Uid>(out.of(i)[0]);
            const std::optional<Uid> b = bullet.at(next++);
            ++a.rays;
            if (r == b) {
                ++a.same;
                continue;
            }
            const std::string why = classify(f.rays[i], live, b, r, a);
            if (!why.empty() && a.first_difference.empty())
                a.first_difference =
                    "frame " + std::to_string(&f - rec.frames.data() + 1) + " ray " + std::to_string(i) + ": " + why;
        }
    }
    EXPECT_EQ(next, bullet.size()) << "every closest-hit ray Bullet answered is in the recording";
    return a;
}

class BulletRecorderTest : public ::testing::Test {
protected:
    std::string path(const std::string& name = "world.rcbscene") const { return dir_.file(name); }
    test::TempDir dir_{"bullet_recorder"};
};

TEST_F(BulletRecorderTest, ClosestHitsMatchBulletsRayTestAtTheShapesLevel) {
    World w;
    std::vector<BulletHit> bullet;
    Random rng(11);
    {
        BulletRecorder rec(w.world, path(), R"({"scene": "boxes and spheres on a ground box"})");
        EXPECT_EQ(rec.live_count(), w.bodies.size());
        for (int step = 0; step < 300; ++step) {
            w.world.stepSimulation(1.0f / 60, 0);
            rec.step();
            cast_rays(rec, rng, bullet);
        }
        rec.close();
    }
    const Recording r = read_recording(path());
    ASSERT_EQ(r.frames.size(), 300u);
    EXPECT_EQ(r.initial.size(), w.bodies.size());
    EXPECT_NE(r.meta.find("rcb::BulletRecorder"), std::string::npos);
    std::size_t moves = 0;
    for (const Frame& f : r.frames) {
        moves += f.moves.size();
        ASSERT_EQ(f.rays.size(), 10u);
        EXPECT_EQ(f.kind(0), QueryKind::closest);
        EXPECT_EQ(f.kind(9), QueryKind::all);  // AllHitsRayResultCallback
    }
    EXPECT_GT(moves, 100u * 50) << "the bodies fall: most move in most frames";

    const Agreement a = replay(path(), bullet);
    std::printf(
        "closest-hit rays %zu: same body %zu, ties %zu, grazes %zu, unconverged %zu, starting inside %zu, "
        "differ %zu\n",
        a.rays, a.same, a.ties, a.grazes, a.unconverged, a.starts_inside, a.differ);
    EXPECT_EQ(a.rays, 300u * 8);
    EXPECT_EQ(a.differ, 0u) << a.first_difference;
    EXPECT_EQ(a.starts_inside, 0u) << "the rays start outside every body";
    EXPECT_GT(a.same, a.rays * 9 / 10);
}

TEST_F(BulletRecorderTest, UidsStayWithTheirObjectsThroughRemovesAndInserts) {
    World w;
    BulletRecorder rec(w.world, path());
    const Uid first = *rec.uid(w.bodies[1].get()), last = *rec.uid(w.bodies.back().get());
    w.world.removeRigidBody(w.bodies[1].get());
    w.world.stepSimulation(1.0f / 60, 0);
    rec.step();
    EXPECT_FALSE(rec.uid(w.bodies[1].get()));
    EXPECT_EQ(*rec.uid(w.bodies.back().get()), last);
    w.world.addRigidBody(w.bodies[1].get());
    rec.step();
    EXPECT_NE(*rec.uid(w.bodies[1].get()), first) << "back in the world: a new object, a new uid";
    rec.close();
    const Recording r = read_recording(path());
    ASSERT_EQ(r.frames.size(), 2u);
    EXPECT_EQ(r.frames[0].removes, std::vector<Uid>{first});
    ASSERT_EQ(r.frames[1].inserts.size(), 1u);
    EXPECT_EQ(r.frames[1].inserts[0].shape.kind, ShapeKind::obb);
}

TEST_F(BulletRecorderTest, AnUnwritablePathIsAOneLineErrorBeforeAnythingIsWritten) {
    World w;
    const std::string missing = path("no/such/folder/world.rcbscene");
    test::expect_input_error([&] { BulletRecorder rec(w.world, missing); }, "does not exist");
    try {
        BulletRecorder rec(w.world, missing);
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
    test::expect_input_error([&] { BulletRecorder rec(w.world, dir_.path().string()); }, "is a directory");
    test::expect_input_error([&] { BulletRecorder rec(w.world, path(), "[1, 2]"); }, "meta must be a JSON object");
    EXPECT_TRUE(fs::is_empty(dir_.path())) << "nothing written";
}

TEST_F(BulletRecorderTest, AnUnrecordableObjectOrRayIsRefusedAndTheExistingFileKept) {
    {
        std::FILE* f = std::fopen(path().c_str(), "wb");
        std::fputs("the game's own file", f);
        std::fclose(f);
    }
    World w;
    btStaticPlaneShape plane(btVector3(0, 1, 0), 0);
    btRigidBody ground(0, nullptr, &plane);
    w.world.addRigidBody(&ground);
    test::expect_input_error([&] { BulletRecorder rec(w.world, path()); },
                             "(STATICPLANE): world AABB: coordinate -1e+18 beyond");
    w.world.removeRigidBody(&ground);

    BulletRecorder rec(w.world, path("other.rcbscene"));
    const float nan = std::nanf("");
    btCollisionWorld::ClosestRayResultCallback cb(btVector3(0, 0, 0), btVector3(nan, 0, 0));
    test::expect_input_error([&] { rec.ray_test(btVector3(0, 0, 0), btVector3(nan, 0, 0), cb); },
                             "frame 1: ray 0: non-finite coordinate");
    std::ifstream in(path());
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "the game's own file")
        << "a file the recorder was not asked to write";
}

}  // namespace
}  // namespace rcb
