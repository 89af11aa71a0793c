#pragma once
/// Scenes and rays for the suites, and the differential check against brute force (the hard
/// scenes themselves are the conformance suite's: testing/conformance.h).
///
/// `expect_matches_ground_truth` replays a recording through the simulator with verification,
/// the counting pass and Structure::check() after every frame, and fails on any mismatch,
/// naming the structure, parameters and the first discrepancies.

#include <filesystem>
#include <initializer_list>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/random.h"
#include "core/scene/scene.h"
#include "sim/simulator.h"
#include "accel/interface/structure.h"
#include "runner/experiment.h"
#include "testing/conformance.h"
#include "tests/test_support.h"

namespace rcb::test {

/// `r` with its objects given shapes inside their boxes, by uid (the same kind and rotation for an
/// object all along): boxes, triangles spanning the box, rotated boxes, spheres and capsules.
Recording with_shapes(const Recording& r, std::uint64_t seed);

/// The hits of one ray, sorted by uid.
std::vector<Uid> sorted_hits(Structure& s, const Segment& ray);

/// `n` segments from the centre of the objects' bounds in random directions (each axis uniform in
/// [-1, 1]), as long as the bounds' x extent at most: incoherent rays, each on its own path.
std::vector<Segment> rays_from_centre(const std::vector<Object>& objects, int n, std::uint64_t seed);

/// A box centred uniformly in [0, world)³ with half extents log-uniform in [0.01, 2].
Aabb random_box(Random& rng, float world);

/// One random change, applied to `live` and to every structure of `targets` (no commit): a remove,
/// an insert of uid `next++`, or a move by up to the object's longest edge per axis (anywhere in
/// the world with `jump`).
void random_change(Random& rng, std::vector<Object>& live, Uid& next, float world, bool jump,
                   std::initializer_list<Structure*> targets);

/// A segment with both ends uniform in [-5, world + 5)³.
Segment random_segment(Random& rng, float world);

/// A generated scene of `generator` named `name` as an experiment's or a tuning's scene: `objects`,
/// `frames` of `rays` each; `key` tells its recording apart in the scene cache.
SceneSpec generated_spec(const std::string& name, const std::string& generator, std::uint32_t objects,
                         std::uint32_t frames, std::uint32_t rays, const nlohmann::json& key);

/// Exact reference for the segment–box test: the set of t in [0, 1] with p0 + t·d inside the box,
/// per axis, by case analysis in double (no reciprocals, no NaN handling).
bool reference_hit(const Segmentd& s, const Aabbd& b);

/// Replays `r` with verification, counting and validation after every frame; expects 0 mismatches.
SimulationResult expect_matches_ground_truth(const Recording& r, const std::string& structure,
                                             const nlohmann::json& params = nlohmann::json::object(),
                                             const std::string& scene_name = "");

}  // namespace rcb::test
