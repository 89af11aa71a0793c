#pragma once
/// Physics-driven scenes: bodies simulated by Bullet's rigid-body world instead of the thesis'
/// protocol of moving 1% of the objects by a random shift (§5.2.1). Every awake body moves every
/// frame by a small coherent step and bodies fall asleep, so the share of objects changing per
/// frame swings from all to almost none. Kinds:
///
///   pile       bodies dropped in a tall jittered block onto a ground, settling until most sleep
///   collapse   stacked brick walls, each knocked over by a ball thrown at it
///   explosion  a packed ball of bodies above a ground flung outward, then settling
///   brownian   bodies in a closed box, no gravity; each frame 1% of them get a new random velocity
///   freefall   a wide grid of bodies falling under gravity onto a ground
///   gravity    bodies in a closed box whose gravity turns around (period 6.2 s)
///
/// The last three follow the scenes of Broadmark (Serpa & Rodrigues 2019, "Broadmark: a testing
/// framework for broad-phase collision detection algorithms"), rebuilt from its description.
/// One frame is one Bullet step of `time_step` seconds (btDiscreteDynamicsWorld, sequential
/// impulse solver, btDbvtBroadphase, single thread): the same settings give the same bytes on one
/// build. A frame's moves are the bodies whose shape changed; each moved object's shape carries
/// the body's rotation (an oriented box, a capsule's axis) and its box is that shape's bounds, so
/// the ground truth is exact. Ground and walls are static colliders, not objects.

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/scene/generate/generators.h"

namespace rcb {

std::vector<std::string> physics_kinds();
bool is_physics_kind(std::string_view kind);

/// InputError unless `seconds` is a number in [1e-4, 0.1].
void check_time_step(double seconds);

/// A physics scene of `settings.kind` (one of physics_kinds()): objects, frames, shape shares,
/// time step, seed and rays as `settings` says (its dynamics settings do not apply).
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
