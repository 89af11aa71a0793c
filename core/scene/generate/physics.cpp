#include "core/scene/generate/physics.h"

#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <numeric>
#include <set>

#include "core/base/error.h"
#include "core/base/number_text.h"
#include "core/base/random.h"

namespace rcb {
namespace {

// Streams for mix_seed, apart from generators.cpp's (objects 1, dynamics 1e6, rays 2e6 + frame,
// shapes 4e6): body layout, and brownian's kicks per frame.
constexpr std::uint64_t kBodyStream = 5'000'000;
constexpr std::uint64_t kKickStream = 6'000'000;  // + frame

btVector3 bt(const Vec3d& v) { return {btScalar(v.x), btScalar(v.y), btScalar(v.z)}; }
Vec3d vec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

enum class BodyShape { box, rotated, sphere, capsule };

/// One body as a kind lays it out: its shape inside a box of half extents `half`, its start.
struct BodySpec {
    BodyShape shape = BodyShape::box;
    Vec3d half{0.5, 0.5, 0.5};
    Vec3d position;
    std::array<float, 4> rotation{1, 0, 0, 0};  // w, x, y, z
    Vec3d velocity;
};

struct StaticBox {
    Vec3d centre, half;
};

/// What a kind sets up: the bodies (uid = index), static colliders and ground, gravity, and whether bodies
/// may fall asleep (Bullet's default thresholds) or stay awake.
struct Setup {
    std::vector<BodySpec> bodies;
    std::vector<StaticBox> statics;
    Vec3d gravity{0, -9.81, 0};
    bool sleep = true;
    bool ground = false;  ///< the plane y = ground_height (a plane: a huge box makes resting contacts jitter)
    double ground_height = 0;
};

/// Exactly round(share × n) bodies of each shape, chosen at random (apply_shapes' rule).
std::vector<BodyShape> shape_mix(std::size_t n, const ShapeSettings& s, Random& rng) {
    std::vector<BodyShape> shapes(n, BodyShape::box);
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::size_t next = 0;
    const std::pair<double, BodyShape> shares[3] = {{s.rotated_share, BodyShape::rotated},
                                                    {s.sphere_share, BodyShape::sphere},
                                                    {s.capsule_share, BodyShape::capsule}};
    for (const auto& [share, shape] : shares) {
        const std::size_t count = std::min(n - next, static_cast<std::size_t>(std::llround(share * double(n))));
        for (std::size_t i = 0; i < count; ++i, ++next) {
            std::swap(order[next], order[next + rng.below(n - next)]);
            shapes[order[next]] = shape;
        }
    }
    return shapes;
}

/// Half extents 0.2 to 0.5 m per axis: a body, even rotated, fits in a ball of radius 0.87 m, so
/// bodies on a lattice of 2 m cells (1.75 m for the explosion) never start overlapping.
Vec3d random_half(Random& rng) { return {rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5)}; }

/// n bodies on a lattice of `cell`-metre cells, `side` cells along x and z, layer by layer upward
/// from `origin` (the first cell's centre), each moved by up to `jitter` metres along x and z.
std::vector<BodySpec> lattice(std::size_t n, std::size_t side, double cell, const Vec3d& origin, double jitter,
                              const std::vector<BodyShape>& shapes, Random& rng) {
    std::vector<BodySpec> bodies(n);
    for (std::size_t i = 0; i < n; ++i) {
        BodySpec& b = bodies[i];
        b.shape = shapes[i];
        b.half = random_half(rng);
        const double x = double(i % side), z = double((i / side) % side), y = double(i / (side * side));
        b.position =
            origin + Vec3d{x * cell + jitter * rng.uniform(-1, 1), y * cell, z * cell + jitter * rng.uniform(-1, 1)};
        if (b.shape == BodyShape::rotated) b.rotation = random_rotation(rng);
    }
    return bodies;
}

/// A closed cube of inner side `side` from the origin: six walls 1 m thick.
std::vector<StaticBox> closed_box(double side) {
    const double h = side / 2;
    std::vector<StaticBox> walls;
    for (int a = 0; a < 3; ++a)
        for (double s : {-1.0, 1.0}) {
            Vec3d c{h, h, h}, half{h + 1, h + 1, h + 1};
            c[a] = h + s * (h + 0.5);
            half[a] = 0.5;
            walls.push_back({c, half});
        }
    return walls;
}

std::size_t cube_side(std::size_t n) { return std::max<std::size_t>(1, std::size_t(std::ceil(std::cbrt(double(n))))); }

Setup pile_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng) {
    Setup s;
    // A block about twice as tall as wide, bodies 0.3 m apart at most sideways so they tumble.
    const std::size_t side = std::max<std::size_t>(1, std::size_t(std::ceil(std::cbrt(double(n) / 2))));
    s.bodies = lattice(n, side, 2.0, {1, 1.5, 1}, 0.3, shapes, rng);
    for (BodySpec& b : s.bodies) b.velocity = {rng.uniform(-0.5, 0.5), 0, rng.uniform(-0.5, 0.5)};
    s.ground = true;
    return s;
}

