#pragma once
/// Physics-driven scenes: bodies simulated by Bullet's rigid-body world instead of the thesis'
/// protocol of moving 1% of the objects by a random shift (§5.2.1). Every awake body moves every
/// frame by a small coherent step and bodies fall asleep, so the share of objects changing per
/// frame swings from all to almost none. rcbench's own generators:
///
///   pile       bodies dropped in a tall jittered block onto a ground, settling until most sleep
///   collapse   stacked brick walls, each knocked over by a ball thrown at it
///   explosion  a packed ball of bodies above a ground flung outward, then settling
///
/// Broadmark's generators (Serpa & Rodrigues 2019, "Broadmark: a testing framework for broad-phase
/// collision detection algorithms"), built with the parameters of its scene generator
/// (ppgia-unifor/Broadmark, SimulationGenerator/Assets/Scripts; physics.cpp cites file and line):
/// N bodies of a shape set (cubes, spheres, assorted) spawned at random in a ball of radius
/// 0.45 L, with velocities up to 0.75 L/s, inside a closed cubic arena of side L sized so that the
/// bodies' nominal unit volumes fill `fill` of it (0.1), one frame of 1/30 s in 4 substeps:
///
///   brownian   no gravity; after each frame ceil(N/100) bodies in turn get a new random velocity
///   freefall   gravity 0.0981 L/s² down: the ball falls and piles on the arena's floor
///   gravity    a pull of 0.3924 L/s² starting along +x that turns 1.94° per frame
///
/// One frame is `time_step` seconds (btDiscreteDynamicsWorld, sequential impulse solver,
/// btDbvtBroadphase, single thread) in one Bullet step (rcbench's generators) or four (Broadmark's): the
/// same settings give the same bytes on one build. A frame's moves are the bodies whose shape
/// changed; each moved object's shape carries the body's rotation (an oriented box, a capsule's
/// axis) and its box is that shape's bounds, so the ground truth is exact. Ground and walls are
/// static colliders, not objects.

#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/scene/generate/generators.h"
#include "core/scene/recording_stream.h"

