#pragma once
/// Physics-driven scenes: bodies simulated by Bullet's rigid-body world instead of the thesis'
/// protocol of moving 1% of the objects by a random shift (§5.2.1). Every awake body moves every
/// frame by a small coherent step and bodies fall asleep, so the share of objects changing per
/// frame swings from all to almost none. rcbench's own kinds:
///
///   pile       bodies dropped in a tall jittered block onto a ground, settling until most sleep
///   collapse   stacked brick walls, each knocked over by a ball thrown at it
///   explosion  a packed ball of bodies above a ground flung outward, then settling
///
/// Broadmark's kinds (Serpa & Rodrigues 2019, "Broadmark: a testing framework for broad-phase
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
/// btDbvtBroadphase, single thread) in one Bullet step (rcbench's kinds) or four (Broadmark's): the
/// same settings give the same bytes on one build. A frame's moves are the bodies whose shape
/// changed; each moved object's shape carries the body's rotation (an oriented box, a capsule's
/// axis) and its box is that shape's bounds, so the ground truth is exact. Ground and walls are
/// static colliders, not objects.

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/scene/generate/generators.h"

namespace rcb {

std::vector<std::string> physics_kinds();
bool is_physics_kind(std::string_view kind);

/// brownian, freefall and gravity: the kinds that follow Broadmark's scene generator.
bool is_broadmark_kind(std::string_view kind);
/// Broadmark's object sets (ObjectsTypes.cs): cubes, spheres, assorted.
std::vector<std::string> broadmark_shape_sets();

/// InputError unless `seconds` is a number in [1e-4, 0.1].
void check_time_step(double seconds);
/// The seconds one frame simulates: settings.time_step, or when 0 the kind's default (1/60 s for
/// rcbench's kinds, Broadmark's FixedTimestep of 1/30 s for its three).
double physics_time_step(const SceneSettings& settings);

/// Broadmark's arena side L for `objects` bodies filling `fill` of it (0: 0.1): the cube root of
/// objects / fill, each body's nominal volume being 1 (SimulationParameters.cs, WorldSideLength).
/// The arena is the cube [−L/2, L/2]³ around the origin.
double broadmark_arena_side(std::uint32_t objects, double fill);

/// A physics scene of `settings.kind` (one of physics_kinds()): objects, frames, shape shares
/// (rcbench's kinds) or shape set and fill (Broadmark's), time step, seed and rays as `settings`
/// says (its dynamics settings do not apply). InputError for a shape share given to a Broadmark
/// kind, or a shape set or fill given to one of rcbench's.
///
/// `map` (pile only): static boxes, in metres with y up, to drop the bodies onto instead of the
/// open ground: each body starts in its own free 2 m cell of a lattice over the map's bounds,
/// drawn at random among the cells that overlap no map box and have one somewhere below them, so
/// it falls onto the map's floors, ledges or roofs (a plane under the map's lowest point catches
/// any that fall off). The recording holds the bodies (uids 0..n−1) and then the map's boxes
/// (uids n..n+m−1) as objects that never move. InputError when the map has fewer such cells than
/// bodies, or is more than 10^6 m across.
Recording generate_physics_scene(const SceneSettings& settings, std::span<const Aabb> map = {});

}  // namespace rcb