/// Reports whether any leaf of a btDbvt was reached (Bullet's AABB tree over a map's boxes).
struct AnyLeaf : btDbvt::ICollide {
    bool hit = false;
    void Process(const btDbvtNode*) override { hit = true; }
};

/// The pile on a map (physics.h): bodies in distinct free 2 m cells drawn at random over the map's
/// bounds. A cell is free when the cube of ±0.9 m around its centre (a body's ball of 0.87 m, see
/// random_half) overlaps no map box, and has a floor when a vertical ray from its centre down to
/// the map's lowest point crosses a map box. At most 64 draws per body, so a map without room ends.
Setup map_pile_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng, std::span<const Aabb> map) {
    Aabbd bounds = Aabbd::empty();
    for (const Aabb& b : map) bounds = merge(bounds, b.as<double>());
    constexpr double kCell = 2.0, kMaxAcross = 1e6;
    const Vec3d ext = bounds.extent();
    if (!(ext.x <= kMaxAcross && ext.y <= kMaxAcross && ext.z <= kMaxAcross))
        throw InputError("the map is " + fixed(bounds.longest_edge(), 0) +
                         " m across; a pile is dropped onto a map at most 10^6 m across");
    btDbvt tree;
    for (const Aabb& b : map)
        tree.insert(btDbvtVolume::FromMM(bt(b.min.as<double>()), bt(b.max.as<double>())), nullptr);
    std::array<std::uint64_t, 3> dims{};
    for (int a = 0; a < 3; ++a) dims[a] = std::max<std::uint64_t>(1, std::uint64_t(std::ceil(ext[a] / kCell)));
    std::set<std::array<std::uint64_t, 3>> used;
    Setup s;
    for (std::size_t draw = 0; draw < 64 * n && s.bodies.size() < n; ++draw) {
        const std::array<std::uint64_t, 3> c{rng.below(dims[0]), rng.below(dims[1]), rng.below(dims[2])};
        if (used.count(c)) continue;
        const Vec3d centre = bounds.min + Vec3d{double(c[0]) + 0.5, double(c[1]) + 0.5, double(c[2]) + 0.5} * kCell;
        AnyLeaf inside, below;
        tree.collideTV(tree.m_root, btDbvtVolume::FromCE(bt(centre), btVector3(0.9f, 0.9f, 0.9f)), inside);
        if (inside.hit) continue;
        btDbvt::rayTest(tree.m_root, bt(centre), bt(Vec3d{centre.x, bounds.min.y, centre.z}), below);
        if (!below.hit) continue;
        used.insert(c);
        BodySpec b;
        b.shape = shapes[s.bodies.size()];
        b.half = random_half(rng);
        b.position = centre;
        if (b.shape == BodyShape::rotated) b.rotation = random_rotation(rng);
        s.bodies.push_back(b);
    }
    if (s.bodies.size() < n)
        throw InputError("the map has room for " + std::to_string(s.bodies.size()) + " of " + std::to_string(n) +
                         " bodies (free 2 m cells above its boxes, found in " + std::to_string(64 * n) + " draws)");
    s.ground = true;  // catches bodies that fall off the map's edges
    s.ground_height = bounds.min.y;
    return s;
}