namespace rcb {

/// The generators whose scenes Bullet simulates: pile, collapse, explosion, brownian, freefall, gravity.
std::vector<std::string> physics_generators();
bool is_physics_generator(std::string_view generator);

/// brownian, freefall and gravity: the generators that follow Broadmark's scene generator.
bool is_broadmark_generator(std::string_view generator);

/// The old names of physics_generators, is_physics_generator and is_broadmark_generator, kept for
/// one release; they go with the next.
[[deprecated("use physics_generators")]] inline std::vector<std::string> physics_kinds() {
    return physics_generators();
}
[[deprecated("use is_physics_generator")]] inline bool is_physics_kind(std::string_view generator) {
    return is_physics_generator(generator);
}
[[deprecated("use is_broadmark_generator")]] inline bool is_broadmark_kind(std::string_view generator) {
    return is_broadmark_generator(generator);
}
/// Broadmark's object sets (ObjectsTypes.cs): cubes, spheres, assorted.
std::vector<std::string> broadmark_shape_sets();

/// InputError unless `seconds` is a number in [1e-4, 0.1].
void check_time_step(double seconds);
/// The seconds one frame simulates: settings.time_step, or when 0 the generator's default (1/60 s
/// for rcbench's generators, Broadmark's FixedTimestep of 1/30 s for its three).
double physics_time_step(const SceneSettings& settings);

/// Broadmark's arena side L for `objects` bodies filling `fill` of it (0: 0.1): the cube root of
/// objects / fill, each body's nominal volume being 1 (SimulationParameters.cs, WorldSideLength).
/// The arena is the cube [−L/2, L/2]³ around the origin.
double broadmark_arena_side(std::uint32_t objects, double fill);

/// A physics scene of `settings.generator` (one of physics_generators()): objects, frames, shape
/// shares (rcbench's generators) or shape set and fill (Broadmark's), time step, seed and rays as
/// `settings` says (its dynamics settings do not apply). InputError for a shape share given to a
/// Broadmark generator, or a shape set or fill given to one of rcbench's.
///
/// `map` (pile only): static boxes, in metres with y up, to drop the bodies onto instead of the
/// open ground: each body starts in its own free 2 m cell of a lattice over the map's bounds,
/// drawn at random among the cells that overlap no map box and have one somewhere below them, so
/// it falls onto the map's floors, ledges or roofs (a plane under the map's lowest point catches
/// any that fall off). The recording holds the bodies (uids 0..n−1) and then the map's boxes
/// (uids n..n+m−1) as objects that never move. InputError when the map has fewer such cells than
/// bodies, or is more than 10^6 m across.
/// Refuses first (check_scene_size) a recording too big to hold in memory.
Recording generate_physics_scene(const SceneSettings& settings, std::span<const Aabb> map = {});

/// The same scene, each frame given to `sink` as soon as it is simulated (the frames bounded by the
/// file's size only: check_streamed_scene_size), so that `scene gen` writes it with RecordingWriter in the memory of
/// one frame. Same settings, same frames as generate_physics_scene.
void stream_physics_scene(const SceneSettings& settings, SceneSink& sink, std::span<const Aabb> map = {});

/// How the Bullet world is configured. The defaults are Bullet's own and what every scene is
/// generated with (`scene gen`, generate_physics_scene); the alternatives are the settings of
/// Broadmark's Bullet engine (ppgia-unifor/Broadmark, SimulationGenerator/Assets/Scripts/Engines/
/// Bullet/BulletEngine.cs, Initialize) and of its default engine, PhysX, so that
/// bench/physics_step can time what they would change. Anything but the defaults changes the
/// scene's bytes.
struct BulletConfig {
    /// btDbvtBroadphase::m_deferedcollide: false (Bullet's default, btDbvtBroadphase's constructor)
    /// collides each moved proxy against both trees inside setAabb; true (BulletEngine.cs:26-28)
    /// collides the trees once per step in btDbvtBroadphase::collide.
    bool deferred_collide = false;
    /// btNNCGConstraintSolver (BulletEngine.cs:32) instead of btSequentialImpulseConstraintSolver.
    bool nncg_solver = false;
    /// btContactSolverInfo::m_numIterations: Bullet's default 10, which Broadmark's Bullet engine
    /// keeps; its PhysX engine runs SolverIterations = 6 (SimulationParameters.cs:22,
    /// PhysxEngine.cs:12).
    int solver_iterations = 10;
};

/// One physics scene being simulated, a frame at a time: the settings checked and the Bullet world
/// built by the constructor, then step() and record() per frame. stream_physics_scene is this loop;
/// apart, it lets a benchmark time Bullet's step alone and rcbench's recording of the frame
/// (bench/physics_step.cpp). Holds the world, the live objects and Bullet's gDeactivationTime for
/// its lifetime: one run at a time per process.
class PhysicsRun {
public:
    explicit PhysicsRun(const SceneSettings& settings, std::span<const Aabb> map = {}, const BulletConfig& config = {});
    ~PhysicsRun();
    PhysicsRun(const PhysicsRun&) = delete;
    PhysicsRun& operator=(const PhysicsRun&) = delete;

    /// The recording's META text and frame 0's objects.
    const std::string& meta() const;
    const std::vector<Object>& initial() const;
    /// Simulates the next frame: Bullet's step (Broadmark's generators: 4 substeps) and what a
    /// Broadmark generator does after each frame (kicks, the turning pull, bodies leaving the arena).
    void step();
    /// The frame last simulated as the recording keeps it: a move for each body whose object (box,
    /// shape, rotation) changed since the last record(), then the frame's rays and query kinds.
    Frame record();
    /// Frames simulated so far.
    std::uint32_t frame() const;
    /// Bodies Bullet simulates now (not asleep, not left the arena).
    std::size_t awake_bodies() const;

    struct State;

private:
    std::unique_ptr<State> state_;
};

}  // namespace rcb
