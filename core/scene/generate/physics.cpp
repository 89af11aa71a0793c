#include "core/scene/generate/physics.h"

#include <BulletDynamics/ConstraintSolver/btNNCGConstraintSolver.h>
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
#include "core/scene/recording_stream.h"

namespace rcb {
namespace {

// Streams for mix_seed, apart from generators.cpp's (objects 1, dynamics 1e6, rays 2e6 + frame,
// shapes 4e6): body layout, and brownian's kicks per frame.
constexpr std::uint64_t kBodyStream = 5'000'000;
constexpr std::uint64_t kKickStream = 6'000'000;  // + frame

btVector3 bt(const Vec3d& v) { return {btScalar(v.x), btScalar(v.y), btScalar(v.z)}; }
Vec3d vec(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

enum class BodyShape { box, rotated, sphere, capsule };

/// One body as a generator lays it out: its shape inside a box of half extents `half`, its start.
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

/// What a generator sets up: the bodies (uid = index), static colliders and ground, gravity, and whether bodies
/// may fall asleep (Bullet's default thresholds) or stay awake.
struct Setup {
    std::vector<BodySpec> bodies;
    std::vector<StaticBox> statics;
    Vec3d gravity{0, -9.81, 0};
    bool sleep = true;
    bool ground = false;  ///< the plane y = ground_height (a plane: a huge box makes resting contacts jitter)
    double ground_height = 0;
    // Broadmark's generators: its bodies' material, the substeps per frame and the arena's side.
    bool broadmark = false;
    int substeps = 1;
    double arena = 0;
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

// Broadmark's scene generator (ppgia-unifor/Broadmark, SimulationGenerator/Assets/Scripts; the
// values are SimulationParameters.cs's defaults, which its StartupPrefab.prefab Template repeats,
// except ObjectDensity: see kBroadmarkFill).
constexpr double kBroadmarkFill = 0.1;           // SimulationParameters.cs:33 ObjectDensity (the prefab: 0.01)
constexpr double kBroadmarkSpawn = 0.90 / 2;     // SimulationParameters.cs:35,52 MaxInitialPosition = 0.45 L
constexpr double kBroadmarkSpeed = 0.75;         // SimulationParameters.cs:36,54 MaxInitialVelocity = 0.75 L/s
constexpr double kBroadmarkGravity = 0.0981;     // SimulationParameters.cs:37,56 Gravity = 0.0981 L/s²
constexpr double kBroadmarkTimeStep = 1.0 / 30;  // SimulationParameters.cs:24 FixedTimestep
constexpr int kBroadmarkSubsteps = 4;            // SimulationParameters.cs:25 SubSteps
constexpr double kBrownianCycle = 100;           // Brownian.cs:16 CyclePeriod: frames to kick every body once
constexpr double kGravityScale = 4;              // Gravity.cs:14 GravityScale
constexpr double kGravityPeriod = 6.2;           // Gravity.cs:13 GravityFrequency (seconds of a turn)

/// A point uniform in the unit ball (Unity's Random.insideUnitSphere, as Simulation.cs:164,171 and
/// Brownian.cs:30 draw positions and velocities).
Vec3d inside_unit_ball(Random& rng) { return rng.direction() * std::cbrt(rng.uniform()); }

/// Full edge lengths of body i of Broadmark's Assorted set (Simulation.cs:177-215,
/// GenerateAssortedSize; ObjectScale 1): by i mod 80, 4 small cubes (0.5), 4 large (1.9), 5 bars
/// (15.2 × 0.4 × 0.4 along x, x, x, y, z), 3 planks (1.9 × 5.7 × 0.1, 1.9 × 0.1 × 5.7,
/// 0.1 × 1.9 × 0.3), 3 square slabs (3.8 × 3.8 × 0.1 in each orientation), and 61 random boxes
/// of 0.803 × U(0.1, 1.9) per axis.
Vec3d assorted_size(std::size_t i, Random& rng) {
    constexpr double lo = 0.1, hi = 1.9;
    const std::size_t k = i % 80;
    if (k < 4) return Vec3d{1, 1, 1} * (5 * lo);
    if (k < 8) return Vec3d{1, 1, 1} * hi;
    if (k < 11) return {hi * 8, lo * 4, lo * 4};
    if (k < 12) return {lo * 4, hi * 8, lo * 4};
    if (k < 13) return {lo * 4, lo * 4, hi * 8};
    if (k < 14) return {hi, hi * 3, lo};
    if (k < 15) return {hi, lo, hi * 3};
    if (k < 16) return {lo, hi, lo * 3};
    if (k < 17) return {hi * 2, hi * 2, lo};
    if (k < 18) return {hi * 2, lo, hi * 2};
    if (k < 19) return {lo, hi * 2, hi * 2};
    const double x = rng.uniform(), y = rng.uniform(), z = rng.uniform();
    return (Vec3d{x, y, z} * (hi - lo) + Vec3d{lo, lo, lo}) * 0.803;
}

/// The closed arena around the cube [−L/2, L/2]³ (Simulation.cs:107-151, GenerateDefaultWorld):
/// six walls 0.5 L thick, those of x reaching past the others to close the edges.
std::vector<StaticBox> broadmark_walls(double side) {
    std::vector<StaticBox> walls;
    for (int a = 0; a < 3; ++a)
        for (double sign : {-1.0, 1.0}) {
            Vec3d c{0, 0, 0}, size{1, 1, 1};
            c[a] = sign * 0.75;
            size[a] = 0.5;
            for (int b = a + 1; b < 3; ++b) size[b] += 1.0;  // bc1..bc4's "+= doubleMargin"
            walls.push_back({c * side, size * (0.5 * side)});
        }
    return walls;
}

/// Broadmark's Start (Simulation.cs:29-37, 153-175): N bodies of the set, identity rotation, mass
/// 1, at insideUnitSphere × 0.45 L from the arena's centre (they may overlap: the engine pushes them
/// apart) with velocity insideUnitSphere × 0.75 L/s; gravity as the generator sets it.
Setup broadmark_setup(const SceneSettings& settings, Random& rng) {
    Setup s;
    const std::size_t n = settings.objects;
    const double side = broadmark_arena_side(settings.objects, settings.fill);
    const std::string set = settings.shape_set.empty() ? "cubes" : settings.shape_set;
    s.bodies.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        BodySpec& b = s.bodies[i];
        b.shape = set == "spheres" ? BodyShape::sphere : BodyShape::box;
        b.half = set == "assorted" ? assorted_size(i, rng) * 0.5 : Vec3d{0.5, 0.5, 0.5};
        b.position = inside_unit_ball(rng) * (kBroadmarkSpawn * side);
        b.velocity = inside_unit_ball(rng) * (kBroadmarkSpeed * side);
    }
    s.statics = broadmark_walls(side);
    s.broadmark = true;
    s.substeps = kBroadmarkSubsteps;
    s.arena = side;
    if (settings.generator == "brownian") s.gravity = {0, 0, 0};                          // Brownian.cs:26
    if (settings.generator == "freefall") s.gravity = {0, -kBroadmarkGravity * side, 0};  // PhysxEngine.cs:14
    if (settings.generator == "gravity") {
        s.gravity = Vec3d{kBroadmarkGravity * kGravityScale * side, 0, 0};  // Gravity.cs:24-29, along +x
        s.sleep = false;  // rcbench's choice: the pull never rests, and Bullet's setGravity skips sleeping bodies
    }
    return s;
}

/// Gravity.cs:32-40 (Step, after the frame's simulation): axis2 turns about z, then the pull
/// (axis3) about axis2, each by 360° × time step / 6.2 s (Gravity.cs:27).
struct TurningPull {
    Vec3d axis2{0, 1, 0}, axis3{1, 0, 0};
    static Vec3d turn(const Vec3d& v, const Vec3d& k, double radians) {  // Rodrigues' rotation formula
        const Vec3d kxv{k.y * v.z - k.z * v.y, k.z * v.x - k.x * v.z, k.x * v.y - k.y * v.x};
        const double kv = k.x * v.x + k.y * v.y + k.z * v.z;
        return v * std::cos(radians) + kxv * std::sin(radians) + k * (kv * (1 - std::cos(radians)));
    }
    void advance(double time_step) {
        const double a = 2 * std::numbers::pi * time_step / kGravityPeriod;
        axis2 = turn(axis2, {0, 0, 1}, a);
        axis3 = turn(axis3, axis2, a);
    }
};

Setup make_setup(const SceneSettings& settings, std::span<const Aabb> map) {
    Random rng(mix_seed(settings.seed, kBodyStream));
    const std::vector<BodyShape> shapes = shape_mix(settings.objects, settings.shapes, rng);
    const std::string& k = settings.generator;
    if (!map.empty() && k != "pile") throw InputError("only the pile generator is dropped onto a map, not " + k);
    if (k == "pile" && !map.empty()) return map_pile_setup(settings.objects, shapes, rng, map);
    if (k == "pile") return pile_setup(settings.objects, shapes, rng);
    if (k == "explosion") return explosion_setup(settings.objects, shapes, rng);
    if (k == "collapse") return collapse_setup(settings.objects, shapes, rng);
    if (is_broadmark_generator(k)) return broadmark_setup(settings, rng);
    throw InputError("unknown physics generator '" + k + "' (known: " + join(physics_generators()) + ")");
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
    std::unique_ptr<btSequentialImpulseConstraintSolver> solver;
    std::vector<std::unique_ptr<btCollisionShape>> shapes;
    std::vector<std::unique_ptr<btRigidBody>> statics, bodies;
    btDiscreteDynamicsWorld world;

    explicit World(const BulletConfig& c)
        : solver(c.nncg_solver ? std::make_unique<btNNCGConstraintSolver>()
                               : std::make_unique<btSequentialImpulseConstraintSolver>()),
          world(&dispatcher, &broadphase, solver.get(), &config) {
        broadphase.m_deferedcollide = c.deferred_collide;
        world.getSolverInfo().m_numIterations = c.solver_iterations;
    }
    World(const World&) = delete;
    World& operator=(const World&) = delete;

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

/// A body's material and damping: rcbench's generators have density 1 and restitution 0.3; Broadmark's
/// have mass 1 each (SimulationParameters.cs:34 ObjectMass), no damping but Unity's Rigidbody
/// default angular drag of 0.05, and Unity's default physic material (friction 0.6, bounciness 0:
/// ProjectSettings/DynamicsManager.asset names no default material).
void add_body(World& w, const BodySpec& b, const Setup& setup) {
    w.shapes.push_back(collision_shape(b));
    btCollisionShape* shape = w.shapes.back().get();
    const btScalar mass = setup.broadmark ? 1.0f : btScalar(8 * b.half.x * b.half.y * b.half.z);
    btVector3 inertia(0, 0, 0);
    shape->calculateLocalInertia(mass, inertia);
    btRigidBody::btRigidBodyConstructionInfo info(mass, nullptr, shape, inertia);
    info.m_startWorldTransform.setOrigin(bt(b.position));
    info.m_startWorldTransform.setRotation(btQuaternion(b.rotation[1], b.rotation[2], b.rotation[3], b.rotation[0]));
    info.m_restitution = setup.broadmark ? 0.0f : 0.3f;
    if (setup.broadmark) info.m_friction = 0.6f;
    w.bodies.push_back(std::make_unique<btRigidBody>(info));
    btRigidBody* body = w.bodies.back().get();
    body->setLinearVelocity(bt(b.velocity));
    if (setup.broadmark) {
        body->setDamping(0.0f, 0.05f);
        body->setSleepingThresholds(kLinearSleep, kAngularSleep);
    }
    if (!setup.sleep) {
        body->setActivationState(DISABLE_DEACTIVATION);
    } else if (!setup.broadmark) {
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

void add_static(World& w, const StaticBox& s, bool broadmark) {
    w.shapes.push_back(std::make_unique<btBoxShape>(bt(s.half)));
    btRigidBody::btRigidBodyConstructionInfo info(0, nullptr, w.shapes.back().get());
    info.m_startWorldTransform.setOrigin(bt(s.centre));
    info.m_restitution = broadmark ? 0.0f : 0.3f;
    if (broadmark) info.m_friction = 0.6f;
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

}  // namespace

std::vector<std::string> physics_generators() {
    return {"pile", "collapse", "explosion", "brownian", "freefall", "gravity"};
}

bool is_physics_generator(std::string_view generator) {
    const auto generators = physics_generators();
    return std::find(generators.begin(), generators.end(), generator) != generators.end();
}

bool is_broadmark_generator(std::string_view generator) {
    return generator == "brownian" || generator == "freefall" || generator == "gravity";
}

std::vector<std::string> broadmark_shape_sets() { return {"cubes", "spheres", "assorted"}; }

void check_time_step(double seconds) {
    if (!(seconds >= 1e-4 && seconds <= 0.1))  // NaN fails too
        throw InputError("time_step: expected a number of seconds in 0.0001..0.1, got " + std::to_string(seconds));
}

double physics_time_step(const SceneSettings& settings) {
    if (settings.time_step != 0) return settings.time_step;
    return is_broadmark_generator(with_generator(settings).generator) ? kBroadmarkTimeStep : 1.0 / 60;
}

double broadmark_arena_side(std::uint32_t objects, double fill) {
    return std::cbrt(double(objects) / (fill > 0 ? fill : kBroadmarkFill));
}

namespace {

/// InputError for settings a generator does not take: shape shares for Broadmark's (their set
/// gives the shapes), a shape set or fill for rcbench's, an unknown set, a fill outside (0, 0.5].
void check_generator_settings(const SceneSettings& s) {
    if (is_broadmark_generator(s.generator)) {
        if (s.shapes.any())
            throw InputError("shapes: " + s.generator +
                             " is Broadmark's scene, whose shape set (cubes, spheres, assorted) gives the shapes; the "
                             "rotated, sphere and capsule shares are for rcbench's generators");
        const auto sets = broadmark_shape_sets();
        if (!s.shape_set.empty() && std::find(sets.begin(), sets.end(), s.shape_set) == sets.end())
            throw InputError("shape_set: unknown set '" + s.shape_set + "' (known: " + join(sets) + ")");
        if (s.fill != 0 && !(s.fill > 0 && s.fill <= 0.5))
            throw InputError("fill: expected a share of the arena in (0, 0.5], got " + std::to_string(s.fill));
    } else if (!s.shape_set.empty() || s.fill != 0) {
        throw InputError(std::string(s.shape_set.empty() ? "fill" : "shape_set") +
                         ": only Broadmark's generators (brownian, freefall, gravity) take it, not " + s.generator);
    }
}

/// What a Broadmark generator does after each frame's simulation (Simulation.cs:64-82, Step, and the
/// scenes' Step overrides, which call it first): bodies whose centre left the world box are made
/// static (Simulation.cs:69-76); Brownian gives the next ceil(N/100) bodies in turn a new velocity
/// insideUnitSphere × 0.75 L/s (Brownian.cs:24,30,40-43; a new velocity wakes a sleeping body, as
/// PhysX does); Gravity turns its pull (Gravity.cs:32-40).
struct BroadmarkStep {
    const SceneSettings& settings;
    const Setup& setup;
    double time_step;
    std::size_t next_kick = 0;
    TurningPull pull;

    void after_frame(World& w, std::uint32_t frame) {
        const double half = setup.arena / 2;
        for (auto& body : w.bodies) {
            const btVector3 c = body->getWorldTransform().getOrigin();
            if (std::abs(c.x()) > half || std::abs(c.y()) > half || std::abs(c.z()) > half) {
                body->setLinearVelocity(btVector3(0, 0, 0));
                body->setAngularVelocity(btVector3(0, 0, 0));
                body->forceActivationState(DISABLE_SIMULATION);
            }
        }
        if (settings.generator == "brownian") {
            const std::size_t n = w.bodies.size(), kicks = std::size_t(std::ceil(double(n) / kBrownianCycle));
            Random rng(mix_seed(settings.seed, kKickStream + frame));
            for (std::size_t k = 0; k < kicks; ++k, next_kick = (next_kick + 1) % n) {
                btRigidBody& body = *w.bodies[next_kick];
                if (body.getActivationState() == DISABLE_SIMULATION) continue;
                body.setLinearVelocity(bt(inside_unit_ball(rng) * (kBroadmarkSpeed * setup.arena)));
                body.activate(true);
            }
        }
        if (settings.generator == "gravity") {
            pull.advance(time_step);
            w.world.setGravity(bt(pull.axis3 * (kBroadmarkGravity * kGravityScale * setup.arena)));
        }
    }
};

}  // namespace

/// A physics scene in the middle of its simulation (physics.h, PhysicsRun). Declared in the order it
/// is built: the settings and setup that BroadmarkStep points to, the calm time, then the world.
struct PhysicsRun::State {
    SceneSettings settings;
    double time_step;
    Setup setup;
    CalmTime calm;
    std::unique_ptr<World> w;
    BroadmarkStep broadmark{settings, setup, time_step, 0, TurningPull{}};
    btScalar substep = btScalar(time_step / setup.substeps);
    std::string meta;
    std::vector<Object> initial;
    LiveSet live;
    std::uint32_t frame = 0;

    State(const SceneSettings& s, double step, std::span<const Aabb> map, const BulletConfig& config)
        : settings(s), time_step(step), setup(make_setup(s, map)), w(std::make_unique<World>(config)) {}
};

PhysicsRun::PhysicsRun(const SceneSettings& given, std::span<const Aabb> map, const BulletConfig& config) {
    const SceneSettings settings = with_generator(given);
    const double time_step = physics_time_step(settings);
    check_time_step(time_step);
    check_shapes(settings.shapes);
    check_generator_settings(settings);
    check_ray_settings(settings.rays);
    check_streamed_scene_size(double(settings.objects) + double(map.size()), settings.frames, settings.rays.per_frame,
                              settings.objects, "scene");
    if (!(config.solver_iterations >= 1 && config.solver_iterations <= 1000))
        throw InputError("solver iterations: expected 1..1000, got " + std::to_string(config.solver_iterations));
    state_ = std::make_unique<State>(settings, time_step, map, config);
    State& s = *state_;
    World& w = *s.w;
    w.world.setGravity(bt(s.setup.gravity));
    for (const StaticBox& b : s.setup.statics) add_static(w, b, s.setup.broadmark);
    for (const Aabb& b : map) add_static(w, {b.center().as<double>(), (b.extent() * 0.5f).as<double>()}, false);
    if (s.setup.ground) add_ground(w, s.setup.ground_height);
    for (const BodySpec& b : s.setup.bodies) add_body(w, b, s.setup);  // in uid order
    nlohmann::json meta = to_json(settings);
    meta["frames"] = settings.frames;
    meta["seed"] = settings.seed;
    meta["rays"] = rays_json(settings.rays);
    if (!map.empty()) meta["map_boxes"] = map.size();
    s.meta = meta.dump();
    for (std::size_t i = 0; i < s.setup.bodies.size(); ++i)
        s.initial.push_back(body_object(Uid(i), s.setup.bodies[i], *w.bodies[i]));
    for (std::size_t i = 0; i < map.size(); ++i) s.initial.push_back({Uid(s.setup.bodies.size() + i), map[i]});
    s.live = LiveSet(s.initial);
}

PhysicsRun::~PhysicsRun() = default;

const std::string& PhysicsRun::meta() const { return state_->meta; }
const std::vector<Object>& PhysicsRun::initial() const { return state_->initial; }
std::uint32_t PhysicsRun::frame() const { return state_->frame; }

std::size_t PhysicsRun::awake_bodies() const {
    std::size_t awake = 0;
    for (const auto& body : state_->w->bodies) awake += body->isActive() ? 1 : 0;
    return awake;
}

void PhysicsRun::step() {
    State& s = *state_;
    ++s.frame;
    // One step of exactly time_step, or Broadmark's substeps (PhysicsEngine.cs:17-26, Step;
    // BulletEngine.cs:99-101 steps Bullet by each substep with no interpolation).
    for (int k = 0; k < s.setup.substeps; ++k) s.w->world.stepSimulation(s.substep, 0);
    if (s.setup.broadmark) s.broadmark.after_frame(*s.w, s.frame);
}

Frame PhysicsRun::record() {
    State& s = *state_;
    Frame frame;
    for (std::size_t i = 0; i < s.setup.bodies.size(); ++i) {
        const Object o = body_object(Uid(i), s.setup.bodies[i], *s.w->bodies[i]);
        if (!(o == s.live.object(o.uid))) frame.moves.push_back(o);
    }
    s.live.apply(frame);
    frame.rays = generate_rays(s.live.objects(), s.settings.rays, s.settings.seed, s.frame);
    frame.kinds = ray_kinds(frame.rays.size(), s.settings.rays, s.settings.seed, s.frame);
    return frame;
}

void stream_physics_scene(const SceneSettings& settings, SceneSink& sink, std::span<const Aabb> map) {
    PhysicsRun run(settings, map);
    sink.begin(run.meta(), run.initial());
    for (std::uint32_t f = 1; f <= settings.frames; ++f) {
        run.step();
        sink.frame(run.record());
    }
}

Recording generate_physics_scene(const SceneSettings& settings, std::span<const Aabb> map) {
    check_scene_size(double(settings.objects) + double(map.size()), settings.frames, settings.rays.per_frame,
                     settings.objects, "scene");
    RecordingCollector collector;
    stream_physics_scene(settings, collector, map);
    return std::move(collector.recording);
}

}  // namespace rcb