Setup freefall_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng) {
    Setup s;
    // A wide grid four layers deep, 10 m above the ground (Broadmark's FreeFall drops a grid).
    const std::size_t side = std::max<std::size_t>(1, std::size_t(std::ceil(std::sqrt(double(n) / 4))));
    s.bodies = lattice(n, side, 2.0, {1, 10, 1}, 0.0, shapes, rng);
    s.ground = true;
    return s;
}

Setup explosion_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng) {
    Setup s;
    const std::size_t side = cube_side(n);
    const double cell = 1.75, radius = 0.5 * cell * double(side);
    const Vec3d centre{radius, radius + 1, radius};
    s.bodies = lattice(n, side, cell, {0.5 * cell, 1 + 0.5 * cell, 0.5 * cell}, 0.0, shapes, rng);
    // Outward from the centre at 10 to 20 m/s with an upward share: debris flung, then falling.
    for (BodySpec& b : s.bodies) {
        Vec3d d = b.position - centre;
        const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
        d = len > 1e-9 ? d * (1.0 / len) : rng.direction();
        b.velocity = d * rng.uniform(10, 20) + Vec3d{0, 5, 0};
    }
    s.ground = true;
    return s;
}

Setup collapse_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng) {
    Setup s;
    // Walls of 10 × 10 bricks (1 × 0.5 × 0.5 m, running bond), each with a ball 6 m in front
    // thrown at it at 12 m/s; walls 15 m apart on a square grid. A rotated brick starts
    // axis-aligned (the wall is stacked) and turns as the wall falls.
    constexpr std::size_t kWide = 10, kHigh = 10, kPerWall = kWide * kHigh + 1;
    const std::size_t walls = (n + kPerWall - 1) / kPerWall;
    const std::size_t grid = std::max<std::size_t>(1, std::size_t(std::ceil(std::sqrt(double(walls)))));
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t w = i / kPerWall, k = i % kPerWall;
        const Vec3d origin{15.0 * double(w % grid), 0, 15.0 * double(w / grid)};
        BodySpec b;
        b.shape = shapes[i] == BodyShape::rotated ? BodyShape::box : shapes[i];
        if (k == 0) {  // the ball
            b.shape = BodyShape::sphere;
            b.half = {0.75, 0.75, 0.75};
            b.position = origin + Vec3d{5, 1.5, -6};
            b.velocity = {rng.uniform(-1, 1), 0, 12};
        } else {
            const std::size_t row = (k - 1) / kWide, col = (k - 1) % kWide;
            b.half = {0.5, 0.25, 0.25};
            b.position = origin + Vec3d{double(col) + (row % 2 ? 0.5 : 0.0), 0.25 + 0.5 * double(row), 0};
        }
        s.bodies.push_back(b);
    }
    s.ground = true;
    return s;
}

Setup boxed_setup(std::size_t n, const std::vector<BodyShape>& shapes, Random& rng, bool brownian) {
    Setup s;
    // Broadmark's Brownian and Gravity: a closed box a quarter full of bodies, which never sleep.
    const std::size_t side = cube_side(n);
    s.bodies = lattice(n, side, 2.0, {1, 1, 1}, 0.0, shapes, rng);
    for (BodySpec& b : s.bodies) b.velocity = rng.direction() * rng.uniform(0, 4);
    s.statics = closed_box(2.0 * double(side));
    s.gravity = brownian ? Vec3d{0, 0, 0} : Vec3d{0, -19.62, 0};
    s.sleep = false;
    return s;
}

Setup make_setup(const SceneSettings& settings, std::span<const Aabb> map) {
    Random rng(mix_seed(settings.seed, kBodyStream));
    const std::vector<BodyShape> shapes = shape_mix(settings.objects, settings.shapes, rng);
    const std::string& k = settings.kind;
    if (!map.empty() && k != "pile") throw InputError("only the pile kind is dropped onto a map, not " + k);
    if (k == "pile" && !map.empty()) return map_pile_setup(settings.objects, shapes, rng, map);
    if (k == "pile") return pile_setup(settings.objects, shapes, rng);
    if (k == "freefall") return freefall_setup(settings.objects, shapes, rng);
    if (k == "explosion") return explosion_setup(settings.objects, shapes, rng);
    if (k == "collapse") return collapse_setup(settings.objects, shapes, rng);
    if (k == "brownian" || k == "gravity") return boxed_setup(settings.objects, shapes, rng, k == "brownian");
    throw InputError("unknown physics kind '" + k + "' (known: " + join(physics_kinds()) + ")");
}

/// When bodies sleep (Bullet's btRigidBody::updateDeactivation and wantsSleeping, and
/// btSimulationIslandManager::buildIslands): an island, the bodies linked by overlapping AABBs,
/// sleeps once every body in it has stayed below its linear and angular sleeping thresholds for
/// gDeactivationTime seconds. A settled pile lies as one island of nearly all its bodies, in which
/// a few resting contacts pop each second (one step above 1 rad/s, then calm again): with Bullet's
/// defaults (0.8 m/s, 1 rad/s, 2 s) one pop every 2 s among hundreds of bodies keeps the whole
/// pile awake for ever, whatever the solver's iterations, restitution or split impulse. Higher
/// thresholds (setSleepingThresholds) and a shorter calm time let it fall asleep within seconds.
constexpr btScalar kLinearSleep = 1.2f, kAngularSleep = 2.0f, kCalmSeconds = 0.5f;

/// Bullet's process-wide gDeactivationTime at kCalmSeconds for one generation, the caller's value
/// put back after (an engine linking rcbench keeps its own).
struct CalmTime {
    btScalar saved = gDeactivationTime;
    CalmTime() { gDeactivationTime = kCalmSeconds; }
    CalmTime(const CalmTime&) = delete;
    CalmTime& operator=(const CalmTime&) = delete;
    ~CalmTime() { gDeactivationTime = saved; }
};

/// Bullet's world and everything it points to. The world goes first (declared last) while the
/// bodies it points to still exist; it frees each body's broadphase proxy itself.
struct World {
    btDefaultCollisionConfiguration config;
    btCollisionDispatcher dispatcher{&config};
    btDbvtBroadphase broadphase;
    btSequentialImpulseConstraintSolver solver;
    std::vector<std::unique_ptr<btCollisionShape>> shapes;
    std::vector<std::unique_ptr<btRigidBody>> statics, bodies;
    btDiscreteDynamicsWorld world{&dispatcher, &broadphase, &solver, &config};

    /// Empties the pair cache pair by pair (a hash lookup each) first: freeing a proxy otherwise
    /// scans every pair, and removing bodies one by one scans the body list, both quadratic in
    /// the body count (minutes at 10^5 bodies).
    ~World() {
        btOverlappingPairCache* cache = world.getPairCache();
        while (cache->getNumOverlappingPairs() > 0) {
            const btBroadphasePair& p = cache->getOverlappingPairArray()[cache->getNumOverlappingPairs() - 1];
            cache->removeOverlappingPair(p.m_pProxy0, p.m_pProxy1, &dispatcher);
        }
    }
};

std::unique_ptr<btCollisionShape> collision_shape(const BodySpec& b) {
    switch (b.shape) {
        case BodyShape::sphere:
            return std::make_unique<btSphereShape>(btScalar(std::min({b.half.x, b.half.y, b.half.z})));
        case BodyShape::capsule: {
            const double r = std::min(b.half.x, b.half.z);
            return std::make_unique<btCapsuleShape>(btScalar(r), btScalar(2 * std::max(b.half.y - r, 0.0)));
        }
        default:
            return std::make_unique<btBoxShape>(bt(b.half));
    }
}

void add_body(World& w, const BodySpec& b, bool sleep) {
    w.shapes.push_back(collision_shape(b));
    btCollisionShape* shape = w.shapes.back().get();
    const btScalar mass = btScalar(8 * b.half.x * b.half.y * b.half.z);  // density 1
    btVector3 inertia(0, 0, 0);
    shape->calculateLocalInertia(mass, inertia);
    btRigidBody::btRigidBodyConstructionInfo info(mass, nullptr, shape, inertia);
    info.m_startWorldTransform.setOrigin(bt(b.position));
    info.m_startWorldTransform.setRotation(btQuaternion(b.rotation[1], b.rotation[2], b.rotation[3], b.rotation[0]));
    info.m_restitution = 0.3f;
    w.bodies.push_back(std::make_unique<btRigidBody>(info));
    btRigidBody* body = w.bodies.back().get();
    body->setLinearVelocity(bt(b.velocity));
    if (!sleep) {
        body->setActivationState(DISABLE_DEACTIVATION);
    } else {
        // Without rolling resistance a sphere or capsule rolls on for ever and keeps its whole
        // pile awake; some damping lets a settled pile reach Bullet's sleeping thresholds. Only
        // round bodies get it: a box lies on faces and does not roll, and each contact with
        // rolling or spinning friction adds up to three solver rows per manifold, work that
        // changes nothing a box does.
        if (b.shape == BodyShape::sphere || b.shape == BodyShape::capsule) {
            body->setRollingFriction(0.05f);
            body->setSpinningFriction(0.05f);
        }
        body->setDamping(0.05f, 0.3f);
        body->setSleepingThresholds(kLinearSleep, kAngularSleep);
    }
    w.world.addRigidBody(body);
}

void add_static(World& w, const StaticBox& s) {
    w.shapes.push_back(std::make_unique<btBoxShape>(bt(s.half)));
    btRigidBody::btRigidBodyConstructionInfo info(0, nullptr, w.shapes.back().get());
    info.m_startWorldTransform.setOrigin(bt(s.centre));
    info.m_restitution = 0.3f;
    w.statics.push_back(std::make_unique<btRigidBody>(info));
    w.world.addRigidBody(w.statics.back().get());
}

void add_ground(World& w, double height) {
    w.shapes.push_back(std::make_unique<btStaticPlaneShape>(btVector3(0, 1, 0), btScalar(height)));
    btRigidBody::btRigidBodyConstructionInfo info(0, nullptr, w.shapes.back().get());
    info.m_restitution = 0.3f;
    w.statics.push_back(std::make_unique<btRigidBody>(info));
    w.world.addRigidBody(w.statics.back().get());
}

/// The object of body `uid` in its current pose: an oriented box (a box while its rotation is the
/// identity and it started axis-aligned), a sphere or a capsule along the body's local y axis.
Object body_object(Uid uid, const BodySpec& spec, const btRigidBody& body) {
    const btTransform& t = body.getWorldTransform();
    const Vec3d c = vec(t.getOrigin());
    const btQuaternion q = t.getRotation();
    const std::array<float, 4> rot{float(q.w()), float(q.x()), float(q.y()), float(q.z())};
    switch (spec.shape) {
        case BodyShape::sphere:
            return shaped_object(
                uid, Shape::sphere(c.as<float>(), float(std::min({spec.half.x, spec.half.y, spec.half.z}))));
        case BodyShape::capsule: {
            const double r = std::min(spec.half.x, spec.half.z), h = std::max(spec.half.y - r, 0.0);
            const Vec3d axis = vec(t.getBasis().getColumn(1)) * h;
            return shaped_object(uid, Shape::capsule((c - axis).as<float>(), (c + axis).as<float>(), float(r)));
        }
        default: {
            const Shape obb = Shape::obb(c.as<float>(), spec.half.as<float>(), rot);
            const bool identity = rot[0] == 1 && rot[1] == 0 && rot[2] == 0 && rot[3] == 0;
            if (spec.shape == BodyShape::box && identity) return {uid, shape_bounds(obb)};
            return shaped_object(uid, obb);
        }
    }
}

/// Gravity's direction in the "gravity" kind at time t: turning around z with period 6.2 s
/// (Broadmark's GravityFrequency) while that circle itself turns around y at half the rate.
Vec3d turning_gravity(double t) {
    const double a = 2 * std::numbers::pi * t / 6.2, b = a / 2;
    return Vec3d{std::sin(a) * std::cos(b), -std::cos(a), std::sin(a) * std::sin(b)} * 19.62;
}

}  // namespace

std::vector<std::string> physics_kinds() {
    return {"pile", "collapse", "explosion", "brownian", "freefall", "gravity"};
}

bool is_physics_kind(std::string_view kind) {
    const auto kinds = physics_kinds();
    return std::find(kinds.begin(), kinds.end(), kind) != kinds.end();
}

void check_time_step(double seconds) {
    if (!(seconds >= 1e-4 && seconds <= 0.1))  // NaN fails too
        throw InputError("time_step: expected a number of seconds in 0.0001..0.1, got " + std::to_string(seconds));
}

Recording generate_physics_scene(const SceneSettings& settings, std::span<const Aabb> map) {
    check_time_step(settings.time_step);
    check_shapes(settings.shapes);
    check_ray_settings(settings.rays);
    check_scene_size(double(settings.objects) + double(map.size()), settings.frames, settings.rays.per_frame,
                     settings.objects, "scene");
    const Setup setup = make_setup(settings, map);
    const CalmTime calm;
    auto w = std::make_unique<World>();
    w->world.setGravity(bt(setup.gravity));
    for (const StaticBox& s : setup.statics) add_static(*w, s);
    for (const Aabb& b : map) add_static(*w, {b.center().as<double>(), (b.extent() * 0.5f).as<double>()});
    if (setup.ground) add_ground(*w, setup.ground_height);
    for (const BodySpec& b : setup.bodies) add_body(*w, b, setup.sleep);  // in uid order
    Recording r;
    nlohmann::json meta = to_json(settings);
    meta["frames"] = settings.frames;
    meta["seed"] = settings.seed;
    meta["rays"] = rays_json(settings.rays);
    if (!map.empty()) meta["map_boxes"] = map.size();
    r.meta = meta.dump();
    for (std::size_t i = 0; i < setup.bodies.size(); ++i)
        r.initial.push_back(body_object(Uid(i), setup.bodies[i], *w->bodies[i]));
    for (std::size_t i = 0; i < map.size(); ++i) r.initial.push_back({Uid(setup.bodies.size() + i), map[i]});
    LiveSet live(r.initial);
    const std::size_t kicks = (setup.bodies.size() + 99) / 100;  // brownian: every body once per 100 frames
    std::size_t next_kick = 0;
    for (std::uint32_t f = 1; f <= settings.frames; ++f) {
        if (settings.kind == "gravity") w->world.setGravity(bt(turning_gravity(f * settings.time_step)));
        if (settings.kind == "brownian") {
            Random rng(mix_seed(settings.seed, kKickStream + f));
            for (std::size_t k = 0; k < kicks; ++k, next_kick = (next_kick + 1) % setup.bodies.size())
                w->bodies[next_kick]->setLinearVelocity(bt(rng.direction() * rng.uniform(0, 4)));
        }
        w->world.stepSimulation(btScalar(settings.time_step), 0);  // one step of exactly time_step
        Frame frame;
        for (std::size_t i = 0; i < setup.bodies.size(); ++i) {
            const Object o = body_object(Uid(i), setup.bodies[i], *w->bodies[i]);
            if (!(o == live.object(o.uid))) frame.moves.push_back(o);
        }
        live.apply(frame);
        frame.rays = generate_rays(live.objects(), settings.rays, settings.seed, f);
        frame.kinds = ray_kinds(frame.rays.size(), settings.rays, settings.seed, f);
        r.frames.push_back(std::move(frame));
    }
    return r;
}

}  // namespace rcb
